"""A mixel that cannot see a frame's change: with direct light only (``max_depth`` 2) its change region is empty,
every replicate of its dP is exactly 0, and that is the answer, not a rare light path that no ray met."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh

import mincam_sim as ms
from mincam_sim import Pose, masks
from mincam_sim.model.optics import Mincam, Mixel
from mincam_sim.render import backend
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.solvers.change import HeavyTailWarning

pytestmark = pytest.mark.skipif(not backend.is_jit(), reason="needs a JIT variant (LLVM or CUDA)")


def test_a_change_out_of_a_mixels_view_is_not_retried_nor_flagged():
    """A block moves on a lit floor into mixel a's view; mixel b, 0.6 m away, sees neither it nor its shadow. b's
    dP was 0 in every replicate, so the frame was traced again with 4x the replicates and a HeavyTailWarning said
    b 'saw no ray meet a change' (a rare, heavy light path): neither was so. Now no retry and no warning; b reads
    0 +- 0, and a the change the plain estimator reads (within 4 sigma; the block darkens its view)."""
    mixels = (Mixel(masks.constant(1.0), pose=Pose((0.0, 0.0, 0.5), (0.1, 0.0, -1.0), (0.0, 1.0, 0.0)), name="a"),
              Mixel(masks.constant(1.0), pose=Pose((0.6, 0.0, 0.5), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)), name="b"))
    box = trimesh.creation.box((0.04, 0.03, 0.02))
    parked, placed = np.array([5.0, 5.0, 0.01]), np.array([0.05, 0.0, 0.01])
    world = {"lamp": sd.area_light(0.2, 0.2, Pose((0.0, 0.0, 1.0), (0.0, 0.0, -1.0)).matrix(), 20.0),
             "floor": sd.textured_plane(np.full((4, 4), 0.5), 12.0, 12.0, Pose((0, 0, 0), (0, 0, 1)).matrix()),
             "block": sd.mesh_object("block", np.asarray(box.vertices) + parked, np.asarray(box.faces), 0.0)}
    sim = ms.Simulation(Mincam(mixels), world=world, max_depth=2)
    frame = {"block.vertex_positions": (np.asarray(box.vertices) + placed).ravel()}
    budget = ms.Budget(spp=1 << 14, replicates=8, seed=3)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        ch = sim.measure_changes([frame], {}, ms.StratifiedChange(), budget)
    assert [str(w.message) for w in said if issubclass(w.category, HeavyTailWarning)] == []
    assert ch.dp.meta["retried_frames"] == [] and ch.dp.meta["no_ray_met_the_change"] == []
    assert ch.dp.irradiance_w_m2[0, 1] == 0.0 and ch.dp.stderr_w_m2[0, 1] == 0.0
    plain = sim.measure_changes([frame], {}, ms.PlainChange(), ms.Budget(spp=1 << 16, replicates=8, seed=4))
    dp, sigma = ch.dp.irradiance_w_m2[0, 0], np.hypot(ch.dp.stderr_w_m2[0, 0], plain.dp.stderr_w_m2[0, 0])
    assert dp < -10 * ch.dp.stderr_w_m2[0, 0]
    assert abs(dp - plain.dp.irradiance_w_m2[0, 0]) < 4 * sigma, (dp, plain.dp.irradiance_w_m2[0, 0], sigma)
