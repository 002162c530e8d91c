"""Frozen launches of the stratified world estimator (``dr.freeze``): every replayed frame equals the traced
one bit for bit on moving geometry (vertex updates and transforms, frame and background passes as
``measure_changes`` runs them), a new budget or a new scene records afresh instead of replaying a stale kernel,
and a moving light is traced unfrozen; the same for the ground-truth camera's images."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from front import changes, estimates

import mincam_sim as ms
from mincam_sim import Pose, cross_layout
from mincam_sim.render import backend
from mincam_sim.render.kernels import frozen as frozen_functions
from mincam_sim.render.kernels import stratified as st
from mincam_sim.render.kernels.change_geometry import changed_shapes
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.elements import transform_update
from mincam_sim.render.scene.mincam_scene import camera_render as render_function
from mincam_sim.render.scene.updates import vertex_update
from mincam_sim.render.solvers.change import STRATA_EXPANSIONS

pytestmark = pytest.mark.skipif(not backend.is_jit(), reason="needs a JIT variant (LLVM or CUDA)")

TOY = trimesh.creation.box((0.04, 0.02, 0.02))
TOY.apply_translation((0, 0, 0.01))


def _sphere_matrix(x_m: float, y_m: float) -> np.ndarray:
    m = np.diag([0.012, 0.012, 0.012, 1.0])
    m[:3, 3] = (x_m, y_m, 0.012)
    return m


def _world(extra: bool = False, moving_light: bool = False, ball: bool = True, camera: bool = False):
    """A textured table under an area light, a box moved by its vertices and (``ball``) a sphere moved by its
    transform (``extra``: one more static shape, so the scene has another shape count; ``camera``: a 24 x 24
    ground-truth camera looking down from the mincam)."""
    cam = cross_layout(center=Pose((0.0, 0.0, 0.5), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)))
    table = np.clip(0.4 + 0.1 * np.random.default_rng(0).standard_normal((32, 32)), 0, 1)
    elements = {
        "table": sd.textured_plane(table, 1.0, 1.0, Pose((0, 0, 0), (0, 0, 1)).matrix()),
        "light": sd.area_light(0.4, 0.4, Pose((0, 0, 1.2), (0, 0, -1)).matrix(), 10.0),
        "toy": sd.mesh_object("toy", TOY.vertices + [5.0, 5.0, 0.0], TOY.faces, 0.9),
        "ball": {"type": "sphere", "to_world": backend.mitsuba().ScalarTransform4f(_sphere_matrix(5.0, -5.0).tolist()),
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.7}}},
    }
    if extra:
        elements["post"] = sd.mesh_object("post", TOY.vertices * 0.5 + [0.3, 0.3, 0.0], TOY.faces, 0.5)
    view = sd.pinhole_camera(Pose((0.0, 0.0, 0.5), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)).matrix(), 40.0, 24, 24,
                             spp=8) if camera else None
    world = ms.Simulation(cam, world=elements, camera=view)
    xs = np.linspace(-0.1, 0.1, 5)
    frames = [{**vertex_update("toy", TOY.vertices + [x, 0.02 * np.sin(20 * x), 0.0]),
               **(transform_update("ball", _sphere_matrix(-x, 0.08)) if ball else {})} for x in xs]
    background = {**vertex_update("toy", TOY.vertices + [5.0, 5.0, 0.0]),
                  **(transform_update("ball", _sphere_matrix(5.0, -5.0)) if ball else {})}
    if moving_light:
        for k, f in enumerate(frames):
            f.update(transform_update("light", Pose((0.01 * k, 0, 1.2), (0, 0, -1)).matrix()
                                      @ np.diag([0.2, 0.2, 1.0, 1.0])))
    return world, frames, background


def _passes(world, frames, background, counts, freeze: bool) -> list[np.ndarray]:
    """Frame and background passes of every frame, in the order measure_changes traces them."""
    out = []
    background = world.complete_background(frames, background)
    for i, frame in enumerate(frames):
        world.update({**background, **frame})
        regions, guide, _ = world.change_reach(changed_shapes(frame, background))
        kw = {"expansions": STRATA_EXPANSIONS, "guide": guide, "max_depth": 3}
        for _ in range(2):
            out.append(st.stratified_estimates(world.scene, world.sensor, world.mincam, regions, 8, counts, 11 + i,
                                               freeze=world.buffers_key() if freeze else None, **kw))
            world.update(background)
    return out


@pytest.mark.parametrize("ball", [False, True], ids=["vertices", "vertices and a transform"])
def test_every_frozen_pass_equals_the_traced_one_bit_for_bit_on_moving_geometry(ball):
    """Frame and background passes of five frames, twice frozen: the same numbers as traced. A moved mesh
    (its vertex buffer at one of a few addresses) replays; a transform moved to a new value records again
    (keyed on its value), and the background passes replay."""
    world, frames, background = _world(ball=ball)
    counts = [40, 8, 8, 8, 8]
    traced = _passes(world, frames, background, counts, freeze=False)
    frozen = _passes(world, frames, background, counts, freeze=True)
    again = _passes(world, frames, background, counts, freeze=True)
    for a, b, c in zip(traced, frozen, again, strict=True):
        assert np.array_equal(a, b) and np.array_equal(a, c)
    recorded = st.frozen_recordings(world.scene)
    most = 2 * len(frames) + 4 if ball else 4
    assert 1 <= recorded <= most, f"{recorded} recordings for {2 * len(frozen)} passes: the launch must replay"
    assert len({tuple(np.round(p.mean(0), 12)) for p in traced[::2]}) == len(frames), "the frames must differ"


def test_measure_changes_frozen_equals_traced_values_and_sigmas():
    world, frames, background = _world()
    runs = {}
    for freeze in (False, True, True):
        world.freeze_launches = freeze
        dp, p = changes(world, frames, background, spp=4096, seed=3, solver=ms.StratifiedChange())
        runs.setdefault(freeze, []).append((dp, p))
    (dp0, p0), = runs[False]
    for dp, p in runs[True]:
        for a, b in ((dp0, dp), (p0, p)):
            assert np.array_equal(a.irradiance_w_m2, b.irradiance_w_m2)
            assert np.array_equal(a.stderr_w_m2, b.stderr_w_m2)
    assert np.all(np.abs(dp0.irradiance_w_m2) > 4 * dp0.stderr_w_m2), "the test needs changes it can see"


def test_a_new_budget_and_a_new_scene_record_instead_of_replaying_a_stale_kernel():
    world, frames, background = _world()
    _passes(world, frames[:2], background, [40, 8, 8, 8, 8], freeze=True)
    before = st.frozen_recordings(world.scene)
    traced = _passes(world, frames[:2], background, [24, 4, 4, 4, 4], freeze=False)
    frozen = _passes(world, frames[:2], background, [24, 4, 4, 4, 4], freeze=True)
    assert st.frozen_recordings(world.scene) > before
    assert all(np.array_equal(a, b) for a, b in zip(traced, frozen, strict=True))

    other, frames2, background2 = _world(extra=True)
    assert len(other.scene.shapes()) == len(world.scene.shapes()) + 1
    assert st.frozen_recordings(other.scene) == 0
    traced = _passes(other, frames2[:2], background2, [40, 8, 8, 8, 8], freeze=False)
    frozen = _passes(other, frames2[:2], background2, [40, 8, 8, 8, 8], freeze=True)
    assert st.frozen_recordings(other.scene) >= 1
    assert all(np.array_equal(a, b) for a, b in zip(traced, frozen, strict=True))


@pytest.mark.filterwarnings("ignore::mincam_sim.render.solvers.change.FallbackWarning")
@pytest.mark.filterwarnings("ignore::mincam_sim.render.solvers.change.HeavyTailWarning")
def test_a_moving_light_is_traced_unfrozen():
    world, frames, background = _world(moving_light=True)
    dp, _ = changes(world, frames[:2], background, spp=320, seed=1, solver=ms.StratifiedChange())
    assert st.frozen_recordings(world.scene) == 0
    world.freeze_launches = False
    dp2, _ = changes(world, frames[:2], background, spp=320, seed=1, solver=ms.StratifiedChange())
    assert np.array_equal(dp.irradiance_w_m2, dp2.irradiance_w_m2)


def _camera_images(world, frames, background, freeze: bool) -> list[np.ndarray]:
    """The camera's image as built (no update yet: the first move then puts the vertices in a new buffer),
    at the background, at every frame and back at the background."""
    world.freeze_launches = freeze
    out = [world.camera_image(spp=8, seed=3)]
    background = world.complete_background(frames, background)  # a moved light back where it was built
    for frame in [background, *frames, background]:
        world.update({**background, **frame})
        out.append(world.camera_image(spp=8, seed=3))
    return out


@pytest.mark.parametrize("ball", [False, True], ids=["vertices", "vertices and a transform"])
def test_frozen_camera_images_equal_the_traced_ones_bit_for_bit_on_moving_geometry(ball):
    """The ground-truth camera's images, replayed from recordings keyed on the moved objects' buffers, equal
    the traced ones bit for bit: from the scene as built (whose first move reallocates the vertices), frame
    after frame, back at the background, and again; a mesh moved by its vertices replays (a few recordings), a
    transform records per value."""
    images = {}
    for label, freeze in (("traced", False), ("frozen", True)):
        world, frames, background = _world(ball=ball, camera=True)  # each run from a scene just built
        images[label] = _camera_images(world, frames, background, freeze=freeze)
        if freeze:
            images["again"] = _camera_images(world, frames, background, freeze=True)
            recorded = frozen_functions.recordings(world.mincam_scene.fast_scene, render_function)
    for a, b in zip(images["traced"], images["frozen"], strict=True):
        assert np.array_equal(a, b)
    assert all(np.array_equal(a, b) for a, b in zip(images["traced"][1:], images["again"][1:], strict=True))
    assert len({img.tobytes() for img in images["traced"][1:]}) == len(frames) + 1, "the frames must differ"
    most = 2 * len(frames) + 4 if ball else 4
    assert 1 <= recorded <= most, f"{recorded} recordings for {2 * len(frames) + 6} images: the render must replay"


def test_a_camera_that_keeps_recording_goes_back_to_tracing():
    """A sphere moved by its transform to a new place every frame keys a new recording every image: after a
    few the camera traces (recording costs more than tracing), with the same images."""
    xs = np.linspace(-0.1, 0.1, 16)
    images = {}
    for freeze in (False, True):
        world, _, background = _world(ball=True, camera=True)
        world.freeze_launches = freeze
        images[freeze] = []
        for x in xs:
            world.update({**background, **transform_update("ball", _sphere_matrix(x, 0.05))})
            images[freeze].append(world.camera_image(spp=8, seed=1))
    assert world._camera_traced
    assert frozen_functions.recordings(world.mincam_scene.fast_scene, render_function) < len(xs)
    assert all(np.array_equal(a, b) for a, b in zip(images[False], images[True], strict=True))


def test_a_moving_light_is_rendered_by_the_camera_unfrozen():
    """Once a light has moved, its sampling tables live where a replay cannot see them: every later image is
    traced (the same images as a run traced throughout)."""
    world, frames, background = _world(moving_light=True, camera=True)
    frozen = _camera_images(world, frames[:2], background, freeze=True)
    assert world._camera_freeze_key() is None
    traced = _camera_images(world, frames[:2], background, freeze=False)
    assert all(np.array_equal(a, b) for a, b in zip(frozen, traced, strict=True))
    assert not np.array_equal(traced[1], traced[2]), "the light must move"


def test_an_in_place_vertex_update_renders_as_a_scene_built_there():
    """Vertex updates are written into the mesh's own buffer (its address, which frozen launches read, stays):
    the renderer sees the move exactly as a scene built with the mesh there, and the mesh's box follows."""
    world, frames, background = _world(ball=False)
    key = "toy.vertex_positions"

    def address():
        return np.from_dlpack(world.mincam_scene.params[key]).__array_interface__["data"][0]

    before = address()
    placed = TOY.vertices + [0.03, -0.02, 0.0]
    world.update(vertex_update("toy", placed))
    assert address() == before
    assert np.allclose(world.world_value(key).reshape(-1, 3), placed, atol=1e-6)
    toy = next(s for s in world.scene.shapes() if s.id() == "toy")
    assert np.allclose(np.array(toy.bbox().min).ravel()[:2] + world.scene_origin_m[:2], placed.min(0)[:2], atol=1e-5)
    moved = estimates(world, 4096, seed=7)

    cam = world.mincam
    table = np.clip(0.4 + 0.1 * np.random.default_rng(0).standard_normal((32, 32)), 0, 1)
    built = ms.Simulation(cam, world={
        "table": sd.textured_plane(table, 1.0, 1.0, Pose((0, 0, 0), (0, 0, 1)).matrix()),
        "light": sd.area_light(0.4, 0.4, Pose((0, 0, 1.2), (0, 0, -1)).matrix(), 10.0),
        "toy": sd.mesh_object("toy", placed, TOY.faces, 0.9)})
    there = estimates(built, 4096, seed=7)
    assert np.allclose(moved, there, rtol=1e-6, atol=0), np.abs(moved / there - 1).max()


@pytest.mark.filterwarnings("ignore::mincam_sim.render.solvers.change.FallbackWarning")
@pytest.mark.parametrize("case", ["toy", "mirror", "far_movers", "glass"])
def test_paired_background_lanes_equal_a_full_background_pass(case):
    """The background pass traces again only the lanes whose frame paths crossed a moving shape's box (in
    either place); every other lane takes the frame's value. dP, P and their sigmas equal those of a full
    background pass bit for bit, also where paths reach the change through a mirror or movers lie far apart,
    with far fewer background rays."""
    if case == "toy":
        world, frames, background = _world(ball=True)
        spp = 2048
    else:
        from rare_paths import rare_scene

        world, frames, background = rare_scene(case)
        spp = 4096
    runs = {}
    for pair in (False, True):
        world.pair_lanes = pair
        runs[pair] = changes(world, frames, background, spp=spp, seed=5, solver=ms.StratifiedChange())
    for a, b in zip(runs[False], runs[True], strict=True):
        assert np.array_equal(a.irradiance_w_m2, b.irradiance_w_m2)
        assert np.array_equal(a.stderr_w_m2, b.stderr_w_m2)
    full, paired = runs[False][0].meta, runs[True][0].meta
    assert full["background_rays_share"] == 1.0 and paired["paired_lanes_reused"]
    assert paired["background_rays_share"] < 0.9, paired["background_rays_share"]
    assert paired["rays_per_mixel_per_frame"] < full["rays_per_mixel_per_frame"]


def _rotation_z(deg: float) -> np.ndarray:
    t = np.radians(deg)
    return np.array([[np.cos(t), -np.sin(t), 0.0], [np.sin(t), np.cos(t), 0.0], [0.0, 0.0, 1.0]])


@pytest.mark.filterwarnings("ignore::mincam_sim.render.solvers.change.HeavyTailWarning")
def test_a_turning_smooth_mesh_on_a_far_tilted_rig_gives_the_traced_numbers():
    """A car loaded by Mitsuba's own OBJ loader (vertex normals, recomputed by Mitsuba when it turns), turning
    under a mincam 1.2 km from the origin and tilted with its table and light: frozen launches with paired lanes
    give the numbers of traced, full-background runs bit for bit, and say how the launches ran."""
    from pathlib import Path

    mi = backend.mitsuba()
    tilt = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(0.6), -np.sin(0.6)], [0.0, np.sin(0.6), np.cos(0.6)]])
    far = np.array([1200.0, -350.0, 40.0])

    def place(m4: np.ndarray) -> np.ndarray:
        out = np.eye(4)
        out[:3, :3], out[:3, 3] = tilt @ m4[:3, :3], tilt @ m4[:3, 3] + far
        return out

    def at(points: np.ndarray) -> np.ndarray:
        return points @ tilt.T + far

    cam_pose = Pose(tuple(at(np.array([0.0, 0.0, 0.5]))), tuple(tilt @ [0.0, 0.0, -1.0]), tuple(tilt @ [0.0, 1.0, 0.0]))
    cam = cross_layout(center=cam_pose)
    obj = Path(__file__).resolve().parents[2] / "scenes" / "world" / "toy_car.obj"
    elements = {
        "table": sd.textured_plane(np.full((8, 8), 0.4), 1.0, 1.0, place(np.eye(4))),
        "light": sd.area_light(0.4, 0.4, place(Pose((0, 0, 1.2), (0, 0, -1)).matrix()), 10.0),
        "car": {"type": "obj", "filename": str(obj), "to_world": mi.ScalarTransform4f(place(np.eye(4)).tolist()),
                "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.8}}},
    }
    world = ms.Simulation(cam, world=elements)
    local = world.world_value("car.vertex_positions").reshape(-1, 3)
    local = (local - far) @ tilt  # the car in the table's frame
    frames = [vertex_update("car", at(local @ _rotation_z(a).T + [x, 0.01, 0.0]))
              for a, x in zip((0.0, 20.0, 45.0, 70.0), (-0.06, -0.02, 0.02, 0.06), strict=True)]
    background = vertex_update("car", at(local + [3.0, 3.0, 0.0]))
    runs = {}
    for fast in (False, True):
        world.freeze_launches = world.pair_lanes = fast
        runs[fast] = changes(world, frames, background, spp=2048, seed=2, solver=ms.StratifiedChange())
    for a, b in zip(runs[False], runs[True], strict=True):
        assert np.array_equal(a.irradiance_w_m2, b.irradiance_w_m2)
        assert np.array_equal(a.stderr_w_m2, b.stderr_w_m2)
    meta = runs[True][0].meta
    assert meta["launches"].startswith(("frozen", "traced from frame")), meta["launches"]
    assert meta["background_rays_share"] < 1.0
    assert np.all(np.abs(runs[False][0].irradiance_w_m2) > 3 * runs[False][0].stderr_w_m2), "changes must show"


def test_vertex_updates_never_write_into_the_callers_arrays():
    """Dr.Jit maps a float32 numpy array without copying, and vertex updates are written in place: the scene
    holds a private copy, so the arrays a caller built (the scene's and every frame's) stay as they were."""
    from mincam_sim.render.scene.mincam_scene import MincamScene

    placed = [np.asarray(TOY.vertices + [0.01 * k, 0.0, 0.0], dtype=np.float32) for k in range(4)]
    kept = [p.copy() for p in placed]
    built = np.asarray(TOY.vertices + [5.0, 5.0, 0.0], dtype=np.float32)
    scene = MincamScene.world(cross_layout(), {"toy": sd.mesh_object("toy", built, TOY.faces, 0.9)})
    built_kept = built.copy()
    for p in placed + placed[::-1]:
        scene.update({"toy.vertex_positions": p.ravel()})
    assert all(np.array_equal(p, k) for p, k in zip(placed, kept, strict=True))
    assert np.array_equal(built, built_kept)
    assert np.array_equal(np.asarray(scene.params["toy.vertex_positions"]), placed[0].ravel())


def test_frozen_paired_launches_of_several_sizes_equal_the_traced_ones(monkeypatch):
    """With a lane limit that splits a pass into launches of unequal sizes (the last one shorter), and a frame
    that moves nothing, frozen paired launches still give the traced, full numbers bit for bit."""
    from mincam_sim.render.kernels import tracing

    world, frames, background = _world(ball=False)
    frames = [*frames[:2], dict(background), frames[2]]  # the third frame is the background itself
    monkeypatch.setattr(tracing, "MAX_LANES", 7 * 72)  # 7 groups of 72 lanes per launch: 32 groups, 5 launches
    runs = {}
    for fast in (False, True, True):
        world.freeze_launches = world.pair_lanes = fast
        runs.setdefault(fast, []).append(changes(world, frames, background, spp=8 * 72, seed=4,
                                                               solver=ms.StratifiedChange()))
    (dp0, p0), = runs[False]
    for dp, p in runs[True]:
        assert np.array_equal(dp0.irradiance_w_m2, dp.irradiance_w_m2)
        assert np.array_equal(dp0.stderr_w_m2, dp.stderr_w_m2)
        assert np.array_equal(p0.irradiance_w_m2, p.irradiance_w_m2)
    assert np.all(dp0.irradiance_w_m2[2] == 0.0), "a frame equal to the background changes nothing"


def test_a_replay_after_another_solver_restored_a_texture_reads_the_texture_where_it_is_now():
    """A stratified run, then a plane replay (which whitens the plane's texture and puts a copy of it back, at a
    new address), then the same stratified run on the same simulation: the frozen launch must not replay the
    recording that read the texture at its old address (it gave dP ~ -5e29). The numbers equal the first run's
    bit for bit, and the traced run's."""
    cam = ms.single(ms.masks.constant(1.0), pose=Pose((0, 0, 0.5), (0, 0, -1), (0, 1, 0)))
    placed = Pose((0, 0, 0), (0, 0, 1)).matrix()

    def sim():
        return ms.Simulation(cam, world={"table": sd.textured_plane(np.full((4, 4), 0.5), 1.0, 1.0, placed),
                                         "sky": sd.sky(2.0)})

    far = placed @ np.diag([0.5, 0.5, 1.0, 1.0])
    far[0, 3] += 100.0
    frames = [{}, {"table.to_world": far}]
    budget = ms.Budget(spp=1 << 12, replicates=8, seed=3)
    shared = sim()
    first = shared.measure_changes(frames, None, ms.StratifiedChange(), budget)
    shared.measure([{}], ms.PlaneReplay("table"), ms.Budget(spp=1 << 12, replicates=8, seed=3))
    again = shared.measure_changes(frames, None, ms.StratifiedChange(), budget)
    np.testing.assert_array_equal(again.dp.irradiance_w_m2, first.dp.irradiance_w_m2)
    np.testing.assert_array_equal(again.dp.stderr_w_m2, first.dp.stderr_w_m2)
    traced = sim()
    traced.freeze_launches = False
    reference = traced.measure_changes(frames, None, ms.StratifiedChange(), budget)
    np.testing.assert_array_equal(again.dp.irradiance_w_m2, reference.dp.irradiance_w_m2)


def test_a_dropped_simulation_releases_its_frozen_launches_and_its_scenes():
    """The frozen functions are kept per scene; they (and the reference that keeps a scene alive) go with the
    simulation that owns the scene, its static split's scene included: a loop over simulations of a large
    table kept up to four dropped scenes alive before."""
    import gc

    world, frames, background = _world(ball=False, camera=True)
    world.split_static = True  # the static shapes in a scene of their own: that scene's launches are kept too
    changes(world, frames[:2], background, spp=1024, seed=3, solver=ms.StratifiedChange())
    world.camera_image(spp=4, seed=1)  # frozen (the default)
    split_scenes = [split.scene for split in world.static_splits.values()]
    assert split_scenes, "the test needs a split run"
    keys = {id(world.scene), *(id(s) for s in split_scenes)}
    assert keys <= set(frozen_functions._FROZEN), "the launches must have run frozen on both scenes"
    del world, split_scenes
    gc.collect()
    assert not keys & set(frozen_functions._FROZEN)


def test_the_mixel_sensor_keeps_its_configuration_out_of_the_frozen_launches_walk():
    """``dr.freeze`` walks every Dr.Jit value reachable from a launch's inputs on every call; the mixels' poses
    (``mi.Transform4f``) and sizes made that walk ~3x longer. They sit in a slotted holder it does not enter (the
    sensor's ``version`` keys the launches instead; the frozen passes above equal the traced ones)."""
    world, _, _ = _world(ball=False)
    sensor = world.sensor
    assert set(vars(sensor)) == {"_mixels", "version"}
    assert not hasattr(sensor._mixels, "__dict__") and len(sensor._mixels.matrices) == len(world.mincam)

