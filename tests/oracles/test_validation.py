"""Bad input gets one clear error each; same seed gives the same numbers."""

from __future__ import annotations

import numpy as np
import pytest

from mincam_sim import (
    Aperture,
    Budget,
    Mixel,
    Pose,
    Reference,
    ResponseMap,
    Run,
    Screen,
    Simulation,
    masks,
    pair_layout,
    single,
)
from mincam_sim.scene.display import FrameSource, white_square

SOLVERS = {"fast": Aperture(), "reference": Reference(), "response_map": ResponseMap()}


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"d_f_m": 0.0}, "d_f_m"),
        ({"d_f_m": -1e-3}, "d_f_m"),
        ({"detector_size_m": 0.0}, "detector_size_m"),
        ({"detector_size_m": -1e-4}, "detector_size_m"),
        ({"detector_size_m": 5e-3}, "larger than its mask"),
    ],
)
def test_bad_mixel_geometry(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Mixel(masks.constant(1.0), **kwargs)


@pytest.mark.parametrize(
    ("array", "message"),
    [
        (np.array([[0.5, np.nan]]), "NaN"),
        (np.array([[0.5, 1.2]]), r"\[0, 1\]"),
        (np.array([[-0.1, 0.5]]), r"\[0, 1\]"),
        (np.zeros((0, 3)), "empty"),
        (np.zeros(4), "2D"),
    ],
)
def test_bad_mask_arrays(array, message):
    with pytest.raises(ValueError, match=message):
        masks.Mask(array)


def test_bad_mask_size():
    with pytest.raises(ValueError, match="width_m"):
        masks.Mask(np.ones((2, 2)), width_m=0.0)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [({"width_m": -1.0}, "width_m"), ({"height_m": 0.0}, "height_m"), ({"resolution": (0, 10)}, "resolution")],
)
def test_bad_screen(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Screen(**kwargs)


def test_mixel_behind_screen_is_refused():
    screen = Screen(pose=Pose((0, 0, -0.5), (0, 0, -1)))  # emits away from the mixel
    with pytest.raises(ValueError, match="behind the screen"):
        Simulation(single(), screen=screen).measure(screen.blank(), Aperture())


def test_screen_outside_field_of_view_is_refused():
    cam = single(pose=Pose((0, 0, 0), (0, 0, 1)))  # looks away from the screen at z = -0.5
    with pytest.raises(ValueError, match="behind the screen|outside"):
        Simulation(cam, screen=Screen()).measure(Screen().blank(), Aperture())
    cam = single(pose=Pose((0, 0, 0), (1, 0, -0.05)))  # looks sideways, screen out of its ~53 deg cone
    with pytest.raises(ValueError, match="outside mixel"):
        Simulation(cam, screen=Screen()).response_maps()


@pytest.mark.parametrize("spp", [0, -5, 1.5])
def test_bad_sample_counts(spp):
    with pytest.raises(ValueError, match="spp"):
        Budget(spp=spp)


def test_bad_frames():
    screen = Screen()
    sim = Simulation(single(), screen=screen)
    with pytest.raises(ValueError, match="shape"):
        sim.measure(np.zeros((3, 3)), Aperture())
    bad = screen.blank()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        sim.measure(bad, Aperture())
    bad[0, 0] = -1
    with pytest.raises(ValueError, match="negative"):
        sim.measure(bad, Aperture())


@pytest.mark.parametrize("form", ["fast", "reference", "response_map"])
def test_same_seed_same_numbers(form):
    screen = Screen()
    cam = pair_layout()
    frames = np.stack([white_square(screen, (x, 0.0), 0.05) for x in (-0.1, 0.0, 0.1)])
    sim = Simulation(cam, screen=screen)
    a, b, c = (sim.measure(frames, SOLVERS[form], Budget(spp=1 << 14, samples_per_texel=16, seed=seed))
               for seed in (42, 42, 43))
    np.testing.assert_array_equal(a.irradiance_w_m2, b.irradiance_w_m2)
    np.testing.assert_array_equal(a.stderr_w_m2, b.stderr_w_m2)
    assert not np.array_equal(a.irradiance_w_m2, c.irradiance_w_m2)


def test_interrupted_run_resumes_without_recomputing(tmp_path):
    """A run killed after some frames keeps them on disk; the rerun computes only the rest, same numbers."""
    screen = Screen()
    sim = Simulation(single(masks.ramp("x", 32)), screen=screen)
    stack = np.stack([white_square(screen, (x, 0.0), 0.05) for x in np.linspace(-0.2, 0.2, 5)])
    budget = Budget(spp=1 << 12, seed=1)
    full = sim.measure(stack, Aperture(), budget)
    calls = {"n": 0, "die_after": 2}

    def make(i: int) -> np.ndarray:  # the aperture solver reads one frame at a time
        calls["n"] += 1
        if calls["n"] > calls["die_after"]:
            raise KeyboardInterrupt
        return stack[i]

    frames = FrameSource(len(stack), screen.shape, make, description={"test": "five squares"})
    with pytest.raises(KeyboardInterrupt), Run(tmp_path) as run:
        run.measure(sim, frames, Aperture(), budget)
    done = np.load(tmp_path / "measurements" / "done.npy")
    assert done.sum() == 2

    calls.update(n=0, die_after=len(stack))
    with Run(tmp_path) as run:
        resumed = run.measure(sim, frames, Aperture(), budget)
    assert calls["n"] == 3
    np.testing.assert_array_equal(resumed.irradiance_w_m2, full.irradiance_w_m2)
    with pytest.raises(ValueError, match="different run"), Run(tmp_path) as run:
        run.measure(sim, frames, Aperture(), Budget(spp=1 << 12, seed=2))


def test_target_noise_is_reached():
    """Asking for a relative standard error picks the samples: the reported worst error meets the target."""
    screen = Screen()
    cam = pair_layout()
    frames = np.stack([white_square(screen, (x, 0.0), 0.04) for x in np.linspace(-0.15, 0.15, 7)])
    sim = Simulation(cam, screen=screen)
    m = sim.measure(frames, ResponseMap(), Budget(target_rel_stderr=2e-3, seed=3))
    assert m.meta["reached_rel_stderr"] <= 2e-3
    assert m.meta["samples_per_texel"] > 8
    m = sim.measure(frames[:2], Aperture(), Budget(target_rel_stderr=5e-3, seed=3))
    assert m.meta["reached_rel_stderr"] <= 5e-3
