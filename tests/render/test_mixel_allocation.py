"""Per-mixel replicate allocation of the stratified change solver: each (frame, mixel) value gets the replicates its
own pilot spread asks for at the budget's target, traced as lane subsets of one launch layout."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_close_mc
from test_moving import _world

import mincam_sim as ms
from mincam_sim.render.solvers.change import allocate_replicates, pooled_mean_stderr


def test_allocation_rule():
    """R_k = clip(ceil(R0 (rel / target)^2), floor, most); insignificant or spread-free values get the floor."""
    rng = np.random.default_rng(0)
    r0 = 16
    pilot = np.stack([1.0 + 0.04 * rng.standard_normal(r0),  # rel ~ 0.01: ~ 4 x 16 at target 0.005
                      1.0 + 0.001 * rng.standard_normal(r0),  # tiny spread: the floor
                      0.1 * rng.standard_normal(r0),  # insignificant mean: the floor
                      np.zeros(r0),  # no ray met the change: the floor
                      1.0 + 0.5 * rng.standard_normal(r0)], axis=1)  # far too noisy: capped
    got = allocate_replicates(pilot, 0.005, 24, 256)
    rel = pilot[:, 0].std(ddof=1) / np.sqrt(r0) / abs(pilot[:, 0].mean())
    assert got[0] == int(np.ceil(r0 * (rel / 0.005) ** 2))
    assert list(got[1:]) == [24, 24, 24, 256]


def test_pooled_mean_and_stderr():
    """NaN replicates are left out of the mean; sigma comes from the chosen rows, divided by sqrt(all traced)."""
    rng = np.random.default_rng(1)
    diff = rng.standard_normal((12, 3))
    full_mean, full_err = pooled_mean_stderr(diff)
    np.testing.assert_array_equal(full_mean, diff.mean(0))
    np.testing.assert_array_equal(full_err, diff.std(0, ddof=1) / np.sqrt(12))
    diff[8:, 1] = np.nan
    rows = np.zeros_like(diff, dtype=bool)
    rows[4:] = True
    mean, err = pooled_mean_stderr(diff, rows)
    np.testing.assert_allclose(mean[1], diff[:8, 1].mean())
    np.testing.assert_allclose(err[1], diff[4:8, 1].std(ddof=1) / np.sqrt(8))
    np.testing.assert_allclose(err[0], diff[4:, 0].std(ddof=1) / np.sqrt(12))


def test_group_subsets_draw_what_a_full_pass_draws():
    """Two passes on complementary (replicate, mixel) groups give a full pass's estimates bit for bit, the
    untraced groups NaN; the paired background pass on the same groups equals a full paired pass there."""
    from mincam_sim.render.kernels.change_geometry import watch_box
    from mincam_sim.render.kernels.stratified import stratified_lanes

    world, frames, bg = _world({}, (0.04, 0.02, 0.02))
    frame = frames([(0.03, 0.02, 0.0)])[0]
    world.update(frame)
    regions, guide, _ = world.change_reach({"mover"})
    world.update(bg)
    bg_regions, _, _ = world.change_reach({"mover"})
    regions = regions.union(bg_regions)
    world.update(frame)
    kw = dict(expansions=(1.0, 2.0), guide=guide, max_depth=world.mincam_scene.max_depth)
    watch = [watch_box(world.shapes_by_id["mover"])]
    n, reps, counts = len(world.mincam), 6, [40, 8, 8]
    some = np.zeros((reps, n), dtype=bool)
    some[:2] = True
    some[2:5, 1] = True
    args = (world.scene, world.sensor, world.mincam, regions, reps, counts, 11)
    full = stratified_lanes(*args, watch=watch, **kw)
    part = stratified_lanes(*args, watch=watch, groups=some, **kw)
    rest = stratified_lanes(*args, groups=~some, **kw)
    whole = full.estimates()
    np.testing.assert_array_equal(part.estimates()[some], whole[some])
    assert np.isnan(part.estimates()[~some]).all() and np.isnan(rest.estimates()[some]).all()
    np.testing.assert_array_equal(rest.estimates()[~some], whole[~some])
    assert part.traced + rest.traced == full.traced
    watch.append(watch_box(world.shapes_by_id["mover"]))
    world.update(bg)
    watch[1] = watch_box(world.shapes_by_id["mover"])
    bg_full = stratified_lanes(*args, pair=full, **kw).estimates()
    bg_part = stratified_lanes(*args, pair=part, groups=some, **kw).estimates()
    np.testing.assert_array_equal(bg_part[some], bg_full[some])
    assert np.isnan(bg_part[~some]).all()
    with pytest.raises(ValueError, match="groups"):
        stratified_lanes(*args, groups=some[:2], **kw)


def _run(world, frames, bg, seed, replicates=16, **solver):
    budget = ms.Budget(spp=128 * replicates, replicates=replicates, seed=seed, target_rel_stderr=0.02)
    return world.measure_changes(frames, bg, ms.StratifiedChange(**solver), budget)


def test_allocated_run_is_reproducible_frozen_equals_traced_and_says_what_it_traced():
    world, frames, bg = _world({}, (0.04, 0.02, 0.02))
    fr = frames([(0.03, 0.02, 0.0), (-0.05, 0.0, 0.0), (0.16, 0.0, 0.0)])
    one = _run(world, fr, bg, 5)
    two = _run(world, fr, bg, 5)
    world.freeze_launches = world.pair_lanes = False
    traced = _run(world, fr, bg, 5)
    world.freeze_launches = world.pair_lanes = True
    for other in (two, traced):
        np.testing.assert_array_equal(other.dp.irradiance_w_m2, one.dp.irradiance_w_m2)
        np.testing.assert_array_equal(other.dp.stderr_w_m2, one.dp.stderr_w_m2)
    alloc = one.dp.meta["allocation"]
    reps = np.asarray(alloc["replicates_per_frame_and_mixel"])
    assert reps.shape == (3, 4) and alloc["floor_replicates"] == 16 and alloc["max_replicates"] == 64
    assert alloc["sigma_from"] == "pilot"
    assert reps.min() >= 16 and reps.max() <= 64 and reps.max() > reps.min()
    # rays as traced: the frame pass and the (paired) background pass of every replicate traced
    per = alloc["rays_per_frame_pass_per_replicate"]
    assert per * reps.mean() <= one.info.rays_per_mixel_per_frame <= 2 * per * reps.mean() + 1
    # a value sized to the target reaches about it (sigma's own noise aside); unsized ones sit at the floor
    rel = np.abs(one.dp.stderr_w_m2 / one.dp.irradiance_w_m2)
    sized = (reps > 16) & (reps < 64)
    assert sized.any() and np.all(rel[sized] < 0.02 * 1.2)
    for sigma, floor in (("pooled", 16), ("independent", 24)):
        other = _run(world, fr, bg, 5, allocation_sigma=sigma).dp.meta["allocation"]
        assert other["floor_replicates"] == floor and min(map(min, other["replicates_per_frame_and_mixel"])) == floor
    with pytest.raises(ms.InputError, match="allocation_sigma"):
        _run(world, fr, bg, 5, allocation_sigma="mine")


def test_allocated_dp_agrees_with_plain_reference():
    """Unbiased: the allocated dP against the plain estimator at many rays (independent code path)."""
    world, frames, bg = _world({}, (0.04, 0.02, 0.02))
    fr = frames([(0.03, 0.02, 0.0), (-0.05, 0.0, 0.0)])
    plain = world.measure_changes(fr, bg, ms.PlainChange(), ms.Budget(spp=1 << 16, replicates=16, seed=3)).dp
    for seed in (21, 22):
        fast = _run(world, fr, bg, seed).dp
        sigma = np.hypot(fast.stderr_w_m2, plain.stderr_w_m2)
        assert_close_mc(fast.irradiance_w_m2, plain.irradiance_w_m2, sigma, what=f"allocated vs plain, seed {seed}")


def test_allocated_sigma_matches_spread_over_seeds():
    """Stein's two-stage sigma (the default) against the scatter of dP over 12 independent seeds, pooled over
    frames and mixels (chi-square bounds at ~1e-4 false-alarm probability), and at most one |z| of 96 beyond 4.5
    against the seeds' mean (a 24-replicate pilot: Student's t with 23 degrees of freedom)."""
    from scipy.stats import chi2

    world, frames, bg = _world({}, (0.04, 0.02, 0.02))
    fr = frames([(0.03, 0.02, 0.0), (-0.05, 0.0, 0.0)])
    runs = [_run(world, fr, bg, 300 + s, replicates=24).dp for s in range(12)]
    values = np.stack([r.irradiance_w_m2 for r in runs])
    sigma = np.stack([r.stderr_w_m2 for r in runs])
    dof = values[0].size * (len(runs) - 1)
    ratio = float(np.sum(values.var(axis=0, ddof=1)) / np.sum(np.mean(sigma**2, axis=0)))
    # sigma's own noise (R0 - 1 = 23 degrees of freedom) widens the bounds a little: 30 % allowance
    lo, hi = chi2.ppf(1e-4 / 2, dof) / dof / 1.3, chi2.ppf(1 - 1e-4 / 2, dof) / dof * 1.3
    assert lo < ratio < hi, f"spread / reported variance = {ratio:.2f}, bounds {lo:.2f} .. {hi:.2f}"
    z = (values - values.mean(axis=0)) / sigma
    assert np.sum(np.abs(z) > 4.5) <= 1, f"|z| > 4.5 in {np.sum(np.abs(z) > 4.5)} of {z.size} values"


def test_allocated_split_run_gives_the_one_scene_numbers():
    """The extra replicates move the movers scene of a static split back to the frame and again to the
    background: the same numbers bit for bit as the one-scene run (two movers, far origin)."""
    from test_static_split import _world as split_world

    for kw in ({"movers": 2}, {"offset": (1200.0, -800.0, 30.0)}):
        world, frames, background = split_world(**kw)
        runs = []
        for split in (False, True):
            world.split_static = split
            runs.append(world.measure_changes(frames, background, ms.StratifiedChange(),
                                              ms.Budget(spp=1 << 11, replicates=16, seed=5, target_rel_stderr=0.02)))
        one, two = runs
        assert two.dp.meta["static_geometry"].startswith("split"), two.dp.meta["static_geometry"]
        assert np.asarray(one.dp.meta["allocation"]["replicates_per_frame_and_mixel"]).max() > 16
        for a, b in ((two.dp, one.dp), (two.p, one.p)):
            np.testing.assert_array_equal(a.irradiance_w_m2, b.irradiance_w_m2)
            np.testing.assert_array_equal(a.stderr_w_m2, b.stderr_w_m2)


def test_every_mixel_at_the_maximum_still_pools_per_mixel():
    """A target no pilot part reaches: every mixel of every frame gets the maximum replicates (no replicate left
    untraced), and the run still pools per mixel with the pilot's sigma (Stein), agreeing with the plain estimator."""
    world, frames, bg = _world({}, (0.04, 0.02, 0.02))
    fr = frames([(0.03, 0.02, 0.0)])
    budget = ms.Budget(spp=128 * 16, replicates=16, seed=7, target_rel_stderr=1e-4)
    with pytest.warns(UserWarning):  # the target is missed: said, not hidden
        fast = world.measure_changes(fr, bg, ms.StratifiedChange(), budget).dp
    reps = np.asarray(fast.meta["allocation"]["replicates_per_frame_and_mixel"])
    assert np.all(reps == 64), reps
    plain = world.measure_changes(fr, bg, ms.PlainChange(), ms.Budget(spp=1 << 16, replicates=16, seed=3)).dp
    assert_close_mc(fast.irradiance_w_m2, plain.irradiance_w_m2, np.hypot(fast.stderr_w_m2, plain.stderr_w_m2),
                    what="every mixel at the maximum vs plain")
