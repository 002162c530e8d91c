"""General scenes: the fast mixel sensor in a tabletop world, parameter updates, correlated-seed changes."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from conftest import assert_close_mc

import mincam_sim as ms
from mincam_sim import Pose, masks, single
from mincam_sim.errors import InputError
from mincam_sim.model.optics import cross_layout
from mincam_sim.oracles.closed_forms import open_aperture_irradiance
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.updates import vertex_update

HEIGHT = 0.5
PARK = np.array([5.0, 5.0, 0.0])


def _p(sim: ms.Simulation, spp: int, seed: int, replicates: int = 16):
    """P of the scene as it stands (the aperture solver), and its standard error, per mixel."""
    m = sim.measure([{}], ms.Aperture(), ms.Budget(spp=spp, seed=seed, replicates=replicates))
    return m.irradiance_w_m2[0], m.stderr_w_m2[0]


def _changes(sim, frames, background, spp, seed, solver=None, replicates=8, **budget):
    return sim.measure_changes(frames, background, solver or ms.PlainChange(),
                               ms.Budget(spp=spp, seed=seed, replicates=replicates, **budget))


def _world(cam, albedo=0.5, sky=2.0):
    box = trimesh.creation.box((0.05, 0.05, 0.05))
    box.apply_translation((0, 0, 0.025))
    elements = {
        "table": sd.textured_plane(np.full((4, 4), albedo), 1.0, 1.0, Pose((0, 0, 0), (0, 0, 1)).matrix()),
        "sky": sd.sky(sky),
        "box": sd.mesh_object("box", box.vertices + PARK, box.faces, 0.9),
    }
    return ms.Simulation(cam, world=elements), box


def test_plane_under_sky_matches_view_factor():
    """A Lambertian plane (albedo rho) lit by a uniform sky L has radiance rho L; an open mixel 0.5 m above it
    measures pi rho L F with F the closed-form view factor of the plane seen through the aperture."""
    cam = single(masks.constant(1.0), pose=Pose((0, 0, HEIGHT), (0, 0, -1), (0, 1, 0)))
    world, _ = _world(cam)
    value, sigma = (v[0] for v in _p(world, 1 << 20, 0))
    expected = open_aperture_irradiance(0.5 * 2.0, 1e-4, 2e-3, 2e-3, 2e-3, (-0.5, 0.5, -0.5, 0.5), HEIGHT)
    assert sigma / expected < 0.002
    assert_close_mc(value, expected, sigma, what="plane under sky")


@pytest.fixture(scope="module")
def moving_box():
    cam = cross_layout(center=Pose((0, 0, HEIGHT), (0, 0, -1), (0, 1, 0)))
    world, box = _world(cam)
    frames = [vertex_update("box", box.vertices + [x, 0.02, 0.0]) for x in (-0.08, 0.0, 0.08)]
    return world, frames, vertex_update("box", box.vertices + PARK)


def test_correlated_seeds_cancel_noise_in_changes(moving_box):
    """dP with the background's seed has a much smaller standard error than with independent seeds, and
    both estimate the same change."""
    world, frames, background = moving_box
    corr = _changes(world, frames, background, 1 << 16, 1, ms.PlainChange(correlated=True)).dp
    indep = _changes(world, frames, background, 1 << 16, 1, ms.PlainChange(correlated=False)).dp
    ratio = np.mean(indep.stderr_w_m2**2) / np.mean(corr.stderr_w_m2**2)
    assert ratio > 4, f"variance reduction only {ratio:.1f}x"
    assert_close_mc(corr.irradiance_w_m2, indep.irradiance_w_m2, np.hypot(corr.stderr_w_m2, indep.stderr_w_m2),
                    what="correlated vs independent dP")
    # the x mixel sees the box move from its dark (left) to its bright (right) side
    assert corr.irradiance_w_m2[2, 0] > corr.irradiance_w_m2[0, 0]


def test_change_target_noise_and_resume(moving_box, tmp_path):
    world, frames, background = moving_box
    dp = _changes(world, frames, background, 1 << 14, 2, target_rel_stderr=0.1).dp
    assert dp.meta["pilot_worst_rel_stderr"] > 0.1  # the pilot alone was not enough
    assert dp.meta["reached_rel_stderr"] <= 0.1
    assert dp.meta["spp_per_mixel_per_frame"] > 1 << 14
    solver, budget = ms.PlainChange(), ms.Budget(spp=1 << 14, seed=3, replicates=8)
    with ms.Run(tmp_path) as run:
        a = run.measure_changes(world, frames, background, solver, budget)
    (tmp_path / "measurements.npz").unlink()  # not finished: the store has every frame done
    with ms.Run(tmp_path) as run:
        b = run.measure_changes(world, frames, background, solver, budget)
    np.testing.assert_array_equal(a.dp.irradiance_w_m2, b.dp.irradiance_w_m2)


def test_unknown_parameter_is_a_clear_error(moving_box):
    world, _, _ = moving_box
    with pytest.raises(InputError, match="unknown scene parameter 'car.vertex_positions'"):
        world.update({"car.vertex_positions": np.zeros(3)})


def _toy_scene(offset_m: np.ndarray, turn_deg: float):
    """The tabletop (table, area light, 4 x 2 x 2 cm toy, cross mincam 0.5 m up) moved rigidly: turned by
    ``turn_deg`` about the vertical, then shifted by ``offset_m``. Returns world, frames, background."""
    c, s = np.cos(np.radians(turn_deg)), np.sin(np.radians(turn_deg))
    rigid = np.eye(4)
    rigid[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    rigid[:3, 3] = offset_m

    def place(points):
        return np.asarray(points, float) @ rigid[:3, :3].T + rigid[:3, 3]

    def pose(position, forward, up=(0.0, 1.0, 0.0)):
        return Pose(tuple(place(position)), tuple(rigid[:3, :3] @ forward), tuple(rigid[:3, :3] @ up))

    cam = cross_layout(center=pose((0.0, 0.0, HEIGHT), (0.0, 0.0, -1.0)))
    table = np.clip(0.4 + 0.1 * np.random.default_rng(0).standard_normal((32, 32)), 0, 1)
    toy = trimesh.creation.box((0.04, 0.02, 0.02))
    toy.apply_translation((0, 0, 0.01))
    elements = {
        "table": sd.textured_plane(table, 1.0, 1.0, pose((0, 0, 0), (0, 0, 1)).matrix()),
        "light": sd.area_light(0.4, 0.4, pose((0.1, 0, 1.2), (0, 0, -1)).matrix(), 10.0),
        "toy": sd.mesh_object("toy", place(toy.vertices + PARK), toy.faces, 0.9),
    }
    world = ms.Simulation(cam, world=elements)
    frames = [vertex_update("toy", place(toy.vertices + [x, 0.02, 0.0])) for x in (-0.05, 0.04)]
    return world, frames, vertex_update("toy", place(toy.vertices + PARK))


def test_rigid_motion_of_the_whole_scene_changes_nothing():
    """The same tabletop at the origin and moved 1 km away and turned by 30 degrees gives the same P and dP within
    the standard error (Mitsuba's ray offsets grow with |p|: built in world coordinates, the toy's dP came out
    3.7 % high, 15 sigma, at 1 km and 1.2 % at 50 m)."""
    results = []
    for offset, turn in ((np.zeros(3), 0.0), (np.array([1000.0, -400.0, 30.0]), 30.0)):
        world, frames, background = _toy_scene(offset, turn)
        ch = _changes(world, frames, background, 1 << 18, 1, ms.StratifiedChange())
        results.append((ch.dp, ch.p))
    (dp0, p0), (dp1, p1) = results
    assert dp0.stderr_w_m2.max() / np.abs(dp0.irradiance_w_m2).min() < 0.006  # 3.7 % would be > 4.5 sigma
    assert_close_mc(dp1.irradiance_w_m2, dp0.irradiance_w_m2, np.hypot(dp0.stderr_w_m2, dp1.stderr_w_m2),
                    what="dP, scene moved 1 km and turned")
    assert_close_mc(p1.irradiance_w_m2, p0.irradiance_w_m2, np.hypot(p0.stderr_w_m2, p1.stderr_w_m2),
                    what="P, scene moved 1 km and turned")


def test_updates_of_a_point_light_a_texture_and_bad_shapes():
    """A point light moved by an update (in world coordinates) renders as one built there; a texture update keeps
    its (rows, cols, channels) shape (it was flattened, and Mitsuba refused it); a wrong size is one clear error."""
    cam = single(masks.constant(1.0), pose=Pose((0, 0, HEIGHT), (0, 0, -1), (0, 1, 0)))

    def world_with_light_at(position):
        elements = {"table": sd.textured_plane(np.full((4, 4), 0.5), 1.0, 1.0, Pose((0, 0, 0), (0, 0, 1)).matrix()),
                    "light": {"type": "point", "position": list(position),
                              "intensity": {"type": "spectrum", "value": 1.0}}}
        return ms.Simulation(cam, world=elements)

    moved = world_with_light_at((0.3, 0.0, 0.6))
    moved.update({"light.position": np.array([-0.1, 0.2, 0.4])})
    built = world_with_light_at((-0.1, 0.2, 0.4))
    (a, _), (b, _) = _p(moved, 1 << 16, 2, 8), _p(built, 1 << 16, 2, 8)
    np.testing.assert_allclose(a, b, rtol=1e-6)
    where = moved.params["light.position"]  # world coordinates, as the update was given
    np.testing.assert_allclose(where, [-0.1, 0.2, 0.4], atol=1e-6)
    key = "table.bsdf.reflectance.data"
    texture = np.array(moved.params[key])
    moved.update({key: texture * 0.5})
    assert np.array(moved.params[key]).shape == texture.shape
    np.testing.assert_allclose(_p(moved, 1 << 16, 2, 8)[0], 0.5 * a, rtol=1e-5)
    with pytest.raises(ValueError, match="texture of shape"):
        moved.update({key: np.zeros(5)})
