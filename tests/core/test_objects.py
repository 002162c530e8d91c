"""Tests for mincam_sim.scene.objects: toy meshes, procedural textures and trajectories (pure numpy/trimesh)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from mincam_sim.scene import objects as ob

# ------------------------------------------------------------------------------------------------ meshes


def _assert_on_ground_centred(mesh: trimesh.Trimesh) -> None:
    lo, hi = mesh.bounds
    assert abs(lo[2]) <= 1e-9, f"min z = {lo[2]}"
    np.testing.assert_allclose((lo[:2] + hi[:2]) / 2, 0.0, atol=1e-9)


def _assert_parts_closed(mesh: trimesh.Trimesh) -> None:
    parts = mesh.split(only_watertight=False)
    assert len(parts) == mesh.metadata["n_parts"]
    assert all(p.is_watertight for p in parts)
    assert all(p.volume > 0 for p in parts), "parts must have outward normals"


@pytest.mark.parametrize(
    "dims", [(0.08, 0.04, 0.035, 0.01), (0.12, 0.05, 0.04, 0.012), (0.05, 0.03, 0.03, 0.008)]
)
def test_toy_car_dims_closed_parts_on_ground(dims):
    L, W, H, r = dims
    car = ob.toy_car(L, W, H, r)
    assert len(car.faces) > 0 and len(car.vertices) > 0
    np.testing.assert_allclose(car.extents, (L, W, H), rtol=1e-6)
    _assert_on_ground_centred(car)
    _assert_parts_closed(car)
    assert car.metadata["n_parts"] == 6
    assert 0.0 <= car.metadata["albedo"] <= 1.0
    assert car.metadata["albedo"] == ob.DEFAULT_CAR_ALBEDO


def test_toy_car_rejects_bad_dims():
    with pytest.raises(ValueError, match="wheel"):
        ob.toy_car(height_m=0.015, wheel_radius_m=0.01)
    with pytest.raises(ValueError, match="positive"):
        ob.toy_car(length_m=-1.0)
    with pytest.raises(ValueError, match="albedo"):
        ob.toy_car(albedo=1.5)


@pytest.mark.parametrize("kind", ["robot", "chick", "frog"])
def test_windup_toys(kind):
    toy = ob.windup_toy(kind, size_m=0.05)
    assert len(toy.faces) > 0
    assert np.max(toy.extents) == pytest.approx(0.05, rel=1e-9)
    _assert_on_ground_centred(toy)
    _assert_parts_closed(toy)
    assert toy.metadata["albedo"] == ob.DEFAULT_TOY_ALBEDO[kind]


def test_windup_toys_differ_and_bad_kind():
    ext = {k: tuple(np.round(ob.windup_toy(k).extents, 6)) for k in ("robot", "chick", "frog")}
    assert len(set(ext.values())) == 3
    with pytest.raises(ValueError, match="unknown wind-up toy"):
        ob.windup_toy("dragon")  # type: ignore[arg-type]


@pytest.mark.parametrize("ext", ["obj", "ply", "stl", "glb"])
def test_load_mesh_roundtrip(tmp_path, ext):
    car = ob.toy_car()
    moved = car.copy()
    moved.apply_translation((0.3, -0.2, 0.1))
    path = tmp_path / f"car.{ext}"
    moved.export(path)
    loaded = ob.load_mesh(path, albedo=0.6)
    np.testing.assert_allclose(loaded.extents, car.extents, atol=1e-6)
    _assert_on_ground_centred(loaded)
    assert len(loaded.faces) == len(car.faces)
    assert loaded.metadata["albedo"] == 0.6
    scaled = ob.load_mesh(path, scale=2.0)
    np.testing.assert_allclose(scaled.extents, 2 * car.extents, atol=1e-6)


def test_load_mesh_scene_flattened_and_y_up(tmp_path):
    scene = trimesh.Scene()
    scene.add_geometry(trimesh.creation.box((1.0, 2.0, 3.0)))
    b2 = trimesh.creation.box((1.0, 1.0, 1.0))
    b2.apply_translation((5.0, 0.0, 0.0))
    scene.add_geometry(b2)
    path = tmp_path / "two.glb"
    scene.export(path)
    m = ob.load_mesh(path, up_axis="z")
    assert isinstance(m, trimesh.Trimesh) and len(m.faces) == 24
    _assert_on_ground_centred(m)
    my = ob.load_mesh(path, up_axis="y")  # +90 deg about x: (x, y, z) extents -> (x, z, y)
    np.testing.assert_allclose(my.extents, m.extents[[0, 2, 1]], atol=1e-9)
    _assert_on_ground_centred(my)


def test_load_mesh_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="not found"):
        ob.load_mesh(tmp_path / "nope.obj")
    with pytest.raises(FileNotFoundError, match="not a regular file"):
        ob.load_mesh(tmp_path)
    empty = tmp_path / "empty.obj"
    empty.write_bytes(b"")
    with pytest.raises(ValueError, match="empty"):
        ob.load_mesh(empty)
    junk = tmp_path / "junk.xyzformat"
    junk.write_text("hello")
    with pytest.raises(ValueError, match="could not read|no triangles"):
        ob.load_mesh(junk)
    points_only = tmp_path / "points.obj"
    points_only.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    with pytest.raises(ValueError, match="no triangles|no geometry|could not read"):
        ob.load_mesh(points_only)


def test_mesh_at_is_rigid():
    car = ob.toy_car()
    v0 = np.asarray(car.vertices)
    v1 = ob.mesh_at(car, (0.1, -0.05), 0.7)
    idx = np.random.default_rng(0).integers(0, len(v0), size=(200, 2))
    d0 = np.linalg.norm(v0[idx[:, 0]] - v0[idx[:, 1]], axis=1)
    d1 = np.linalg.norm(v1[idx[:, 0]] - v1[idx[:, 1]], axis=1)
    np.testing.assert_allclose(d1, d0, atol=1e-12)
    np.testing.assert_allclose(v1[:, 2], v0[:, 2], atol=1e-15)  # rotation about z only
    c, sn = np.cos(0.7), np.sin(0.7)
    np.testing.assert_allclose(v1[:, :2].mean(0), np.array([[c, -sn], [sn, c]]) @ v0[:, :2].mean(0) + [0.1, -0.05])
    # heading pi/2: the front (+x) faces +y
    front = ob.mesh_at(np.array([[1.0, 0.0, 0.0]]), (0.0, 0.0), np.pi / 2)
    np.testing.assert_allclose(front, [[0.0, 1.0, 0.0]], atol=1e-15)
    np.testing.assert_array_equal(car.vertices, v0)  # input untouched
    assert ob.mesh_at(car, (1.0, 2.0, 3.0), 0.0)[:, 2].min() == pytest.approx(3.0)


# ---------------------------------------------------------------------------------------------- textures


@pytest.mark.parametrize("kind", ["paper", "checker", "noise"])
def test_printed_background(kind):
    a = ob.printed_background((128, 160), np.random.default_rng(5), kind=kind)
    b = ob.printed_background((128, 160), np.random.default_rng(5), kind=kind)
    c = ob.printed_background((128, 160), np.random.default_rng(6), kind=kind)
    assert a.shape == (128, 160) and a.dtype == np.float64
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert a.min() >= 0.0 and a.max() <= 1.0
    assert a.mean() == pytest.approx(0.4, abs=0.02)
    assert 0.01 < a.std() < 0.2  # low contrast, but not flat


def test_printed_background_seed_int_and_errors():
    np.testing.assert_array_equal(ob.printed_background((32, 32), 3), ob.printed_background((32, 32), 3))
    with pytest.raises(ValueError, match="unknown background"):
        ob.printed_background((32, 32), 0, kind="wood")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="shape"):
        ob.printed_background((32,), 0)  # type: ignore[arg-type]


def test_road_texture_deterministic_and_broadband():
    a = ob.road_texture((128, 2048), rng=11)
    np.testing.assert_array_equal(a, ob.road_texture((128, 2048), rng=np.random.default_rng(11)))
    assert not np.array_equal(a, ob.road_texture((128, 2048), rng=12))
    assert a.min() >= 0.0 and a.max() <= 1.0
    # power spectrum along x (the direction of motion), averaged over rows
    rows = a - a.mean(axis=1, keepdims=True)
    power = (np.abs(np.fft.rfft(rows, axis=1)) ** 2).mean(axis=0)[1:]
    k_low = int(np.ceil(0.05 * power.size))
    frac_high = power[k_low:].sum() / power.sum()
    assert frac_high > 0.2, frac_high
    # energy at many frequencies: no handful of bins holds most of the power
    assert np.sort(power)[::-1][:20].sum() / power.sum() < 0.5
    # lane-marking dashes: bright paint along the centre rows, periodic along x
    centre = a[64]
    assert centre.max() > 0.8 and (centre > 0.7).mean() == pytest.approx(0.5, abs=0.1)


# ------------------------------------------------------------------------------------------ trajectories


def test_trajectory_validation_and_at():
    t = ob.Trajectory([0.0, 1.0, 2.0], [[0, 0], [1, 0], [1, 1]], [0.0, np.pi / 2, np.pi / 2])
    pos, h = t.at(0.5)
    np.testing.assert_allclose(pos, [0.5, 0.0])
    assert h == pytest.approx(np.pi / 4)
    pos, h = t.at(np.array([-1.0, 1.5, 9.0]))
    np.testing.assert_allclose(pos, [[0, 0], [1, 0.5], [1, 1]])
    np.testing.assert_allclose(t.speeds_m_s(), [1.0, 1.0, 1.0])
    # heading interpolation takes the short arc across +-pi
    w = ob.Trajectory([0.0, 1.0], [[0, 0], [0, 0]], [np.pi - 0.1, -np.pi + 0.1])
    assert abs(abs(w.at(0.5)[1]) - np.pi) < 1e-12
    with pytest.raises(ValueError, match="increasing"):
        ob.Trajectory([0.0, 0.0], [[0, 0], [1, 0]], [0, 0])
    with pytest.raises(ValueError, match="shape"):
        ob.Trajectory([0.0, 1.0], [[0, 0, 0], [1, 0, 0]], [0, 0])


def test_straight_race_scalar_and_vector():
    t = ob.straight_race(-0.2, 0.2, 2.0, 21, lateral_offset_m=0.05)
    np.testing.assert_allclose(t.positions_m[:, 1], 0.05)
    np.testing.assert_allclose(t.speeds_m_s(), 0.2)
    np.testing.assert_allclose(t.headings_rad, 0.0)
    back = ob.straight_race(0.2, -0.2, 2.0, 5)
    np.testing.assert_allclose(np.abs(back.headings_rad), np.pi)
    v = ob.straight_race((0.0, -0.1), (0.0, 0.1), 1.0, 3, lateral_offset_m=0.02)  # along +y, offset left = -x
    np.testing.assert_allclose(v.positions_m[:, 0], -0.02)
    np.testing.assert_allclose(v.headings_rad, np.pi / 2)
    with pytest.raises(ValueError, match="coincide"):
        ob.straight_race(0.1, 0.1, 1.0, 3)


def test_race_pair_crosses_once_each():
    x0 = -0.1378
    a, b = ob.race_pair(finish_line_x_m=x0, lanes_y_m=(-0.08, 0.08), speeds_m_s=(0.12, 0.09))
    np.testing.assert_array_equal(a.times_s, b.times_s)
    ca, cb = a.line_crossings(x0), b.line_crossings(x0)
    assert len(ca) == 1 and len(cb) == 1
    for traj in (a, b):
        d = traj.positions_m[:, 0] - x0
        assert np.sum((d[:-1] < 0) & (d[1:] >= 0)) == 1 and np.sum((d[:-1] >= 0) & (d[1:] < 0)) == 0
    (ta, ya), (tb, yb) = ca[0], cb[0]
    assert ta == pytest.approx(0.2 / 0.12) and tb == pytest.approx(0.2 / 0.09)
    assert ya == pytest.approx(-0.08) and yb == pytest.approx(0.08)
    assert ta != pytest.approx(tb)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_random_smooth_path(seed):
    bounds = ((-0.2, 0.2), (-0.15, 0.1))
    t = ob.random_smooth_path(np.random.default_rng(seed), 1500, 1 / 30, bounds_m=bounds, speed_m_s=0.05)
    assert len(t) == 1500
    np.testing.assert_allclose(t.times_s[1], 1 / 30)
    s = t.speeds_m_s()
    np.testing.assert_allclose(s, 0.05, rtol=0.05)
    p = t.positions_m
    assert np.all(p[:, 0] >= -0.2) and np.all(p[:, 0] <= 0.2)
    assert np.all(p[:, 1] >= -0.15) and np.all(p[:, 1] <= 0.1)
    v = t.velocities_m_s()
    moving = s > 1e-12
    ang = np.angle(np.exp(1j * (np.arctan2(v[:, 1], v[:, 0]) - t.headings_rad)))
    assert np.all(np.abs(ang[moving]) < 1e-6)
    # smooth: most per-frame heading changes are small (reflections are the exceptions)
    dh = np.abs(np.angle(np.exp(1j * np.diff(t.headings_rad))))
    assert np.median(dh) < 0.1
    # it actually explores the region
    assert np.ptp(p[:, 0]) > 0.1 and np.ptp(p[:, 1]) > 0.05
    # deterministic
    t2 = ob.random_smooth_path(seed, 1500, 1 / 30, bounds_m=bounds, speed_m_s=0.05)
    np.testing.assert_array_equal(t.positions_m, t2.positions_m)


def test_random_smooth_path_errors_and_still():
    with pytest.raises(ValueError, match="too large"):
        ob.random_smooth_path(0, 10, 1.0, speed_m_s=1.0)
    with pytest.raises(ValueError, match="n_frames"):
        ob.random_smooth_path(0, 1, 0.1)
    still = ob.random_smooth_path(0, 10, 0.1, speed_m_s=0.0)
    np.testing.assert_allclose(still.speeds_m_s(), 0.0)
