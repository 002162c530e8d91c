"""Runs that never lie (render side): content-addressed identity and map cache, resume after a kill,
streaming frames, no silent 0 +/- 0. Results are kept through ``mincam_sim.Run`` (its sink)."""

from __future__ import annotations

import numpy as np
import pytest

import mincam_sim as ms
from mincam_sim import Mincam, Mixel, Pose, Screen, masks, pair_layout
from mincam_sim.errors import StaleResultError
from mincam_sim.render.kernels import map_tracing as rm
from mincam_sim.render.kernels.monte_carlo import UnseenWarning
from mincam_sim.runs.run import Run
from mincam_sim.scene.display import FrameSource, line_sweep

SCREEN = Screen(resolution=(64, 36))


def _sinusoid_cam(phase_rad: float) -> Mincam:
    mask = masks.sinusoid(2 * np.pi / 0.5e-3, 0.5, 0.4, phase_rad=phase_rad, resolution=64)
    return Mincam((Mixel(mask, name="sin"), Mixel(masks.ramp("x", 64), pose=Pose((0.01, 0, 0), (0, 0, -1)),
                                                  name="x")))


SOLVERS = {"response_map": ms.ResponseMap, "fast": ms.Aperture}


def _render(mincam, screen, frames, form="response_map", out_dir=None, overwrite=False, spp=None,
            samples_per_texel=None, **kw):
    """``Simulation.measure``, kept in ``out_dir/run`` by a Run when ``out_dir`` is given."""
    sim, solver = ms.Simulation(mincam, screen=screen), SOLVERS[form]()
    budget = ms.Budget(spp=spp, samples_per_texel=samples_per_texel, **kw)
    if out_dir is None:
        return sim.measure(frames, solver, budget)
    with Run(out_dir, overwrite=overwrite) as run:
        return run.measure(sim, frames, solver, budget, name="run")


def _frames(n: int = 6) -> np.ndarray:
    return line_sweep((-0.2, 0.0), (0.2, 0.0), n, 0.05).frame_stack(SCREEN)


@pytest.mark.parametrize("form", ["response_map", "fast"])
def test_changed_mask_content_is_refused_not_reused(form, tmp_path):
    """Same mask name and shape, different phase: the old code returned the old numbers (rc 0)."""
    kw = {"spp": 1 << 12, "samples_per_texel": 16, "seed": 1, "out_dir": tmp_path}
    _render(_sinusoid_cam(0.0), SCREEN, _frames(), form, **kw)
    with pytest.raises(StaleResultError, match=r"different run.*mincam.*--overwrite|different run.*overwrite"):
        _render(_sinusoid_cam(1.0), SCREEN, _frames(), form, **kw)
    fresh = _render(_sinusoid_cam(1.0), SCREEN, _frames(), form, **{**kw, "out_dir": None})
    replaced = _render(_sinusoid_cam(1.0), SCREEN, _frames(), form, overwrite=True, **kw)
    np.testing.assert_array_equal(replaced.irradiance_w_m2, fresh.irradiance_w_m2)


def test_changed_frame_content_is_refused(tmp_path):
    frames = _frames()
    _render(pair_layout(), SCREEN, frames, samples_per_texel=16, out_dir=tmp_path)
    frames[2, 0, 0] += 0.5
    with pytest.raises(StaleResultError, match="frames"):
        _render(pair_layout(), SCREEN, frames, samples_per_texel=16, out_dir=tmp_path)


def test_rerun_with_target_noise_reuses_cached_maps(tmp_path, monkeypatch):
    """The README's example twice: the second run finds its maps in the content cache and traces nothing."""
    cam, frames = pair_layout(), _frames()
    first = _render(cam, SCREEN, frames, target_rel_stderr=3e-3, seed=2, out_dir=tmp_path)

    def no_tracing(*args, **kwargs):
        raise AssertionError("maps were traced again although they are cached")

    monkeypatch.setattr(rm, "RayWeight", no_tracing)
    (tmp_path / "run.npz").unlink()  # not the finished result: the store resumes and the maps come from the cache
    second = _render(cam, SCREEN, frames, target_rel_stderr=3e-3, seed=2, out_dir=tmp_path)
    np.testing.assert_array_equal(first.irradiance_w_m2, second.irradiance_w_m2)
    assert second.meta["samples_per_texel"] == first.meta["samples_per_texel"]


def test_killed_map_tracing_resumes_mixel_by_mixel(tmp_path, monkeypatch):
    cam, frames = _sinusoid_cam(0.3), _frames()
    reference = _render(cam, SCREEN, frames, samples_per_texel=16, seed=4)
    original_put = rm.ContentCache.put
    calls = []

    def dying_put(self, key, arrays, meta=None):
        calls.append(key)
        original_put(self, key, arrays, meta)
        if len(calls) == 1:
            raise KeyboardInterrupt  # killed after the first mixel's map was stored

    monkeypatch.setattr(rm.ContentCache, "put", dying_put)
    with pytest.raises(KeyboardInterrupt):
        _render(cam, SCREEN, frames, samples_per_texel=16, seed=4, out_dir=tmp_path)
    monkeypatch.setattr(rm.ContentCache, "put", original_put)
    traced = []
    original_eval = rm.RayWeight

    def counting_eval(mixel):
        traced.append(mixel.mask.name)
        return original_eval(mixel)

    monkeypatch.setattr(rm, "RayWeight", counting_eval)
    resumed = _render(cam, SCREEN, frames, samples_per_texel=16, seed=4, out_dir=tmp_path)
    assert traced == [cam[1].mask.name]  # only the mixel whose map was not stored
    np.testing.assert_array_equal(resumed.irradiance_w_m2, reference.irradiance_w_m2)


def test_streamed_frames_equal_the_stack(tmp_path):
    sweep = line_sweep((-0.2, -0.05), (0.2, 0.05), 40, 0.04)
    source = sweep.frame_source(SCREEN)
    assert isinstance(source, FrameSource) and source.shape == (40, *SCREEN.shape)
    stacked = _render(pair_layout(), SCREEN, sweep.frame_stack(SCREEN), samples_per_texel=16, seed=5)
    streamed = _render(pair_layout(), SCREEN, source, samples_per_texel=16, seed=5, out_dir=tmp_path)
    np.testing.assert_array_equal(stacked.irradiance_w_m2, streamed.irradiance_w_m2)
    np.testing.assert_array_equal(stacked.stderr_w_m2, streamed.stderr_w_m2)


def test_a_measurement_no_sample_reached_warns():
    dark = np.zeros((2, *SCREEN.shape))
    dark[1] = 1.0
    with pytest.warns(UnseenWarning, match="not seen"):
        m = _render(pair_layout(), SCREEN, dark, samples_per_texel=16)
    assert np.all(m.irradiance_w_m2[0] == 0)
