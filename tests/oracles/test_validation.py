"""Bad input gets one clear error each; same seed gives the same numbers."""

from __future__ import annotations

import numpy as np
import pytest

from mincam_sim import Mixel, Pose, Screen, masks, pair_layout, single
from mincam_sim.render.screen_engine import ScreenRenderer, render_frames, response_maps
from mincam_sim.scene.display import white_square


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
        ScreenRenderer(single(), screen)


def test_screen_outside_field_of_view_is_refused():
    cam = single(pose=Pose((0, 0, 0), (0, 0, 1)))  # looks away from the screen at z = -0.5
    with pytest.raises(ValueError, match="behind the screen|outside"):
        ScreenRenderer(cam, Screen())
    cam = single(pose=Pose((0, 0, 0), (1, 0, -0.05)))  # looks sideways, screen out of its ~53 deg cone
    with pytest.raises(ValueError, match="outside mixel"):
        response_maps(cam, Screen())


@pytest.mark.parametrize("spp", [0, -5, 1.5])
def test_bad_sample_counts(spp):
    screen = Screen()
    renderer = ScreenRenderer(single(), screen)
    with pytest.raises(ValueError, match="spp"):
        renderer.render(screen.blank(), spp=spp)


def test_bad_frames():
    screen = Screen()
    renderer = ScreenRenderer(single(), screen)
    with pytest.raises(ValueError, match="shape"):
        renderer.render(np.zeros((3, 3)))
    bad = screen.blank()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        renderer.render(bad)
    bad[0, 0] = -1
    with pytest.raises(ValueError, match="negative"):
        renderer.render(bad)


@pytest.mark.parametrize("form", ["fast", "reference", "response_map"])
def test_same_seed_same_numbers(form):
    screen = Screen()
    cam = pair_layout()
    frames = np.stack([white_square(screen, (x, 0.0), 0.05) for x in (-0.1, 0.0, 0.1)])
    a, _ = render_frames(cam, screen, frames, form, spp=1 << 14, samples_per_texel=16, seed=42)
    b, _ = render_frames(cam, screen, frames, form, spp=1 << 14, samples_per_texel=16, seed=42)
    c, _ = render_frames(cam, screen, frames, form, spp=1 << 14, samples_per_texel=16, seed=43)
    np.testing.assert_array_equal(a.irradiance_w_m2, b.irradiance_w_m2)
    np.testing.assert_array_equal(a.stderr_w_m2, b.stderr_w_m2)
    assert not np.array_equal(a.irradiance_w_m2, c.irradiance_w_m2)


def test_interrupted_run_resumes_without_recomputing(tmp_path, monkeypatch):
    """A run killed after some frames keeps them on disk; the rerun computes only the rest, same numbers."""
    screen = Screen()
    cam = single(masks.ramp("x", 32))
    frames = np.stack([white_square(screen, (x, 0.0), 0.05) for x in np.linspace(-0.2, 0.2, 5)])
    full, _ = render_frames(cam, screen, frames, "fast", spp=1 << 12, seed=1)

    calls = {"n": 0}
    original = ScreenRenderer.render

    def dying_render(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] > 2:
            raise KeyboardInterrupt
        return original(self, *args, **kwargs)

    monkeypatch.setattr(ScreenRenderer, "render", dying_render)
    with pytest.raises(KeyboardInterrupt):
        render_frames(cam, screen, frames, "fast", spp=1 << 12, seed=1, out_dir=tmp_path)
    monkeypatch.setattr(ScreenRenderer, "render", original)
    done = np.load(tmp_path / "done.npy")
    assert done.sum() == 2

    counted = {"n": 0}

    def counting_render(self, *args, **kwargs):
        counted["n"] += 1
        return original(self, *args, **kwargs)

    monkeypatch.setattr(ScreenRenderer, "render", counting_render)
    resumed, _ = render_frames(cam, screen, frames, "fast", spp=1 << 12, seed=1, out_dir=tmp_path)
    assert counted["n"] == 3
    np.testing.assert_array_equal(resumed.irradiance_w_m2, full.irradiance_w_m2)
    with pytest.raises(ValueError, match="different run"):
        render_frames(cam, screen, frames, "fast", spp=1 << 12, seed=2, out_dir=tmp_path)


def test_target_noise_is_reached():
    """Asking for a relative standard error picks the samples: the reported worst error meets the target."""
    screen = Screen()
    cam = pair_layout()
    frames = np.stack([white_square(screen, (x, 0.0), 0.04) for x in np.linspace(-0.15, 0.15, 7)])
    m, _ = render_frames(cam, screen, frames, "response_map", target_rel_stderr=2e-3, seed=3)
    assert m.meta["reached_rel_stderr"] <= 2e-3
    assert m.meta["samples_per_texel"] > 8
    m, _ = render_frames(cam, screen, frames[:2], "fast", target_rel_stderr=5e-3, seed=3)
    assert m.meta["reached_rel_stderr"] <= 5e-3
