"""The stratified estimator's weights, checked on the whole irradiance P (not a change): for any region bounds,
its strata must add up to the aperture's integral. Regions that leave rings beyond the aperture's edge, empty,
unbounded, off the aperture, tiny, or sliding with the detector point, against the independent whole-aperture
estimator of the same scene (a mask that is not uniform, a textured table)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_close_mc
from front import tilted_table_world

from mincam_sim.render.kernels.change_region import ApertureRegions
from mincam_sim.render.kernels.stratified import stratified_estimates
from mincam_sim.render.solvers.change import STRATA_EXPANSIONS

REPLICATES = 16


@pytest.fixture(scope="module")
def world():
    return tilted_table_world()


def _regions(world, base, slope=(0.0, 0.0, 0.0, 0.0)) -> ApertureRegions:
    n = len(world.mincam)
    half = np.array([0.5 * m.detector_size_m for m in world.mincam])
    return ApertureRegions(np.tile(np.asarray(base, float), (n, 1)), np.tile(np.asarray(slope, float), (n, 1)), half)


CASES = {
    "small, inside": ([0.45, 0.40, 0.50, 0.48], (0, 0, 0, 0)),
    "rings beyond the edge": ([0.2, 0.25, 0.7, 0.7], (0, 0, 0, 0)),
    "across the edge": ([0.8, -0.2, 1.3, 0.3], (0, 0, 0, 0)),
    "off the aperture": ([1.5, 1.5, 1.7, 1.8], (0, 0, 0, 0)),
    "empty": ([1.0, 1.0, 0.0, 0.0], (0, 0, 0, 0)),
    "unbounded": ([-np.inf, -np.inf, np.inf, np.inf], (0, 0, 0, 0)),
    "sliding with the detector point": ([0.4, 0.4, 0.5, 0.5], (-300.0, 200.0, -250.0, 350.0)),
}


@pytest.mark.parametrize("case", list(CASES))
def test_strata_add_up_to_the_whole_aperture(world, case):
    world.update({})
    plain = world.mincam_scene.fast_estimates(1 << 17, REPLICATES, 1)  # the aperture kernel
    base, slope = CASES[case]
    strat = stratified_estimates(world.scene, world.sensor, world.mincam, _regions(world, base, slope), REPLICATES,
                                 [1200, 300, 300, 300, 300], seed=2, expansions=STRATA_EXPANSIONS)
    sigma = np.hypot(plain.std(0, ddof=1), strat.std(0, ddof=1)) / np.sqrt(REPLICATES)
    assert_close_mc(strat.mean(0), plain.mean(0), sigma, what=f"stratified P ({case}) vs independent P")
    assert np.all(sigma < 0.01 * plain.mean(0)), "the check should resolve 1 % of P"
