"""Several movers: a rectangle per mover (and per mover's background place) instead of their union, sampled by
multi-sample importance sampling (balance heuristic, the whole aperture as the defensive technique).

Checked against independent references: P from rectangle sets of every kind against the aperture kernel, dP of 2
and 8 movers against the plain estimator at many rays; the rectangles used are each mover's own (a far mover's is
empty); frozen launches and paired background lanes equal traced and full passes bit for bit with several
rectangles; the reported sigma matches the spread of dP over 16 seeds of 8 movers."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from conftest import assert_close_mc
from front import changes, tilted_table_world

import mincam_sim as ms
from mincam_sim import Pose
from mincam_sim.model.optics import cross_layout
from mincam_sim.render import backend
from mincam_sim.render.kernels import change_region
from mincam_sim.render.kernels.change_region import (
    ApertureRegions,
    RegionSet,
    mover_regions,
)
from mincam_sim.render.kernels.stratified import stratified_estimates
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.updates import vertex_update
from mincam_sim.render.solvers import change as change_module
from mincam_sim.render.solvers.change import STRATA_EXPANSIONS

pytestmark = pytest.mark.skipif(not backend.is_jit(), reason="needs a JIT variant (LLVM or CUDA)")

TOY = trimesh.creation.box((0.04, 0.02, 0.02))
TOY.apply_translation((0, 0, 0.01))
PARK = np.array([5.0, 5.0, 0.0])  # [m] where the movers wait, out of view


def _world(n_movers: int, radius_m: float = 0.1, far: tuple[int, ...] = ()):
    """4 mixels 0.5 m over a textured table under an area light, ``n_movers`` boxes parked out of view; the frames
    carry them around a circle of ``radius_m`` (the movers in ``far`` stay 0.6 m away, out of view)."""
    cam = cross_layout(center=Pose((0.0, 0.0, 0.5), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)))
    table = np.clip(0.4 + 0.1 * np.random.default_rng(2).standard_normal((32, 32)), 0, 1)
    elements = {"table": sd.textured_plane(table, 1.2, 1.2, Pose((0, 0, 0), (0, 0, 1)).matrix()),
                "light": sd.area_light(0.4, 0.4, Pose((0, 0, 1.2), (0, 0, -1)).matrix(), 10.0)}
    background = {}
    for k in range(n_movers):
        parked = TOY.vertices + PARK + [k, 0.0, 0.0]
        elements[f"toy{k}"] = sd.mesh_object(f"toy{k}", parked, TOY.faces, 0.9)
        background.update(vertex_update(f"toy{k}", parked))
    angles = np.linspace(0, 2 * np.pi, n_movers, endpoint=False) + 0.3
    centres = [(0.6, 0.0) if k in far else (radius_m * np.cos(a), radius_m * np.sin(a))
               for k, a in enumerate(angles)]

    def frames(shifts_m):
        return [{key: value for k, (cx, cy) in enumerate(centres)
                 for key, value in vertex_update(f"toy{k}", TOY.vertices + [cx + dx, cy, 0.0]).items()}
                for dx in shifts_m]

    return ms.Simulation(cam, world=elements), frames, background


def _spy(monkeypatch) -> list:
    """The regions every stratified pass of the change solver samples."""
    seen, real = [], change_module.stratified_lanes

    def spying(scene, sensor, mincam, regions, *args, **kwargs):
        seen.append(regions)
        return real(scene, sensor, mincam, regions, *args, **kwargs)

    monkeypatch.setattr(change_module, "stratified_lanes", spying)
    return seen


# ------------------------------------------------------------------------------------------ the rectangles


def test_each_mover_in_view_has_its_own_rectangle_and_a_far_one_none():
    """Three movers, two in view 20 cm apart and one 0.6 m away: every mixel keeps two rectangles, each one a
    mover's own region; the far mover's region is empty for every mixel (its rays go nowhere), and the two
    rectangles cover far less of the aperture than the one rectangle that holds both."""
    world, frames, background = _world(3, far=(2,))
    world.update({**background, **frames([0.0])[0]})
    each, guide, why = world.change_reach_each(["toy0", "toy1", "toy2"])
    assert not why and guide
    assert np.all(each[2].is_empty()), "the far mover must not be in view"
    assert not np.any(each[0].is_empty()) and not np.any(each[1].is_empty())
    apart = mover_regions(each)
    assert isinstance(apart, RegionSet) and apart.n_regions == 2
    assert np.all(apart.distinct == 2)
    for m in range(len(world.mincam)):
        slots = {tuple(apart.base[m, k]) for k in range(2)}
        assert slots == {tuple(each[0].base[m]), tuple(each[1].base[m])}, f"mixel {m}: not the movers' own"
    union = each[0].union(each[1]).union(each[2])
    assert np.all(apart.area_fraction() < 0.5 * union.area_fraction())


def test_overlapping_rectangles_merge_and_the_count_is_capped():
    """Nested or overlapping rectangles merge into their bounding rectangle (as ``union`` does), disjoint ones stay
    apart (in a power-of-two count of slots), and beyond ``max_regions`` the pair that adds the least area merges;
    each expansion's rays split over the rectangles by area, one at least each."""
    n, half = 2, np.full(2, 1e-3)

    def rect(lo_x, lo_y, hi_x, hi_y):
        return ApertureRegions(np.tile([lo_x, lo_y, hi_x, hi_y], (n, 1)).astype(float), np.zeros((n, 4)), half)

    a, b, c, d = rect(0.1, 0.1, 0.2, 0.2), rect(0.15, 0.12, 0.25, 0.2), rect(0.6, 0.6, 0.7, 0.7), rect(0.6, 0.1,
                                                                                                        0.7, 0.2)
    merged = mover_regions([a, b, c])
    assert merged.n_regions == 2 and np.all(merged.distinct == 2)
    assert {tuple(merged.base[0, k]) for k in range(2)} == {tuple(a.union(b).base[0]), tuple(c.base[0])}
    three = mover_regions([a, c, d])  # slots: a power of two, the spare one empty and without rays
    assert three.n_regions == 4 and np.all(three.distinct == 3) and np.all(three.region(3).is_empty())
    assert np.all(three.allocation([600], (1.0,))[:, 0] == [200, 200, 200, 0])
    capped = mover_regions([a, c, d], max_regions=2)
    assert capped.n_regions == 2
    assert tuple(a.union(d).base[0]) in {tuple(capped.base[0, k]) for k in range(2)}, "a and d lie closest"
    nothing = mover_regions([rect(1.0, 1.0, 0.0, 0.0), rect(1.5, 1.5, 1.7, 1.8)])
    assert nothing.n_regions == 1 and np.all(nothing.distinct == 0)
    full = mover_regions([a, rect(-np.inf, -np.inf, np.inf, np.inf)])
    assert full.n_regions == 1 and not np.any(np.isfinite(full.base))
    alloc = merged.allocation([600, 100], (1.0, 2.0))
    assert alloc.shape == (n, 2, 2) and np.all(alloc.sum(axis=2) == [600, 100]) and np.all(alloc >= 1)
    with pytest.raises(ValueError, match="max_regions"):
        mover_regions([a], max_regions=0)


def test_mixels_whose_rectangles_lie_apart_keep_them_as_the_merging_loop_would(monkeypatch):
    """The rectangles of every mixel checked at once for lying apart give the same rectangle set, bit for bit, as
    the pairwise merging loop run on each mixel alone (random rectangles, 64 mixels: apart, overlapping,
    nested, off the aperture, unbounded, more than ``max_regions``)."""
    rng = np.random.default_rng(7)
    n = 64
    half = rng.uniform(1e-4, 3e-3, n)
    parts = []
    for _ in range(10):
        lo = rng.uniform(-0.2, 1.0, (n, 2))
        hi = lo + rng.uniform(0.01, 0.3, (n, 2)) * (rng.uniform(size=(n, 1)) < 0.9)  # some empty (hi <= lo)
        base = np.concatenate([lo, hi], axis=1)
        base[rng.uniform(size=n) < 0.02] = [-np.inf, -np.inf, np.inf, np.inf]
        slope = np.sort(rng.uniform(-3.0, 3.0, (n, 2, 2)), axis=2).reshape(n, 4)
        parts.append(ApertureRegions(base, slope, half))
    for count, cap in ((3, 8), (6, 8), (10, 8), (10, 4)):
        fast = mover_regions(parts[:count], max_regions=cap)
        monkeypatch.setattr(change_region, "_already_apart", lambda base, *a: np.zeros(len(base), dtype=bool))
        loop = mover_regions(parts[:count], max_regions=cap)
        monkeypatch.undo()
        assert np.array_equal(fast.distinct, loop.distinct)
        assert np.array_equal(fast.base, loop.base) and np.array_equal(fast.slope, loop.slope)
    six = parts[:6]
    seen = ~np.stack([p.is_empty() for p in six], axis=1)
    apart = change_region._already_apart(np.stack([p.base for p in six], axis=1),
                                         np.stack([p.slope for p in six], axis=1), seen, half, 8)
    assert 0 < apart.sum() < n  # both ways were taken


def test_the_solver_samples_per_mover_rectangles_and_one_mover_keeps_the_nested_strata(monkeypatch):
    """Two movers apart: the frame and background passes sample a RegionSet of two rectangles; one mover: the one
    rectangle (ApertureRegions, nested strata), as before."""
    seen = _spy(monkeypatch)
    world, frames, background = _world(2)
    changes(world, frames([0.0]), background, spp=512, seed=1, solver=ms.StratifiedChange())
    assert seen and all(isinstance(r, RegionSet) and r.n_regions == 2 for r in seen)
    seen.clear()
    world, frames, background = _world(1)
    changes(world, frames([0.0]), background, spp=512, seed=1, solver=ms.StratifiedChange())
    assert seen and all(isinstance(r, ApertureRegions) for r in seen)


# ------------------------------------------------------------------------------------------ unbiased


@pytest.fixture(scope="module")
def still():
    """A tilted mincam over a textured table (a change-free scene: P itself is checked)."""
    return tilted_table_world()


RECTANGLE_SETS = {
    "apart": [[0.45, 0.40, 0.50, 0.48], [0.1, 0.7, 0.2, 0.8], [0.7, 0.1, 0.75, 0.3]],
    "overlapping": [[0.3, 0.3, 0.6, 0.6], [0.4, 0.4, 0.7, 0.5]],
    "across the edge, off, empty": [[0.8, -0.2, 1.3, 0.3], [1.5, 1.5, 1.7, 1.8], [1.0, 1.0, 0.0, 0.0],
                                    [0.2, 0.25, 0.3, 0.3]],
    "one unbounded": [[0.45, 0.40, 0.50, 0.48], [-np.inf, -np.inf, np.inf, np.inf]],
    "sliding with the detector point": [[0.4, 0.4, 0.5, 0.5], [0.1, 0.1, 0.15, 0.2]],
}


@pytest.mark.parametrize("case", list(RECTANGLE_SETS))
def test_mis_weights_add_up_to_the_whole_aperture(still, case):
    """P from several rectangles per mixel (apart, overlapping, across the aperture's edge, off it, empty,
    unbounded, sliding with the detector point) equals the aperture kernel's independent P within sigma."""
    still.update({})
    plain = still.mincam_scene.fast_estimates(1 << 17, 16, 1)
    n = len(still.mincam)
    half = np.array([0.5 * m.detector_size_m for m in still.mincam])
    slope = np.array([-300.0, 200.0, -250.0, 350.0]) if case.startswith("sliding") else np.zeros(4)
    rects = RECTANGLE_SETS[case]
    base = np.tile(np.asarray(rects, float)[None], (n, 1, 1))
    regions = RegionSet(base, np.tile(slope, (n, len(rects), 1)), half, np.full(n, len(rects)))
    strat = stratified_estimates(still.scene, still.sensor, still.mincam, regions, 16, [1200, 300, 300, 300, 300],
                                 seed=2, expansions=STRATA_EXPANSIONS)
    sigma = np.hypot(plain.std(0, ddof=1), strat.std(0, ddof=1)) / np.sqrt(16)
    assert_close_mc(strat.mean(0), plain.mean(0), sigma, what=f"MIS P ({case}) vs independent P")
    assert np.all(sigma < 0.01 * plain.mean(0)), "the check should resolve 1 % of P"


@pytest.mark.parametrize("n_movers", [2, 8])
def test_several_movers_agree_with_the_plain_estimator(monkeypatch, n_movers):
    """dP and P of 2 and 8 movers (rectangles apart) against the plain estimator at many rays, every frame and
    mixel within 4.5 combined sigma; the comparison resolves a few % of the change."""
    seen = _spy(monkeypatch)
    world, frames, background = _world(n_movers)
    fr = frames([-0.03, 0.0, 0.04])
    plain_dp, plain_p = changes(world, fr, background, spp=1 << 17, seed=3)
    fast_dp, fast_p = changes(world, fr, background, spp=1 << 14, seed=4, solver=ms.StratifiedChange())
    assert any(getattr(r, "n_regions", 1) >= 2 for r in seen), "the frames must sample several rectangles"
    for what, a, b in (("dP", fast_dp, plain_dp), ("P", fast_p, plain_p)):
        sigma = np.hypot(a.stderr_w_m2, b.stderr_w_m2)
        assert_close_mc(a.irradiance_w_m2, b.irradiance_w_m2, sigma,
                        what=f"stratified vs plain {what}, {n_movers} movers")
    resolution = np.hypot(fast_dp.stderr_w_m2, plain_dp.stderr_w_m2) / np.abs(plain_dp.irradiance_w_m2)
    assert np.all(resolution < 0.1), f"the comparison resolves only {resolution.max():.1%} of a change"


def test_several_movers_with_per_mixel_replicates_agree_with_the_plain_estimator(monkeypatch):
    """Per-mover rectangles and per-mixel replicate allocation together (a target): 8 movers' dP against the plain
    estimator at many rays, and the extra replicates sample the movers' rectangles too."""
    seen = _spy(monkeypatch)
    world, frames, background = _world(8)
    fr = frames([-0.02, 0.03])
    plain_dp, _ = changes(world, fr, background, spp=1 << 17, seed=3)
    fast = world.measure_changes(fr, background, ms.StratifiedChange(),
                                 ms.Budget(spp=1 << 12, replicates=16, seed=5, target_rel_stderr=0.004)).dp
    reps = np.asarray(fast.meta["allocation"]["replicates_per_frame_and_mixel"])
    assert reps.max() > 16, "some value must have been sized above the pilot part"
    assert sum(getattr(r, "n_regions", 1) >= 2 for r in seen) >= 4, "pilot and extra passes sample the rectangles"
    assert_close_mc(fast.irradiance_w_m2, plain_dp.irradiance_w_m2, np.hypot(fast.stderr_w_m2, plain_dp.stderr_w_m2),
                    what="allocated stratified vs plain dP, 8 movers")


# ------------------------------------------------------------------------------------------ bit for bit


def test_frozen_and_paired_passes_with_several_rectangles_equal_traced_full_ones(monkeypatch):
    """With rectangles per mover (8 movers): frozen launches give the traced numbers, and the paired background
    (only lanes whose paths met a mover traced again) gives a full background pass's numbers, bit for bit."""
    seen = _spy(monkeypatch)
    world, frames, background = _world(8)
    fr = frames([-0.02, 0.0, 0.02])
    runs = []
    for freeze, pair in ((False, False), (True, False), (False, True), (True, True), (True, True)):
        world.freeze_launches, world.pair_lanes = freeze, pair
        runs.append(changes(world, fr, background, spp=2048, seed=6, solver=ms.StratifiedChange()))
    assert all(getattr(r, "n_regions", 1) == 8 for r in seen)
    (dp0, p0), rest = runs[0], runs[1:]
    for dp, p in rest:
        for a, b in ((dp0, dp), (p0, p)):
            assert np.array_equal(a.irradiance_w_m2, b.irradiance_w_m2)
            assert np.array_equal(a.stderr_w_m2, b.stderr_w_m2)
    assert runs[2][0].meta["paired_lanes_reused"] and runs[2][0].meta["background_rays_share"] < 1.0
    assert np.all(np.abs(dp0.irradiance_w_m2) > 4 * dp0.stderr_w_m2), "the test needs changes it can see"


# ------------------------------------------------------------------------------------------ sigma


def test_reported_sigma_matches_the_spread_over_16_seeds_of_8_movers():
    """Over 16 seeds of 8 movers, the variance of dP over seeds against the mean reported variance, per frame and
    mixel: each ratio ~ chi2(15) / 15, within its 1e-4 / (cells) quantiles (widened by the reported variance's
    own noise, as tests/render/test_qmc.py)."""
    from scipy import stats

    world, frames, background = _world(8)
    fr = frames([-0.03, 0.03])
    seeds, replicates = 16, 8
    runs = [changes(world, fr, background, spp=4096, seed=200 + s, solver=ms.StratifiedChange(),
                    replicates=replicates)[0] for s in range(seeds)]
    value = np.stack([r.irradiance_w_m2 for r in runs])  # (seeds, frames, mixels)
    sigma = np.stack([r.stderr_w_m2 for r in runs])
    assert np.all(np.abs(value.mean(0)) > 10 * value.std(0, ddof=1) / np.sqrt(seeds)), "changes must be resolved"
    ratio = value.var(0, ddof=1) / np.mean(sigma**2, axis=0)
    cells = ratio.size
    lo, hi = stats.chi2.ppf([1e-4 / cells, 1 - 1e-4 / cells], seeds - 1) / (seeds - 1)
    noise = 4.5 * np.sqrt(2.0 / (replicates - 1) / seeds)  # relative noise of the mean reported variance
    assert np.all((ratio > lo * (1 - noise)) & (ratio < hi * (1 + noise))), \
        f"variance over seeds / mean reported variance {np.round(ratio, 2)} (bounds {lo:.2f} .. {hi:.2f})"
    dof = cells * (seeds - 1)
    pooled = float(np.mean(ratio))
    lo, hi = stats.chi2.ppf([1e-4, 1 - 1e-4], dof) / dof
    assert lo * (1 - noise) < pooled < hi * (1 + noise), f"pooled ratio {pooled:.2f} ({lo:.2f} .. {hi:.2f})"



@pytest.mark.parametrize("case", ["far_movers", "mirror", "emitter"])
def test_each_movers_regions_at_once_equal_one_look_per_mover(case):
    """``change_regions_each`` (every mover's regions from one look at the scene: what a run reads once for the
    movers' background places) equals ``change_reach`` of each mover alone, bit for bit: two movers apart, one
    seen in a mirror (its image's rectangle joined), and a moving emitter (the whole aperture, and why)."""
    from rare_paths import rare_scene

    world, frames, background = rare_scene(case)
    world.update({**background, **frames[0]})
    names = sorted({key.split(".")[0] for key in frames[0]})
    at_once = world.change_regions_each(names)
    assert list(at_once) == names
    for name in names:
        alone, _, why = world.change_reach([name])
        regions, reason = at_once[name]
        assert np.array_equal(regions.base, alone.base) and np.array_equal(regions.slope, alone.slope)
        assert reason == (why[0] if why else "")
    if case == "emitter":
        assert at_once["glow"][1] and np.all(np.isinf(at_once["glow"][0].base))
