"""Instances (``shapegroup`` + ``instance``) in a world: they load from a file and from dicts, and an instance
moves by its ``to_world`` as the same shapes given one by one move."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_close_mc

import mincam_sim as ms
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.scene_files import SceneFile

CAM = ms.pair_layout(center=ms.Pose((0.0, 0.0, 0.4), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)))
SOLVER = ms.StratifiedChange
BUDGET = ms.Budget(spp=1 << 16, seed=5, replicates=16)
# the group's two cards (local frame [m]): a 10 x 5 cm lid 6 cm up and a 10 x 6 cm side standing at its edge
LID = np.array([[0.05, 0, 0, 0], [0, 0.025, 0, 0], [0, 0, 1, 0.06], [0, 0, 0, 1.0]])
SIDE = np.array([[0.05, 0, 0, 0], [0, 0, -1, 0.025], [0, 0.03, 0, 0.03], [0, 0, 0, 1.0]])
PLACED = np.array([[1, 0, 0, -0.06], [0, 1, 0, 0.03], [0, 0, 1, 0], [0, 0, 0, 1.0]])  # the instance's to_world
MOVED = PLACED + np.array([[0, 0, 0, 0.09], [0, 0, 0, -0.02], [0, 0, 0, 0], [0, 0, 0, 0]])


def _grey(value: float) -> dict:
    return {"type": "diffuse", "reflectance": {"type": "spectrum", "value": value}}


def _room() -> dict:
    return {"floor": {"type": "rectangle", "to_world": sd._transform(np.diag([0.6, 0.6, 1.0, 1.0])),
                      "bsdf": _grey(0.3)},
            "lamp": sd.area_light(0.24, 0.24, ms.Pose((0.05, 0.0, 1.0), (0.0, 0.0, -1.0)).matrix(), 40.0)}


def _separate(placed: np.ndarray) -> dict:
    return {"lid": {"type": "rectangle", "to_world": sd._transform(placed @ LID), "bsdf": _grey(0.8)},
            "side": {"type": "rectangle", "to_world": sd._transform(placed @ SIDE), "bsdf": _grey(0.8)}}


def _dP(sim: ms.Simulation, frame: dict, seed: int) -> tuple[np.ndarray, np.ndarray]:
    ch = sim.measure_changes([frame], background={}, solver=SOLVER(),
                             budget=ms.Budget(spp=BUDGET.spp, seed=seed, replicates=BUDGET.replicates))
    return ch.dp.irradiance_w_m2[0], ch.dp.stderr_w_m2[0]


def _matrix_xml(matrix: np.ndarray) -> str:
    return " ".join(f"{v:.9g}" for v in np.asarray(matrix).ravel())


def _instance_xml(unit: float) -> str:
    """The room, the group and two instances of it (one far off to the side), in units of ``unit`` [m]."""
    to_unit = np.diag([1 / unit, 1 / unit, 1 / unit, 1.0])
    far = PLACED + np.array([[0, 0, 0, 0.0], [0, 0, 0, -0.45], [0, 0, 0, 0], [0, 0, 0, 0]])
    lamp = ms.Pose((0.05, 0.0, 1.0), (0.0, 0.0, -1.0)).matrix() @ np.diag([0.12, 0.12, 1.0, 1.0])
    return f"""<scene version="3.0.0">
    <shape type="rectangle" id="floor"><transform name="to_world"><matrix value="{_matrix_xml(
        to_unit @ np.diag([0.6, 0.6, 1.0, 1.0]))}"/></transform>
        <bsdf type="diffuse"><float name="reflectance" value="0.3"/></bsdf></shape>
    <shape type="rectangle" id="lamp"><transform name="to_world"><matrix value="{_matrix_xml(to_unit @ lamp)}"/>
        </transform><bsdf type="diffuse"><float name="reflectance" value="0"/></bsdf>
        <emitter type="area"><float name="radiance" value="40"/></emitter></shape>
    <shape type="shapegroup" id="box">
        <shape type="rectangle"><transform name="to_world"><matrix value="{_matrix_xml(to_unit @ LID)}"/>
            </transform><bsdf type="diffuse"><float name="reflectance" value="0.8"/></bsdf></shape>
        <shape type="rectangle"><transform name="to_world"><matrix value="{_matrix_xml(to_unit @ SIDE)}"/>
            </transform><bsdf type="diffuse"><float name="reflectance" value="0.8"/></bsdf></shape>
    </shape>
    <shape type="instance" id="box_a"><ref id="box"/>
        <transform name="to_world"><matrix value="{_matrix_xml(to_unit @ PLACED @ np.linalg.inv(to_unit))}"/>
        </transform></shape>
    <shape type="instance" id="box_b"><ref id="box"/>
        <transform name="to_world"><matrix value="{_matrix_xml(to_unit @ far @ np.linalg.inv(to_unit))}"/>
        </transform></shape>
</scene>
"""


def _separate_with_far_twin() -> dict:
    far = PLACED + np.array([[0, 0, 0, 0.0], [0, 0, 0, -0.45], [0, 0, 0, 0], [0, 0, 0, 0]])
    twin = {f"{k}_b": v for k, v in _separate(far).items()}
    return {**_room(), **_separate(PLACED), **twin}


@pytest.mark.parametrize("unit_m", [pytest.param(1.0, marks=pytest.mark.slow), 0.01])  # cm holds the harder case
def test_an_instance_in_a_file_moves_as_the_same_shapes_given_one_by_one(tmp_path, unit_m):
    """A file with a shape group drawn by two instances (in metres, and in cm with ``unit_m``: the group's own
    shapes are never scaled or shifted a second time): moving one instance by its ``to_world`` changes P as
    moving the two cards of the same scene built from separate shapes. In cm the instance's ``to_world`` in
    metres carries the file's scale (its group's shapes stay in the file's units)."""
    path = tmp_path / "boxes.xml"
    path.write_text(_instance_xml(unit_m))
    from_file = ms.Simulation(CAM, world={"scene": SceneFile(path, unit_m=unit_m)})
    separate = ms.Simulation(CAM, world=_separate_with_far_twin())
    assert "box_a" in from_file.movable() and "box" not in from_file.movable()
    unit = np.diag([unit_m, unit_m, unit_m, 1.0])
    np.testing.assert_allclose(from_file.params["box_a.to_world"], PLACED @ unit, atol=1e-6)
    a, sa = _dP(from_file, {"box_a.to_world": MOVED @ unit}, seed=1)
    b, sb = _dP(separate, {"lid.to_world": MOVED @ LID, "side.to_world": MOVED @ SIDE}, seed=2)
    assert np.all(np.abs(b) > 10 * sb), "the move is resolved"
    assert_close_mc(a, b, np.hypot(sa, sb), z=4.5, what=f"instance mover vs separate shapes (unit_m={unit_m})")


def test_an_instance_given_as_dicts_moves_and_its_background_takes_it_out():
    """A shape group and an instance given as Python dicts (a ``ref`` to the group): the instance is a mover,
    the group is not, and ``without`` takes the instance out (the background of a change) as it takes out the
    separate shapes."""
    group = {"type": "shapegroup", "lid": {"type": "rectangle", "to_world": sd._transform(LID), "bsdf": _grey(0.8)},
             "side": {"type": "rectangle", "to_world": sd._transform(SIDE), "bsdf": _grey(0.8)}}
    inst = {"type": "instance", "group": {"type": "ref", "id": "box"}, "to_world": sd._transform(PLACED)}
    sim = ms.Simulation(CAM, world={**_room(), "box": group, "box_a": inst})
    separate = ms.Simulation(CAM, world={**_room(), **_separate(PLACED)})
    assert sim.movable() == ["box_a", "floor", "lamp"]
    a, sa = _dP(sim, sim.without("box_a"), seed=3)
    b, sb = _dP(separate, separate.without("lid", "side"), seed=4)
    assert np.all(np.abs(b) > 10 * sb), "taking the box out is resolved"
    assert_close_mc(a, b, np.hypot(sa, sb), z=4.5, what="instance taken out vs separate shapes taken out")


def test_a_mirror_drawn_by_an_instance_is_a_mirror_of_the_change_solver():
    """An instance has a diffuse BSDF of its own: the mirrors and glass of the group it draws are found through it
    (rays cast at its box) and placed by its ``to_world``. The rare-path mirror drawn by an instance then gives
    the mirror plane the mirror itself gives and measures what it measures, to float32 rounding (unregistered, the
    sigma of dP was 12x larger at equal rays and 48 seeds showed a value at 5.3 sigma); an instance of a group of
    two mirrors, turned, has both planes, keyed by its name and the part, each turned with it."""
    from rare_paths import rare_scene

    out = {}
    for case in ("mirror", "mirror_instance"):
        world, frames, background = rare_scene(case)
        out[case] = (world._mirrors, world.measure_changes(frames, background, ms.StratifiedChange(),
                                                           ms.Budget(spp=1 << 12, seed=2, replicates=8)).dp)
    (mesh, dp_mesh), (inst, dp_inst) = out["mirror"], out["mirror_instance"]
    assert list(inst.planes) == ["mirror"] and not inst.boxes and "mirror" in inst
    np.testing.assert_allclose(inst.planes["mirror"][0], mesh.planes["mirror"][0], atol=1e-6)
    assert inst.planes["mirror"][1] == pytest.approx(mesh.planes["mirror"][1], abs=1e-6)
    np.testing.assert_allclose(dp_inst.irradiance_w_m2, dp_mesh.irradiance_w_m2, rtol=1e-5, atol=0)
    np.testing.assert_allclose(dp_inst.stderr_w_m2, dp_mesh.stderr_w_m2, rtol=1e-4, atol=0)

    mirror = {"type": "conductor", "material": "none"}
    group = {"type": "shapegroup",
             "a": {"type": "rectangle", "to_world": sd._transform(LID), "bsdf": mirror},  # normal +z, 6 cm up
             "b": {"type": "rectangle", "to_world": sd._transform(SIDE), "bsdf": mirror}}  # normal -y, y = 2.5 cm
    turn = np.array([[0.0, -1.0, 0.0, 0.1], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    sim = ms.Simulation(CAM, world={**_room(), "box": group, "box_a": {"type": "instance", "group": {
        "type": "ref", "id": "box"}, "to_world": sd._transform(turn)}})
    planes, origin = sim._mirrors.planes, sim.scene_origin_m  # planes in scene coordinates: world - origin
    assert set(planes) == {("box_a", 0), ("box_a", 1)} and "box_a" in sim._mirrors
    by_normal = {tuple(np.round(np.abs(n), 6)): (n, c) for n, c in planes.values()}
    n_lid, c_lid = by_normal[(0.0, 0.0, 1.0)]
    assert c_lid * n_lid[2] == pytest.approx(0.06 - origin[2], abs=1e-6)
    n_side, c_side = by_normal[(1.0, 0.0, 0.0)]  # -y turned a quarter about z: +x; y = 2.5 cm -> x = 0.1 - 0.025
    assert c_side * n_side[0] == pytest.approx(0.075 - origin[0], abs=1e-6)
    assert sim._mirrors.reflect(np.zeros((1, 3)), exclude="box_a") == []
