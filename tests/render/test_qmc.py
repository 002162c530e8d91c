"""Randomised quasi-Monte Carlo points of the stratified estimator (Owen-scrambled Sobol, ``kernels/qmc.py``).

The generator alone: its direction numbers against SciPy's Sobol sequence, the net property of its first ``2^m``
points in every 1D and 2D projection, and integrals with known values over many scrambles (unbiased, and less
variance than independent points). In the estimator: dP against the plain estimator, same seed same numbers,
and per-run honesty of the replicate sigma over 96 seeds (the count of |z| > 4.5 against Poisson, the reported
sigma against the spread over seeds)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from conftest import Z, assert_close_mc

import mincam_sim as ms
from mincam_sim import Pose, cross_layout
from mincam_sim.render import backend
from mincam_sim.render.kernels import qmc
from mincam_sim.render.kernels import stratified as st
from mincam_sim.render.kernels.change_geometry import changed_shapes
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.updates import vertex_update
from mincam_sim.render.solvers.change import STRATA_EXPANSIONS

pytestmark = pytest.mark.skipif(not backend.is_jit(), reason="needs a JIT variant (LLVM or CUDA)")


def _u32(values):
    return backend.mitsuba().UInt32(np.asarray(values, dtype=np.uint32))


def _points(n: int, seed: int) -> np.ndarray:
    """(n, DIMENSIONS) points 0 .. n - 1 of the sequence scrambled by ``seed``."""
    out = qmc.owen_sobol(_u32(np.arange(n)), _u32([seed]))
    return np.stack([np.asarray(p, dtype=np.float64) for p in out], axis=1)


def test_direction_numbers_are_joe_kuos():
    """Unscrambled, the generator is SciPy's Sobol sequence (Joe-Kuo directions; SciPy in Gray-code order)."""
    from scipy.stats import qmc as scipy_qmc

    i = np.arange(1 << 10, dtype=np.uint32)
    gray = _u32(i ^ (i >> 1))
    ours = np.stack([np.asarray(qmc.sobol_u32(gray, d), dtype=np.float64) / 2.0**32 for d in range(qmc.DIMENSIONS)],
                    axis=1)
    np.testing.assert_array_equal(ours, scipy_qmc.Sobol(qmc.DIMENSIONS, scramble=False).random_base2(10))


def _boxes_hold(points: np.ndarray, k: int, m_minus_t: int) -> bool:
    """Whether every ``2^-k x 2^-(m - t - k)`` box of a 2D point set holds the same number of points."""
    cells = (np.floor(points[:, 0] * 2**k).astype(int) << (m_minus_t - k)) + np.floor(
        points[:, 1] * 2 ** (m_minus_t - k)).astype(int)
    counts = np.bincount(cells, minlength=1 << m_minus_t)
    return bool(counts.min() == counts.max())


def _t_value(points: np.ndarray, m: int) -> int:
    """The smallest t for which the 2D set of 2^m points is a (t, m, 2)-net (every elementary box of volume
    2^(t - m) holds 2^t points)."""
    return next(t for t in range(m + 1) if all(_boxes_hold(points, k, m - t) for k in range(m - t + 1)))


@pytest.mark.parametrize("seed", [0, 7, 2**32 - 1])
@pytest.mark.parametrize("m", [3, 6, 10])
def test_first_power_of_two_points_are_a_net_in_every_projection(seed, m):
    """The first 2^m points of any scramble: one point per 2^-m interval in every coordinate, and in every 2D
    projection the net quality (t) of the unscrambled Sobol points (SciPy's; Owen scrambling keeps it): t = 0
    for dimensions (0, 1), the aperture point, and t <= 3 for every pair."""
    from scipy.stats import qmc as scipy_qmc

    points = _points(1 << m, seed)
    sobol = scipy_qmc.Sobol(qmc.DIMENSIONS, scramble=False).random_base2(m)
    assert np.all((points >= 0) & (points < 1))
    for d in range(qmc.DIMENSIONS):
        assert np.array_equal(np.bincount(np.floor(points[:, d] * 2**m).astype(int), minlength=1 << m),
                              np.ones(1 << m, dtype=int)), f"dimension {d}"
    for a in range(qmc.DIMENSIONS):
        for b in range(a + 1, qmc.DIMENSIONS):
            t = _t_value(sobol[:, [a, b]], m)
            assert t <= (0 if (a, b) == (0, 1) else 3), f"dimensions {a}, {b}: t = {t}"
            assert all(_boxes_hold(points[:, [a, b]], k, m - t) for k in range(m - t + 1)), \
                f"dimensions {a}, {b}: not a ({t}, {m}, 2)-net after scrambling"


def test_scrambles_differ_and_subsets_draw_what_the_full_set_draws():
    """Two seeds give different points; points drawn for a subset of indices are those of the full set."""
    full = _points(64, 3)
    assert not np.array_equal(full, _points(64, 4))
    picked = np.array([5, 17, 63, 0])
    out = qmc.owen_sobol(_u32(picked), _u32([3]))
    np.testing.assert_array_equal(np.stack([np.asarray(p, dtype=np.float64) for p in out], axis=1), full[picked])
    with pytest.raises(ValueError, match="dims"):
        qmc.owen_sobol(_u32([0]), _u32([0]), qmc.DIMENSIONS + 1)


def test_each_stratum_of_each_group_gets_a_net_of_its_own():
    """The estimator's wiring: in every (group, stratum) with 2^m rays the aperture points are a (0, m, 2)-net and
    the detector points one per 2^-m interval in each coordinate; other groups and strata get other scrambles."""
    import drjit as dr

    mi = backend.mitsuba()
    counts = [64, 16, 16, 8, 8]
    per, groups = sum(counts), 3
    lanes = dr.arange(mi.UInt32, per * groups)
    j, group = lanes % per, lanes // per
    stratum = mi.UInt32(np.repeat(np.arange(len(counts)), counts)[np.asarray(j)].astype(np.uint32))
    u, v, pick = st._sobol_samples(dr, mi, mi.UInt32(77), group, j, stratum, counts)
    u, v = (np.stack([np.asarray(point.x), np.asarray(point.y)], axis=1) for point in (u, v))
    pick = np.asarray(pick)
    start = np.r_[0, np.cumsum(counts)]
    seen = set()
    for g in range(groups):
        for s, n in enumerate(counts):
            rows = g * per + np.arange(start[s], start[s + 1])
            m = int(np.log2(n))
            assert all(_boxes_hold(v[rows], k, m) for k in range(m + 1)), f"group {g}, stratum {s}"
            for x in (u[rows, 0], u[rows, 1], pick[rows]):
                assert np.array_equal(np.sort(np.floor(x * n).astype(int)), np.arange(n)), f"group {g}, stratum {s}"
            seen.add(tuple(np.round(v[rows][:4].ravel(), 6)))
    assert len(seen) == groups * len(counts), "every (group, stratum) must have a scramble of its own"


def _irwin_hall_cdf(x: float, n: int) -> float:
    """P(sum of n independent uniforms on [0, 1) <= x)."""
    return sum((-1) ** k * math.comb(n, k) * (x - k) ** n for k in range(int(math.floor(x)) + 1)) / math.factorial(n)


INTEGRANDS = {  # name -> (f of (points, dims), exact integral over the unit cube)
    "4D corner (discontinuous)": (lambda p: (p[:, :4].sum(1) <= 1.5).astype(float), _irwin_hall_cdf(1.5, 4)),
    "5D half (discontinuous)": (lambda p: (p.sum(1) <= 2.1).astype(float), _irwin_hall_cdf(2.1, 5)),
    "4D smooth product": (lambda p: np.prod(3 * p[:, :4] ** 2, axis=1), 1.0),
}


@pytest.mark.parametrize("name", list(INTEGRANDS))
def test_integrals_over_many_scrambles_are_unbiased_and_beat_independent_points(name):
    """512 scrambles of 64 points each: the mean of the per-scramble estimates is the exact integral within
    4.5 of their standard error, and their variance is below that of 64 independent points."""
    f, exact = INTEGRANDS[name]
    n, scrambles = 64, 512
    index = _u32(np.tile(np.arange(n), scrambles))
    seeds = qmc.hash_u32(_u32(np.repeat(np.arange(scrambles), n)) + 12345)
    points = np.stack([np.asarray(p, dtype=np.float64) for p in qmc.owen_sobol(index, seeds)], axis=1)
    values = f(points)
    estimates = values.reshape(scrambles, n).mean(1)
    sigma = estimates.std(ddof=1) / math.sqrt(scrambles)
    assert_close_mc(estimates.mean(), exact, sigma, what=f"{name}: Owen-scrambled Sobol vs exact")
    independent_var = values.var() / n  # the variance of one point's value over the cube, over n points
    ratio = estimates.var(ddof=1) / independent_var
    assert ratio < 0.6, f"{name}: variance ratio QMC / independent = {ratio:.2f}"


TOY = trimesh.creation.box((0.04, 0.02, 0.02))
TOY.apply_translation((0, 0, 0.01))


@pytest.fixture(scope="module")
def tabletop():
    """4 mixels 0.5 m above a textured table under an area light, a small box moved by its vertices."""
    cam = cross_layout(center=Pose((0.0, 0.0, 0.5), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)))
    table = np.clip(0.4 + 0.1 * np.random.default_rng(0).standard_normal((32, 32)), 0, 1)
    elements = {
        "table": sd.textured_plane(table, 1.0, 1.0, Pose((0, 0, 0), (0, 0, 1)).matrix()),
        "light": sd.area_light(0.4, 0.4, Pose((0, 0, 1.2), (0, 0, -1)).matrix(), 10.0),
        "toy": sd.mesh_object("toy", TOY.vertices + [5.0, 5.0, 0.0], TOY.faces, 0.9),
    }
    world = ms.Simulation(cam, world=elements)
    frame = vertex_update("toy", TOY.vertices + [0.03, 0.01, 0.0])
    background = world.complete_background([frame], vertex_update("toy", TOY.vertices + [5.0, 5.0, 0.0]))
    return world, frame, background


def _dp(world, frame, background, counts, seed: int, replicates: int = 16, sobol: bool = True,
        freeze: bool = False) -> np.ndarray:
    """(replicates, n_mixels) per-replicate dP of one frame: frame and background passes with one seed, as the
    stratified change solver traces them (guided bounces, no lane reuse)."""
    world.update({**background, **frame})
    regions, guide, _ = world.change_reach(changed_shapes(frame, background))
    kw = {"expansions": STRATA_EXPANSIONS, "guide": guide, "max_depth": world.mincam_scene.max_depth,
          "sobol": sobol}
    out = []
    for _ in range(2):
        out.append(st.stratified_estimates(world.scene, world.sensor, world.mincam, regions, replicates, counts,
                                           seed, freeze=world.buffers_key() if freeze else None, **kw))
        world.update(background)
    return out[0] - out[1]


COUNTS = [64, 16, 16, 16, 16]


def test_same_seed_same_numbers_and_frozen_equals_traced(tabletop):
    world, frame, background = tabletop
    first = _dp(world, frame, background, COUNTS, 5)
    assert np.array_equal(first, _dp(world, frame, background, COUNTS, 5))
    assert np.array_equal(first, _dp(world, frame, background, COUNTS, 5, freeze=True))
    assert np.array_equal(first, _dp(world, frame, background, COUNTS, 5, freeze=True))  # replayed
    assert not np.array_equal(first, _dp(world, frame, background, COUNTS, 6))
    assert not np.array_equal(first, _dp(world, frame, background, COUNTS, 5, sobol=False))


def test_sobol_dp_agrees_with_plain_and_is_less_noisy_than_independent_points(tabletop):
    world, frame, background = tabletop
    plain, _ = _plain_reference(world, frame, background)
    qmc_dp = _dp(world, frame, background, [256, 32, 32, 32, 32], 9)
    sigma = qmc_dp.std(0, ddof=1) / 4.0
    assert_close_mc(qmc_dp.mean(0), plain.irradiance_w_m2[0], np.hypot(sigma, plain.stderr_w_m2[0]),
                    what="Sobol stratified dP vs plain dP")
    independent = _dp(world, frame, background, [256, 32, 32, 32, 32], 9, sobol=False)
    var_ratio = float(np.mean(qmc_dp.var(0, ddof=1)) / np.mean(independent.var(0, ddof=1)))
    assert var_ratio < 0.8, f"variance Sobol / independent (jittered) points = {var_ratio:.2f}"


_PLAIN = {}


def _plain_reference(world, frame, background):
    key = id(world)
    if key not in _PLAIN:
        res = world.measure_changes([frame], background, ms.PlainChange(), ms.Budget(spp=1 << 19, replicates=16,
                                                                                      seed=1))
        _PLAIN[key] = (res.dp, res)
    return _PLAIN[key]


def _poisson_tail(count: int, mean: float) -> float:
    """P(N >= count) for N ~ Poisson(mean)."""
    return 1.0 - sum(math.exp(-mean) * mean**k / math.factorial(k) for k in range(count))


def check_per_run_sigma(value: np.ndarray, sigma: np.ndarray, replicates: int, what: str) -> None:
    """Per-run honesty over seeds: ``value`` and ``sigma`` (seeds, n) are each run's dP and its reported
    (replicate) standard error. Each run's value against the mean of the other runs (leave one out: independent
    of it): the count of |z| > 4.5 is consistent with a t distribution of ``replicates - 1`` degrees of freedom
    (Poisson p >= 1e-3), and for every value the variance over seeds matches the mean reported variance
    (chi-square bounds at 1e-3 over all values, widened by the noise of the mean reported variance only)."""
    from scipy import stats

    seeds, n = value.shape
    others = (value.sum(0) - value) / (seeds - 1)
    z = (value - others) / np.sqrt(sigma**2 + np.mean(sigma**2, axis=0) / (seeds - 1))
    beyond = int(np.sum(np.abs(z) > Z))
    expected = z.size * 2 * stats.t.sf(Z, replicates - 1)
    p = _poisson_tail(beyond, expected)
    assert p >= 1e-3, (f"{what}: {beyond} of {z.size} values beyond {Z} sigma (expected {expected:.2f}, "
                       f"p = {p:.1e}, worst |z| {np.abs(z).max():.1f})")
    ratio = value.var(0, ddof=1) / np.mean(sigma**2, axis=0)  # ~ chi2(seeds - 1) / (seeds - 1) each
    lo, hi = stats.chi2.ppf([5e-4 / n, 1 - 5e-4 / n], seeds - 1) / (seeds - 1)
    noise = 4.5 * math.sqrt(2.0 / (replicates - 1) / seeds)  # relative noise of the mean reported variance
    assert np.all((ratio > lo * (1 - noise)) & (ratio < hi * (1 + noise))), \
        f"{what}: variance over seeds / mean reported variance {np.round(ratio, 2)} (bounds {lo:.2f} .. {hi:.2f})"


def test_reported_sigma_is_honest_over_96_seeds(tabletop):
    """96 seeds of a small budget (16 replicates of 128 rays): |z| > 4.5 as often as the replicate sigma says,
    and the reported sigma is the spread over seeds."""
    world, frame, background = tabletop
    runs = np.stack([_dp(world, frame, background, COUNTS, 1000 + s, freeze=True) for s in range(96)])
    check_per_run_sigma(runs.mean(1), runs.std(1, ddof=1) / 4.0, 16, "Sobol stratified dP, small tabletop")


@pytest.mark.slow
def test_reported_sigma_is_honest_over_96_seeds_on_the_benchmark_scene():
    """The benchmark's moving box (9 frames, 4 mixels, 64 replicates, ~10 k rays per mixel per frame, the solver
    itself with frozen launches and paired lanes): per-run sigma honest over 96 seeds."""
    cam = cross_layout(center=Pose((0.0, 0.0, 0.5), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)))
    table = np.clip(0.4 + 0.1 * np.random.default_rng(0).standard_normal((64, 64)), 0, 1)
    elements = {
        "table": sd.textured_plane(table, 1.0, 1.0, Pose((0, 0, 0), (0, 0, 1)).matrix()),
        "light": sd.area_light(0.4, 0.4, Pose((0, 0, 1.2), (0, 0, -1)).matrix(), 10.0),
        "toy": sd.mesh_object("toy", TOY.vertices + [5.0, 5.0, 0.0], TOY.faces, 0.9),
    }
    world = ms.Simulation(cam, world=elements)
    xs = np.linspace(-0.12, 0.12, 9)
    frames = [vertex_update("toy", TOY.vertices + [x, 0.03 * np.sin(20 * x), 0.0]) for x in xs]
    background = vertex_update("toy", TOY.vertices + [5.0, 5.0, 0.0])
    values, sigmas = [], []
    for s in range(96):
        dp = world.measure_changes(frames, background, ms.StratifiedChange(),
                                   ms.Budget(spp=9830, replicates=64, seed=500 + s)).dp
        values.append(dp.irradiance_w_m2.ravel())
        sigmas.append(dp.stderr_w_m2.ravel())
    check_per_run_sigma(np.array(values), np.array(sigmas), 64, "the benchmark's moving box")
