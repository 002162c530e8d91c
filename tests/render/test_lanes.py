"""One lane limit (``tracing.MAX_LANES``) for every launch loop, and one launch-seed rule.

Response maps draw each texel's random numbers from a launch of its own (``LaneSampler``) and each block's
pairing from its place in one stream, so a map is the same bit for bit whatever the limit; the ray loops
(``trace_groups``) launch at most ``MAX_LANES`` lanes at a time."""

from __future__ import annotations

import numpy as np
import pytest

from mincam_sim.model.optics import pair_layout
from mincam_sim.scene.display import Screen


def _needs_jit():
    from mincam_sim.render import backend

    if not backend.is_jit():
        pytest.skip("needs a JIT variant")


@pytest.mark.parametrize("seed, launch", [(0, 0), (12345, 7), (2**31 - 1, 99_999)])
def test_lane_sampler_draws_what_the_launch_sampler_draws(seed, launch):
    """Lane i of launch g, drawn among other launches' lanes, equals lane i of ``seeded_sampler(seed, g, n)``."""
    _needs_jit()
    from mincam_sim.render import backend
    from mincam_sim.render.kernels import tracing

    mi = backend.mitsuba()

    n = 257
    alone = tracing.seeded_sampler(seed, launch, n)
    expected = [alone.next_2d(), alone.next_1d(), alone.next_2d()]
    # the same lanes, packed after the lanes of another launch
    other = 3
    launches = mi.UInt32(np.r_[np.full(other, launch + 1), np.full(n, launch)].astype(np.uint32))
    index = mi.UInt32(np.r_[np.arange(other), np.arange(n)].astype(np.uint32))
    packed = tracing.LaneSampler(seed, launches, index)
    got = [packed.next_2d(), packed.next_1d(), packed.next_2d()]
    for e, g in zip(_columns(expected), _columns(got), strict=True):
        np.testing.assert_array_equal(g[other:], e)


def _columns(draws) -> list[np.ndarray]:
    """Each draw's coordinates as NumPy arrays (x and y of a 2D draw)."""
    out = []
    for d in draws:
        out += [np.asarray(d.x), np.asarray(d.y)] if "Point2" in type(d).__name__ else [np.asarray(d)]
    return out


@pytest.mark.parametrize("kw", [dict(samples_per_texel=64), dict(samples_per_texel=256, replicates=16, seed=3)],
                         ids=["4x4^2", "16x4^2"])
def test_response_maps_do_not_depend_on_the_lane_limit(monkeypatch, kw):
    """A limit of a few texels per launch (chunks that start mid-row) gives the maps of one launch, bit for bit,
    and every launch stays within the limit."""
    _needs_jit()
    from mincam_sim.render.kernels import tracing
    from mincam_sim.render.kernels.map_tracing import response_maps

    screen = Screen(resolution=(16, 9))
    one = response_maps(pair_layout(), screen, **kw)
    limit = 7 * one.meta["samples_per_texel"] + 5
    lanes = []
    real = tracing.LaneSampler

    def counting(seed, launch, index):
        lanes.append(len(index))
        return real(seed, launch, index)

    monkeypatch.setattr(tracing, "MAX_LANES", limit)
    monkeypatch.setattr(tracing, "LaneSampler", counting)
    chunked = response_maps(pair_layout(), screen, **kw)
    assert len(lanes) == 2 * -(-screen.shape[0] * screen.shape[1] // 7) and max(lanes) <= limit
    np.testing.assert_array_equal(chunked.weights_sr, one.weights_sr)
    np.testing.assert_array_equal(chunked.variance_sr2, one.variance_sr2)
    assert one.weights_sr.max() > 0


def test_ray_groups_launch_within_the_lane_limit(monkeypatch):
    """``trace_groups`` (fast and reference forms) splits its groups at the same limit."""
    _needs_jit()
    from mincam_sim.render.kernels import tracing
    from mincam_sim.render.scene.mincam_scene import MincamScene

    scene = MincamScene.display(pair_layout(), Screen(resolution=(16, 9)))
    scene.set_frame(np.ones((9, 16)))
    lanes = []
    real = tracing.seeded_sampler

    def counting(seed, launch, n):
        lanes.append(n)
        return real(seed, launch, n)

    monkeypatch.setattr(tracing, "seeded_sampler", counting)
    monkeypatch.setattr(tracing, "MAX_LANES", 1000)
    estimates = scene.fast_estimates(4096, 4, seed=1)  # 2 mixels x 4 replicates x 1024 rays
    assert max(lanes) <= 1000 and sum(lanes) == 2 * 4096 and len(lanes) == 16
    assert np.all(estimates > 0)


def test_stratified_passes_launch_within_the_lane_limit(monkeypatch):
    """The stratified dP estimator splits its groups at the one limit too."""
    _needs_jit()
    import drjit as dr
    from test_moving import _world

    from mincam_sim.render.kernels import stratified, tracing
    from mincam_sim.render.kernels.change_region import ApertureRegions

    world, _, bg = _world({}, (0.06, 0.06, 0.03))
    world.update(bg)
    lanes = []
    real = stratified._launch

    def counting(scene, sensor, coeffs, seed, g0, lane_index, *rest):
        lanes.append(dr.width(lane_index))
        return real(scene, sensor, coeffs, seed, g0, lane_index, *rest)

    monkeypatch.setattr(stratified, "_launch", counting)
    monkeypatch.setattr(tracing, "MAX_LANES", 2048)
    stratified.stratified_estimates(world.scene, world.sensor, world.mincam, ApertureRegions.full(world.mincam), 4,
                                    [1024, 512, 512], 4, (1.0, 3.0))
    assert sum(lanes) == 4 * 4 * 2048 and max(lanes) <= 2048
