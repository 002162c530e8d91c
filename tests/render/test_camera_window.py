"""The ground-truth camera's change windows: where a frame can differ from its background, film coordinates of
scene points against closed forms, and the windowed change against whole-film renders of the same scene (a
tilted camera over a rig 40 m from the origin, a mover seen only in a mirror, a moving light, frozen == traced)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from rare_paths import _glass_mesh

import mincam_sim as ms
from mincam_sim import Pose, cross_layout
from mincam_sim.experiments.ground_truth import GroundTruthCamera
from mincam_sim.experiments.setup import Setup
from mincam_sim.model.geometry import look_at
from mincam_sim.render import backend
from mincam_sim.render.kernels.camera_window import WINDOW_STEP_PX, FilmProjection, change_windows
from mincam_sim.render.kernels.change_geometry import change_points_of
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.updates import vertex_update

pytestmark = pytest.mark.skipif(not backend.is_jit(), reason="needs a JIT variant (LLVM or CUDA)")

FAR = np.array([40.0, -25.0, 3.0])  # the rig, the table and the camera all sit this far from the origin [m]
BOX = trimesh.creation.box((0.06, 0.04, 0.05))
BOX.apply_translation((0, 0, 0.025))
PARKED = FAR + [20.0, 20.0, 0.0]
SMALL = BOX.copy()
SMALL.apply_scale(0.8)


def _world(mirror: bool = False, pixels: int = 64, spp: int = 8, other: bool = False, glass: bool = False):
    """A textured table under an area light 1.2 m up and a box moved by its vertices; a camera 0.8 m over the
    table, tilted 25 degrees and looking at its centre (``mirror``: a vertical mirror at x = +0.3 m, and the
    camera turned to see it; ``other``: a second, smaller box, parked 1 m beside the first; ``glass``: an 8 cm
    thick upright glass slab between the camera and the table's centre, out of the light's way, and paths of
    up to 6 segments, so that the camera sees the box through it)."""
    table = np.clip(0.45 + 0.1 * np.random.default_rng(0).standard_normal((32, 32)), 0, 1)
    elements = {
        "table": sd.textured_plane(table, 1.2, 1.2, Pose(tuple(FAR), (0, 0, 1)).matrix()),
        "light": sd.area_light(0.4, 0.4, Pose(tuple(FAR + [0, 0, 1.2]), (0, 0, -1)).matrix(), 10.0),
        "box": sd.mesh_object("box", BOX.vertices + PARKED, BOX.faces, 0.9),
    }
    if other:
        elements["other"] = sd.mesh_object("other", SMALL.vertices + PARKED + [1, 0, 0], SMALL.faces, 0.8)
    target = FAR + ([0.3, 0.0, 0.1] if mirror else [0.0, 0.0, 0.0])
    eye = FAR + ([-0.1, 0.05, 0.5] if mirror else [-0.37, 0.0, 0.8])
    if mirror:
        elements["mirror"] = {"type": "rectangle", "bsdf": {"type": "conductor"},
                              "to_world": backend.mitsuba().ScalarTransform4f(
                                  Pose(tuple(FAR + [0.3, 0.0, 0.15]), (-1, 0, 0), (0, 0, 1)).matrix()
                                  @ np.diag([0.15, 0.3, 1.0, 1.0]))}
    if glass:
        slab = trimesh.creation.box((0.08, 0.3, 0.3))
        slab.apply_translation(FAR + [-0.12, 0.0, 0.3])
        elements["slab"] = _glass_mesh("slab", slab.vertices, slab.faces)
    camera = sd.pinhole_camera(look_at(eye, target, (0.0, 0.0, 1.0)).matrix(), 50.0, pixels, pixels, spp=spp)
    rig = cross_layout(center=Pose(tuple(FAR + [0.0, 0.0, 0.5]), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)))
    world = ms.Simulation(rig, world=elements, camera=camera, max_depth=6 if glass else None)
    background = vertex_update("box", BOX.vertices + PARKED)
    if other:
        background.update(vertex_update("other", SMALL.vertices + PARKED + [1, 0, 0]))
    return world, background


def _box_at(x_m: float, y_m: float) -> dict:
    return vertex_update("box", BOX.vertices + FAR + [x_m, y_m, 0.0])


def _whole_change(world, frame: dict, background: dict, spp: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The background's whole film and the frame's whole-film change from it (the same seed: paired), the world
    left at the background."""
    world.update(background)
    bg = world.camera_image(spp=spp, seed=seed)
    world.update(frame)
    whole = world.camera_image(spp=spp, seed=seed) - bg
    world.update(background)
    return bg, whole


def test_film_coordinates_of_table_points_follow_the_ground_truth_cameras_closed_form():
    """The camera looking straight down from depth d: a table point (x, y, 0) lies at column x / pitch + W / 2
    and row H / 2 - y / pitch (film coordinates, pixel edges; the ground truth camera's own convention), a point
    at height z at d / (d - z) times that offset from the centre."""
    setup = Setup(quick=True)
    camera = GroundTruthCamera.for_setup(setup)
    world = ms.Simulation(cross_layout(center=setup.center), world={
        "table": sd.textured_plane(np.full((4, 4), 0.4), 1.2, 1.2, Pose((0, 0, 0), (0, 0, 1)).matrix()),
        "light": sd.area_light(0.6, 0.6, Pose((0, 0, 1.5), (0, 0, -1)).matrix(), 20.0)},
        camera=camera.scene_dict(setup))
    project = FilmProjection(world.camera)
    rng = np.random.default_rng(1)
    points = np.column_stack([rng.uniform(-0.25, 0.25, (50, 2)), rng.uniform(0.0, 0.2, 50)])
    pitch = 2 * camera.half_extent_m / camera.pixels
    scale = setup.depth_m / (setup.depth_m - points[:, 2])
    expected = np.column_stack([points[:, 0] * scale / pitch + camera.pixels / 2,
                                camera.pixels / 2 - points[:, 1] * scale / pitch])
    np.testing.assert_allclose(project(points - world.scene_origin_m), expected, atol=1e-3)
    assert project(np.array([[0.0, 0.0, 0.1]])) is None  # behind the camera (scene coordinates: the rig at 0)


def test_a_tilted_camera_far_from_the_origin_casts_its_ray_through_the_projected_point():
    """For points in front of a tilted camera 40 m from the origin, the ray the sensor casts through each
    projected film position passes through the point (to 1e-6 of its distance)."""
    world, _ = _world()
    project = FilmProjection(world.camera)
    rng = np.random.default_rng(2)
    points = FAR + np.column_stack([rng.uniform(-0.2, 0.2, (20, 2)), rng.uniform(0.0, 0.3, 20)])
    film = project(points - world.scene_origin_m)
    mi = backend.mitsuba()
    for point, (col, row) in zip(points - world.scene_origin_m, film, strict=True):
        ray, _ = world.camera.sample_ray(0.0, 0.5, mi.Point2f(float(col) / 64, float(row) / 64),
                                          mi.Point2f(0.5, 0.5))
        o, d = np.array(ray.o, dtype=float).ravel(), np.array(ray.d, dtype=float).ravel()
        rel = point - o
        assert np.linalg.norm(rel - (rel @ d) * d) < 1e-6 * np.linalg.norm(rel)


def test_windows_hold_the_projected_hulls_in_steps_and_inside_the_film():
    """A hull's window holds its projection grown by the margin, in sides of WINDOW_STEP_PX, inside the film;
    hulls apart keep windows of their own, overlapping ones share one; a hull out of view gives no window
    (nothing can change), one behind the camera or unbounded the whole film."""
    world, _ = _world(pixels=100)
    project = FilmProjection(world.camera)
    origin = world.scene_origin_m

    def hull(x, y):
        return FAR - origin + np.array([[x + dx, y + dy, z] for dx in (-0.05, 0.05) for dy in (-0.03, 0.04)
                                        for z in (0.0, 0.05)])

    (row, col, rows, cols), = change_windows(project, [hull(0.0, 0.0)])
    film = project(hull(0.0, 0.0))
    assert rows % WINDOW_STEP_PX == 0 and cols % WINDOW_STEP_PX == 0
    assert col <= film[:, 0].min() - 1 and film[:, 0].max() + 1 <= col + cols
    assert row <= film[:, 1].min() - 1 and film[:, 1].max() + 1 <= row + rows
    apart = change_windows(project, [hull(-0.25, -0.2), hull(0.25, 0.2)])
    assert len(apart) == 2 and sum(r * c for *_, r, c in apart) < 0.5 * 100 * 100
    (r0, c0, h0, w0), (r1, c1, h1, w1) = apart
    assert r0 + h0 <= r1 or r1 + h1 <= r0 or c0 + w0 <= c1 or c1 + w1 <= c0  # no pixel in both
    assert len(change_windows(project, [hull(0.0, 0.0), hull(0.02, 0.01)])) == 1
    corner = FAR - origin + np.array([[0.0, 0.0, 0.0], [0.0, 3.0, 0.01]])  # out of the film on one side: cut
    (row, col, rows, cols), = change_windows(project, [corner])
    assert 0 <= row and row + rows <= 100 and 0 <= col and col + cols <= 100 and rows * cols < 100 * 100
    assert change_windows(project, [PARKED - origin + np.zeros((2, 3))]) == ()
    assert change_windows(project, [hull(0.0, 0.0), None]) == ((0, 0, 100, 100),)
    behind = FAR - origin + np.array([[-0.37, 0.0, 0.9], [-0.5, 0.0, 1.2]])
    assert change_windows(project, [hull(0.0, 0.0), behind]) == ((0, 0, 100, 100),)


def test_the_windowed_change_agrees_with_whole_film_renders():
    """A box moved onto the table of a tilted camera 40 m from the origin: every pixel whose whole-film change
    (1,024 samples a pixel) passes 2 % of the brightest background pixel lies in the window; in the window the
    change equals the whole-film one within the two renders' noise (the mean difference within 4.5 standard
    errors, the centroids of |change| within 0.1 px); pixels none of whose paths meet the box are equal bit for
    bit (same seed lane by lane); the world is left at the background."""
    world, background = _world()
    frame = _box_at(0.05, -0.02)
    bg, whole = _whole_change(world, frame, background, 1024, 5)  # paired: 0 where no path meets the box
    change = world.camera_changes([frame], background, spp=1024, seed=7)[0]
    assert world.world_value("box.vertex_positions")[0] == pytest.approx(BOX.vertices[0, 0] + PARKED[0])
    inside = change.inside(bg.shape)
    seen = np.abs(whole) > 0.02 * bg.max()
    assert seen.sum() > 20 and not (seen & ~inside).any()
    windowed = change.change_image(bg.shape)
    difference = (windowed - whole)[inside]
    assert abs(difference.mean()) < 4.5 * difference.std() / np.sqrt(difference.size)

    def centroid(image):
        rows_, cols_ = np.nonzero(inside)
        weights = np.abs(image[inside])
        return np.array([rows_ @ weights, cols_ @ weights]) / weights.sum()

    np.testing.assert_allclose(centroid(windowed), centroid(whole), atol=0.1)
    few = world.camera_changes([frame], background, spp=2, seed=7)[0]  # few paths: many meet no box
    assert few.windows == change.windows
    assert np.mean(np.concatenate([(f == b).ravel() for f, b in zip(few.frame, few.background, strict=True)])) > 0.2


def test_a_mover_seen_only_in_a_mirror_is_in_the_window():
    """The box behind the camera's view, seen only in a vertical mirror: its mirror image's window holds every
    pixel its change reaches (256 samples a pixel, whole film), and that change is there."""
    world, background = _world(mirror=True, pixels=48)
    frame = _box_at(0.1, 0.0)
    bg, whole = _whole_change(world, frame, background, 256, 1)
    change = world.camera_changes([frame], background, spp=256, seed=1)[0]
    assert change.windows
    inside = change.inside(bg.shape)
    seen = np.abs(whole) > 0.02 * bg.max()
    assert seen.sum() > 10 and not (seen & ~inside).any()
    assert (np.abs(change.change_image(bg.shape)) > 0.02 * bg.max()).sum() > 10


def test_a_mover_seen_through_a_glass_slab_is_in_the_window():
    """The box seen through a thick glass slab (two refractions shift it sideways): the windows hold the slab's
    image, and with it every pixel whose whole-film change (512 samples, paired) passes 2 % of the brightest
    background pixel, some of which lie outside the window of the box's own hull (so the slab is what holds them).
    A frame's hulls are the mover's and each of its images apart (a glass box beside a mover's hull once broke
    the window's projection)."""
    world, background = _world(pixels=48, glass=True)
    frame = _box_at(0.05, -0.02)
    bg, whole = _whole_change(world, frame, background, 512, 4)
    change = world.camera_changes([frame], background, spp=64, seed=4)[0]
    seen = np.abs(whole) > 0.02 * bg.max()
    assert seen.sum() > 10 and not (seen & ~change.inside(bg.shape)).any()
    world.update(frame)
    own_hull = world._change_hulls(["box"])[0][0]
    world.update(background)
    own = np.zeros(bg.shape, dtype=bool)
    for row, col, rows, cols in change_windows(world._film_projection, [own_hull]):
        own[row:row + rows, col:col + cols] = True
    assert (seen & ~own).sum() >= 3
    assert (np.abs(change.change_image(bg.shape)) > 0.02 * bg.max()).sum() > 0.8 * seen.sum()


def test_a_moving_glass_block_changes_the_whole_film():
    """A glass block moved onto the table throws light beside its shadow (refracted and reflected lamp light):
    the paired whole-film change (512 samples) outside the window of its box and shadow volumes adds up to more than
    half the brightest background pixel, all of it brighter (light, not noise), at each of two seeds; so a moving
    mirror or glass shape gets the whole film."""
    table = np.clip(0.45 + 0.1 * np.random.default_rng(0).standard_normal((32, 32)), 0, 1)
    block = trimesh.creation.box((0.08, 0.06, 0.06))
    block.apply_translation((0.0, 0.0, 0.03))
    elements = {
        "table": sd.textured_plane(table, 1.2, 1.2, Pose(tuple(FAR), (0, 0, 1)).matrix()),
        "light": sd.area_light(0.2, 0.2, Pose(tuple(FAR + [0.15, 0, 1.2]), (0, 0, -1)).matrix(), 40.0),
        "glass": _glass_mesh("glass", block.vertices + PARKED, block.faces),
    }
    camera = sd.pinhole_camera(look_at(FAR + [-0.37, 0.0, 0.8], FAR, (0.0, 0.0, 1.0)).matrix(), 50.0, 64, 64, spp=8)
    rig = cross_layout(center=Pose(tuple(FAR + [0.0, 0.0, 0.5]), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)))
    world = ms.Simulation(rig, world=elements, camera=camera, max_depth=6)
    background = vertex_update("glass", block.vertices + PARKED)
    frame = vertex_update("glass", block.vertices + FAR + [0.02, 0.01, 0.0])
    assert world.camera_changes([frame], background, spp=4)[0].windows == ((0, 0, 64, 64),)
    world.update(frame)
    hull = change_points_of(world.scene, ["glass"])[0]
    world.update(background)
    near = np.zeros((64, 64), dtype=bool)
    for row, col, rows, cols in change_windows(FilmProjection(world.camera), [hull]):
        near[row:row + rows, col:col + cols] = True
    for seed in (1, 2):
        bg, whole = _whole_change(world, frame, background, 512, seed)
        beyond = whole[~near]
        assert beyond.sum() > 0.5 * bg.max() and beyond.sum() >= 0.99 * np.abs(beyond).sum()


@pytest.mark.parametrize("glass", [True, False])
def test_a_moving_instance_of_glass_changes_the_whole_film_and_one_of_a_diffuse_group_its_window(glass):
    """An ``instance`` has no BSDF of its own (Mitsuba gives it a diffuse one): moved, an instance of a glass block
    gets the whole film as the block itself would, an instance of a diffuse block the window of its box."""
    def block(kind):
        return {"type": "cube", "to_world": sd._transform(np.diag([0.04, 0.03, 0.03, 1.0])),
                "bsdf": {"type": kind} if kind == "dielectric" else {"type": "diffuse"}}

    group = {"type": "shapegroup", "part": block("dielectric" if glass else "diffuse")}
    placed = np.eye(4)
    placed[:3, 3] = PARKED + [0.0, 0.0, 0.03]
    moved = np.eye(4)
    moved[:3, 3] = FAR + [0.02, 0.01, 0.03]
    table = np.full((8, 8), 0.5)
    elements = {
        "table": sd.textured_plane(table, 1.2, 1.2, Pose(tuple(FAR), (0, 0, 1)).matrix()),
        "light": sd.area_light(0.2, 0.2, Pose(tuple(FAR + [0.15, 0, 1.2]), (0, 0, -1)).matrix(), 40.0),
        "group": group,
        "block": {"type": "instance", "group": {"type": "ref", "id": "group"}, "to_world": sd._transform(placed)},
    }
    camera = sd.pinhole_camera(look_at(FAR + [-0.37, 0.0, 0.8], FAR, (0.0, 0.0, 1.0)).matrix(), 50.0, 64, 64, spp=8)
    rig = cross_layout(center=Pose(tuple(FAR + [0.0, 0.0, 0.5]), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)))
    world = ms.Simulation(rig, world=elements, camera=camera, max_depth=6)
    frame = {"block.to_world": moved}
    change = world.camera_changes([frame], {"block.to_world": placed}, spp=4)[0]
    assert (change.windows == ((0, 0, 64, 64),)) == glass
    assert change.windows and change.inside((64, 64)).mean() > (0.99 if glass else 0.0)


def test_a_moving_light_changes_the_whole_film_and_nothing_changes_nothing():
    """A light moved by a frame can change any pixel: the window is the whole film. A frame that leaves the
    box parked changes nothing: no window, a change of 0."""
    world, background = _world(pixels=32)
    moved = {"light.to_world": Pose(tuple(FAR + [0.1, 0, 1.2]), (0, 0, -1)).matrix()}
    lit = world.camera_changes([moved], {"light.to_world": world.world_value("light.to_world")}, spp=4)[0]
    assert lit.windows == ((0, 0, 32, 32),)
    same = world.camera_changes([background], background, spp=4)[0]
    assert same.windows == () and not same.change_image((32, 32)).any()


def test_frozen_windows_equal_traced_ones_bit_for_bit():
    """Windows of several sizes, replayed from recordings, equal the traced ones bit for bit (a recording is
    keyed on the window's shape: Dr.Jit 1.5 replayed a 32 x 48 recording for a 48 x 48 window keyed on the
    integers alone), and so do the whole-film differences beside them."""
    frames = [_box_at(x, 0.3 * x) for x in (-0.3, -0.05, 0.0, 0.12, 0.35)]
    out = {}
    for freeze in (False, True):
        world, background = _world(pixels=160)
        world.freeze_launches = freeze
        out[freeze] = world.camera_changes(frames, background, spp=8, seed=2, elsewhere_spp=2)
    shapes = {f.shape for c in out[True] for f in c.frame}
    assert len(shapes) >= 2, shapes
    for a, b in zip(out[False], out[True], strict=True):
        assert a.windows == b.windows
        for name in ("frame", "background"):
            assert all(np.array_equal(x, y) for x, y in zip(getattr(a, name), getattr(b, name), strict=True))
        assert np.array_equal(a.elsewhere, b.elsewhere)


def test_a_frozen_window_of_a_new_shape_records_afresh():
    """Windows of 32 x 32, 32 x 48, 48 x 32 and then 48 x 48 pixels at 32 samples: each frozen render has its own
    window's shape and equals the traced one bit for bit (Dr.Jit 1.5 replayed the 32 x 48 recording for the
    48 x 48 window while the recordings were keyed on the integers alone)."""
    world, background = _world(pixels=96)
    world.update(_box_at(0.0, 0.0))
    scene = world.mincam_scene
    for window in [(10, 12, 32, 32), (10, 12, 32, 48), (10, 12, 48, 32), (10, 12, 48, 48), (20, 30, 32, 48)]:
        frozen = scene.camera_window(window, 32, 3, freeze=world._camera_freeze_key())
        assert frozen.shape == window[2:]
        assert np.array_equal(frozen, scene.camera_window(window, 32, 3))


@pytest.mark.parametrize(("field", "value"), [("spp", 0), ("spp", 2.5), ("spp", True), ("elsewhere_spp", -1)])
def test_bad_sample_counts_are_refused_by_name(field, value):
    """A sample count that is no integer, or below 1 (``spp``) or 0 (``elsewhere_spp``), is one InputError naming
    it, before anything is rendered."""
    world, background = _world(pixels=16)
    with pytest.raises(ms.InputError, match=field):
        world.camera_changes([_box_at(0.0, 0.0)], background, **{field: value})


def test_two_movers_apart_are_both_in_the_window():
    """Two boxes moved at once to opposite sides of the view: each keeps a window of its own (the pixels between
    them are not rendered), every pixel whose whole-film change (512 samples, paired) passes 2 % of the brightest
    background pixel lies in one of them, and both boxes' changes are there."""
    world2, background = _world(pixels=48, other=True)
    frame = {**_box_at(-0.15, 0.12), **vertex_update("other", SMALL.vertices + FAR + [0.2, -0.15, 0.0])}
    bg, whole = _whole_change(world2, frame, background, 512, 4)
    change = world2.camera_changes([frame], background, spp=64, seed=4)[0]
    inside = change.inside(bg.shape)
    seen = np.abs(whole) > 0.02 * bg.max()
    assert not (seen & ~inside).any()
    rows_seen, cols_seen = np.nonzero(seen)
    assert np.ptp(cols_seen) > 10 or np.ptp(rows_seen) > 10, "the two changes must lie apart"
    assert (np.abs(change.change_image(bg.shape)) > 0.02 * bg.max()).sum() > 0.8 * seen.sum()
    assert len(change.windows) == 2 and inside.mean() < 0.5


def test_the_background_of_a_window_is_rendered_once_and_equals_its_own_render():
    """Frames whose box stays within one window share its background: rendered once (the background is one
    scene state, one seed, random numbers by the window's shape), and equal bit for bit to the background
    rendered over that window on its own."""
    world, background = _world(pixels=64)
    frames = [_box_at(x, 0.0) for x in (0.0, 0.0005, 0.001, 0.03)]
    rendered = []
    own = world._camera_windows

    def counted(windows, spp, seed):
        rendered.append(windows)
        return own(windows, spp, seed)

    world._camera_windows = counted
    changes = world.camera_changes(frames, background, spp=8, seed=3)
    distinct = {c.windows for c in changes}
    assert 1 < len(distinct) < len(frames), [c.windows for c in changes]
    assert len(rendered) == len(frames) + len(distinct)  # a window per frame, one per distinct background
    world._camera_windows = own
    world.update(background)
    for change in changes:
        alone = world._camera_windows(change.windows, 8, 3)
        assert all(np.array_equal(a, b) for a, b in zip(change.background, alone, strict=True))
