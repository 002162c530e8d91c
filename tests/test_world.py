"""General scenes: the fast mixel sensor in a tabletop world, parameter updates, correlated-seed changes."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from conftest import assert_close_mc

from mincam_sim import Pose, masks, single
from mincam_sim.closed_forms import open_aperture_irradiance
from mincam_sim.optics import cross_layout
from mincam_sim.render import scene_dicts as sd
from mincam_sim.render.world import WorldRenderer, vertex_update

HEIGHT = 0.5
PARK = np.array([5.0, 5.0, 0.0])


def _world(cam, albedo=0.5, sky=2.0, replicates=16):
    box = trimesh.creation.box((0.05, 0.05, 0.05))
    box.apply_translation((0, 0, 0.025))
    elements = {
        "table": sd.textured_plane(np.full((4, 4), albedo), 1.0, 1.0, Pose((0, 0, 0), (0, 0, 1)).matrix()),
        "sky": sd.sky(sky),
        "box": sd.mesh_object("box", box.vertices + PARK, box.faces, 0.9),
    }
    return WorldRenderer(cam, elements, replicates=replicates), box


def test_plane_under_sky_matches_view_factor():
    """A Lambertian plane (albedo rho) lit by a uniform sky L has radiance rho L; an open mixel 0.5 m above it
    measures pi rho L F with F the closed-form view factor of the plane seen through the aperture."""
    cam = single(masks.constant(1.0), pose=Pose((0, 0, HEIGHT), (0, 0, -1), (0, 1, 0)))
    world, _ = _world(cam)
    est = world.estimates(1 << 20, seed=0)
    value, sigma = est.mean(0)[0], est.std(0, ddof=1)[0] / np.sqrt(len(est))
    expected = open_aperture_irradiance(0.5 * 2.0, 1e-4, 2e-3, 2e-3, 2e-3, (-0.5, 0.5, -0.5, 0.5), HEIGHT)
    assert sigma / expected < 0.002
    assert_close_mc(value, expected, sigma, what="plane under sky")


@pytest.fixture(scope="module")
def moving_box():
    cam = cross_layout(center=Pose((0, 0, HEIGHT), (0, 0, -1), (0, 1, 0)))
    world, box = _world(cam, replicates=8)
    frames = [vertex_update("box", box.vertices + [x, 0.02, 0.0]) for x in (-0.08, 0.0, 0.08)]
    return world, frames, vertex_update("box", box.vertices + PARK)


def test_correlated_seeds_cancel_noise_in_changes(moving_box):
    """dP with the background's seed has a much smaller standard error than with independent seeds, and
    both estimate the same change."""
    world, frames, background = moving_box
    corr, _ = world.measure_changes(frames, background, spp=1 << 16, seed=1, correlated=True)
    indep, _ = world.measure_changes(frames, background, spp=1 << 16, seed=1, correlated=False)
    ratio = np.mean(indep.stderr_w_m2**2) / np.mean(corr.stderr_w_m2**2)
    assert ratio > 4, f"variance reduction only {ratio:.1f}x"
    assert_close_mc(corr.irradiance_w_m2, indep.irradiance_w_m2, np.hypot(corr.stderr_w_m2, indep.stderr_w_m2),
                    what="correlated vs independent dP")
    # the x mixel sees the box move from its dark (left) to its bright (right) side
    assert corr.irradiance_w_m2[2, 0] > corr.irradiance_w_m2[0, 0]


def test_change_target_noise_and_resume(moving_box, tmp_path):
    world, frames, background = moving_box
    dp, _ = world.measure_changes(frames, background, spp=1 << 16, seed=2, target_rel_stderr=0.05)
    assert dp.meta["pilot_worst_rel_stderr"] > 0.05  # the pilot alone was not enough
    assert dp.meta["reached_rel_stderr"] <= 0.05
    assert dp.meta["spp_per_mixel_per_frame"] > 1 << 16
    a, _ = world.measure_changes(frames, background, spp=1 << 14, seed=3, out_dir=tmp_path)
    b, _ = world.measure_changes(frames, background, spp=1 << 14, seed=3, out_dir=tmp_path)  # all frames done
    np.testing.assert_array_equal(a.irradiance_w_m2, b.irradiance_w_m2)


def test_unknown_parameter_is_a_clear_error(moving_box):
    world, _, _ = moving_box
    with pytest.raises(KeyError, match="unknown scene parameter"):
        world.update({"car.vertex_positions": np.zeros(3)})
