"""A textured plane moving within its own plane, traced once and replayed (``PlaneReplay``'s ``SlidingPlane``).

A slide replays the frame Mitsuba traces with the plane moved there (same seed) to float32 rounding: with the
road's end passing through the view, a tilted plane under a rig 1.2 km from the origin, black occluders and an
area light. A turn also turns the plane's shading frame, so the path tracer's bounce directions (drawn in that
frame) turn with it: its frames agree with the traced ones within their standard errors, not lane by lane.
Scenes where the replay would not be exact are refused with the field and the fix named; the renderer is left
as found."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import mincam_sim as ms
from mincam_sim import Pose, masks
from mincam_sim.errors import InputError
from mincam_sim.model.optics import Mincam, Mixel
from mincam_sim.render import backend
from mincam_sim.render.kernels.monte_carlo import replicate_mean_stderr
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.solvers.plane_replay import SlidingPlane

pytestmark = pytest.mark.skipif(not backend.is_jit(), reason="needs a JIT variant (LLVM or CUDA)")

SPP = 1 << 13
ROUNDING = 2e-5  # float32: the plane's texture coordinates and the albedo product, relative to the value


def _mixel(name: str, position, forward=(0.0, 0.0, -1.0), up=(0.0, 1.0, 0.0)) -> Mixel:
    mask = masks.sinusoid(2 * np.pi / 0.4e-3, 0.5, 0.5, resolution=64, width_m=2e-3)
    return Mixel(mask, 2e-3, 1e-3, Pose(tuple(position), forward, up), name)


def _placement(centre_xy, heading_rad: float, size_m, frame: np.ndarray) -> np.ndarray:
    """The road's to_world in ``frame`` (a rigid 4 x 4): centred at ``centre_xy`` of the frame's plane, turned
    by ``heading_rad``, spanning ``size_m``."""
    c, s = np.cos(heading_rad), np.sin(heading_rad)
    local = np.array([[c, -s, 0, centre_xy[0]], [s, c, 0, centre_xy[1]], [0, 0, 1, 0], [0, 0, 0, 1.0]])
    return frame @ local @ np.diag([size_m[0] / 2, size_m[1] / 2, 1.0, 1.0])


REPLICATES = 4


def estimates(world, spp: int, seed: int, replicates: int = REPLICATES) -> np.ndarray:
    """(replicates, n_mixels) estimates of the aperture solver's kernel, the scene as it stands."""
    return world.mincam_scene.fast_estimates(spp, replicates, seed)


def _road_world(frame: np.ndarray | None = None, extras: dict | None = None, two: bool = False):
    frame = np.eye(4) if frame is None else frame
    rng = np.random.default_rng(3)
    # grain on a gradient across the road and stripes along it: a mirrored or misplaced texture shows
    rows, cols = np.mgrid[0:64, 0:256]
    texture = np.clip(0.15 + 0.6 * rows / 63 + 0.15 * np.sin(cols / 5) + 0.05 * rng.standard_normal((64, 256)),
                      0, 1)
    mixels = [_mixel("a", frame[:3, :3] @ (0.0, 0.02 if two else 0.0, 0.3) + frame[:3, 3],
                     tuple(frame[:3, :3] @ (0, 0, -1.0)), tuple(frame[:3, :3] @ (0, 1.0, 0)))]
    if two:
        mixels.append(_mixel("b", frame[:3, :3] @ (0.0, -0.02, 0.3) + frame[:3, 3],
                             tuple(frame[:3, :3] @ (0.2, 0, -1.0) / np.hypot(0.2, 1)),
                             tuple(frame[:3, :3] @ (0, 1.0, 0))))
    road = sd.textured_plane(texture, 2.0, 2.0, _placement((0.0, 0.0), 0.0, (2.0, 0.5), frame))
    elements = {"road": road, "sky": sd.sky(1.0), **(extras or {})}
    return ms.Simulation(Mincam(tuple(mixels)), world=elements)


def _traced(world, placements, spp: int = SPP, seed: int = 11, replicates: int = REPLICATES) -> np.ndarray:
    out = []
    for m in placements:
        world.update({"road.to_world": m})
        out.append(estimates(world, spp, seed, replicates))
    return np.array(out)


def _assert_replays(world, placements) -> np.ndarray:
    replay = SlidingPlane(world, "road", placements, SPP, 11, REPLICATES)
    replayed = np.array([replay.estimates(m) for m in placements])
    traced = _traced(world, placements)
    np.testing.assert_allclose(replayed, traced, rtol=ROUNDING, atol=ROUNDING * np.abs(traced).max())
    return traced


def _assert_agree(world, placements, spp: int = 1 << 15, replicates: int = REPLICATES) -> float:
    """Replayed and traced frames (seeds of their own) agree within 4.5 combined standard errors; returns the
    largest |z|."""
    replay = SlidingPlane(world, "road", placements, spp, 5, replicates)
    mean_r, se_r = replicate_mean_stderr(np.array([replay.estimates(m) for m in placements]).transpose(1, 0, 2))
    mean_t, se_t = replicate_mean_stderr(_traced(world, placements, spp, 6, replicates).transpose(1, 0, 2))
    z = (mean_r - mean_t) / np.hypot(se_r, se_t)
    assert np.abs(z).max() <= 4.5, z
    assert np.ptp(mean_t) > 10 * se_t.max()  # the frames differ by far more than the noise: a real comparison
    return float(np.abs(z).max())


def test_slides_past_the_road_end():
    """The road's end passes under the mixel: rays that met the road meet the sky below it, and back."""
    frame = np.eye(4)
    placements = [_placement((x, 0.0), 0.0, (2.0, 0.5), frame) for x in np.linspace(-1.6, 1.6, 9)]
    traced = _assert_replays(_road_world(frame), placements)
    assert np.ptp(traced[:, :, 0].mean(axis=1)) > 0.05 * traced.mean()  # the end is in view: values change


def test_turns_agree_within_the_standard_error_with_two_mixels_shadowing_each_other():
    placements = [_placement((0.3 * np.sin(h), 0.1 * h), h, (2.0, 0.5), np.eye(4)) for h in np.linspace(0, 1.2, 6)]
    _assert_agree(_road_world(two=True), placements)


def test_slides_with_two_mixels_shadowing_each_other():
    placements = [_placement((x, 0.2 * x), 0.0, (2.0, 0.5), np.eye(4)) for x in np.linspace(-1.2, 1.2, 6)]
    _assert_replays(_road_world(two=True), placements)


def _tilted_far_world():
    tilt = Pose((1200.0, -300.0, 40.0), (0.3, -0.2, 1.0), (0.0, 1.0, 0.2)).matrix()
    box = trimesh.creation.box((0.05, 0.05, 0.05))
    occluder = (tilt[:3, :3] @ (box.vertices + [0.0, 0.12, 0.2]).T).T + tilt[:3, 3]
    light = tilt @ Pose((0.0, -0.3, 0.6), (0.0, 0.5, -1.0), (0.0, 1.0, 0.0)).matrix()
    extras = {"occluder": sd.mesh_object("occluder", occluder, box.faces, 0.0),
              "lamp": sd.area_light(0.2, 0.2, light, 5.0)}
    return _road_world(tilt, extras), tilt


def test_tilted_plane_far_from_the_origin_with_black_occluder_and_area_light():
    world, tilt = _tilted_far_world()
    placements = [_placement((x, 0.05 * x), 0.0, (2.0, 0.5), tilt) for x in np.linspace(-1.6, 1.6, 7)]
    _assert_replays(world, placements)
    world, tilt = _tilted_far_world()
    turns = [_placement((x, 0.05 * x), 0.4 * x, (2.0, 0.5), tilt) for x in np.linspace(-0.8, 0.8, 5)]
    _assert_agree(world, turns, replicates=8)


def test_leaves_the_renderer_as_found():
    world = _road_world()
    before = {k: np.array(world.params[k]) for k in ("road.to_world", "road.bsdf.reflectance.data")}
    first = estimates(world, SPP, 2)
    SlidingPlane(world, "road", [_placement((0.2, 0.0), 0.0, (2.0, 0.5), np.eye(4))], SPP, 2, REPLICATES)
    for key, value in before.items():
        np.testing.assert_array_equal(np.array(world.params[key]), value)
    np.testing.assert_array_equal(estimates(world, SPP, 2), first)


def _refusal(world, placements, match: str, name: str = "road"):
    with pytest.raises(InputError, match=match):
        SlidingPlane(world, name, placements, SPP, 0, REPLICATES)


def test_refuses_scenes_where_the_replay_is_not_exact():
    flat = [_placement((0.0, 0.0), 0.0, (2.0, 0.5), np.eye(4))]
    grey = {"post": sd.mesh_object("post", trimesh.creation.box((0.02,) * 3).vertices + [0, 0.1, 0.1],
                                   trimesh.creation.box((0.02,) * 3).faces, 0.5)}
    _refusal(_road_world(extras=grey), flat, r"'post'\] reflect too")
    world = _road_world()
    _refusal(world, flat, "no element named 'lawn'", name="lawn")
    lifted = flat[0].copy()
    lifted[2, 3] = 0.01
    _refusal(world, flat + [lifted], r"placements_m\[1\] is not in the plane")
    flipped = flat[0] @ np.diag([1.0, -1.0, -1.0, 1.0])
    _refusal(world, flat + [flipped], r"placements_m\[1\] is not in the plane")
    _refusal(world, [np.eye(3)], "4 x 4")
    _refusal(world, [flat[0] * np.nan], "finite")
    replay = SlidingPlane(world, "road", flat, SPP, 0, REPLICATES)
    with pytest.raises(InputError, match="beyond the placements"):
        replay.estimates(_placement((0.5, 0.0), 0.0, (2.0, 0.5), np.eye(4)))
    with pytest.raises(InputError, match="leaves the plane"):
        replay.estimates(lifted)


def test_a_new_texture_is_replayed_and_any_other_change_refused():
    world = _road_world()
    placements = [_placement((x, 0.0), 0.0, (2.0, 0.5), np.eye(4)) for x in (-0.3, 0.4)]
    replay = SlidingPlane(world, "road", placements, SPP, 11, REPLICATES)
    data = np.array(world.params["road.bsdf.reflectance.data"])
    world.update({"road.bsdf.reflectance.data": (1.0 - data).astype(np.float32)})  # the negative of the road
    traced = _traced(world, placements)
    np.testing.assert_allclose([replay.estimates(m) for m in placements], traced, rtol=ROUNDING,
                               atol=ROUNDING * np.abs(traced).max())
    world.update({"sky.radiance.value": 2.0})
    with pytest.raises(InputError, match=r"the scene changed since .*\['sky.radiance.value'\]"):
        replay.estimates(placements[0])


def test_refuses_a_plane_that_is_not_a_textured_rectangle():
    sphere = {"ball": {"type": "sphere", "bsdf": sd.black_bsdf()}}
    world = _road_world(extras=sphere)
    _refusal(world, [np.eye(4)], "is a Sphere, not a rectangle", name="ball")
    plain = {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": {"type": "spectrum", "value": 0.5}}}
    world = ms.Simulation(Mincam((_mixel("a", (0, 0, 0.3)),)), world={"road": plain, "sky": sd.sky(1.0)})
    _refusal(world, [np.eye(4)], "bitmap reflectance")
    glowing = sd.textured_plane(np.full((4, 4), 0.5), 2.0, 2.0, np.eye(4))
    glowing["emitter"] = {"type": "area", "radiance": {"type": "spectrum", "value": 1.0}}
    world = ms.Simulation(Mincam((_mixel("a", (0, 0, 0.3)),)), world={"road": glowing, "sky": sd.sky(1.0)})
    _refusal(world, [np.eye(4)], "also emits light")


def test_the_front_door_replays_what_the_aperture_solver_traces():
    rng = np.random.default_rng(3)
    texture = np.clip(0.3 + 0.3 * rng.random((32, 128)), 0, 1)
    elements = {"road": sd.textured_plane(texture, 2.0, 2.0, _placement((0, 0), 0, (2.0, 0.5), np.eye(4))),
                "sky": sd.sky(1.0)}
    sim = ms.Simulation(Mincam((_mixel("a", (0, 0, 0.3)), _mixel("b", (0.03, 0, 0.3)))), world=elements)
    frames = [{"road.to_world": _placement((x, 0), 0, (2.0, 0.5), np.eye(4))} for x in np.linspace(-1.5, 1.5, 5)]
    frames.append({})  # the scene as built
    budget = ms.Budget(spp=SPP, replicates=4, seed=9)
    replayed = sim.measure(frames, solver=ms.PlaneReplay("road"), budget=budget)
    traced = sim.measure(frames, solver=ms.Aperture(), budget=budget)
    np.testing.assert_allclose(replayed.irradiance_w_m2, traced.irradiance_w_m2, rtol=ROUNDING)
    np.testing.assert_allclose(replayed.stderr_w_m2, traced.stderr_w_m2, rtol=1e-3,
                               atol=ROUNDING * traced.irradiance_w_m2.max())
    assert replayed.meta["solver"] == "plane_replay"
    with pytest.raises(InputError, match=r"frames\[0\] sets \['sky.radiance.value'\]"):
        sim.measure([{"sky.radiance.value": 2.0}], solver=ms.PlaneReplay("road"), budget=budget)
    with pytest.raises(InputError, match=r"frames\[1\] must be a dict 'name.parameter' -> value, got list"):
        sim.measure([{}, ["road.to_world"]], solver=ms.PlaneReplay("road"), budget=budget)
    with pytest.raises(InputError, match="no parameter 'lawn.to_world'"):
        sim.measure(frames, solver=ms.PlaneReplay("lawn"), budget=budget)


@pytest.mark.slow
def test_each_runs_sigma_is_honest_over_many_seeds():
    """Per run, not on average: over 200 seeds of replayed turning frames at 1 k rays (8 replicates), the count of
    |z| > 4.5 against a traced reference of 2^18 rays is Poisson with the rate Student's t with 7 degrees of
    freedom gives (0.28 %: ~7 of 2,400; two-sided p >= 1e-3), and the reported variance matches the spread over
    seeds. (With 4 replicates the rate is t with 3 degrees of freedom's, 2.1 %: the test once held 4 replicates
    to 8's rate and failed at 2.5 %.)"""
    from scipy import stats

    replicates = 8
    world = _road_world(two=True)
    placements = [_placement((0.3 * np.sin(h), 0.1 * h), h, (2.0, 0.5), np.eye(4)) for h in np.linspace(0, 1.2, 6)]
    reference, ref_se = replicate_mean_stderr(_traced(world, placements, 1 << 18, seed=1).transpose(1, 0, 2))
    means, sigmas = [], []
    for seed in range(200):
        replay = SlidingPlane(world, "road", placements, 1 << 10, 1000 + seed, replicates)
        mean, se = replicate_mean_stderr(np.array([replay.estimates(m) for m in placements]).transpose(1, 0, 2))
        means.append(mean)
        sigmas.append(se)
    means, sigmas = np.array(means), np.array(sigmas)
    z = (means - reference) / np.hypot(sigmas, ref_se)
    assert np.all(sigmas > 0)  # never 0 +- 0
    beyond = int((np.abs(z) > 4.5).sum())
    lo, hi = stats.poisson.ppf([5e-4, 1 - 5e-4], z.size * 2 * stats.t.sf(4.5, replicates - 1))
    assert lo <= beyond <= hi, f"|z| > 4.5 in {beyond} of {z.size} values (Poisson bounds {lo:g}-{hi:g})"
    ratio = float(np.mean(means.var(axis=0, ddof=1) / np.mean(sigmas**2, axis=0)))
    assert 0.8 < ratio < 1.25, f"spread / reported variance = {ratio:.2f}"
