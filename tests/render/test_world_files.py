"""Your own scene from a file: Mitsuba XML scenes and meshes, movers on trajectories, from the CLI and Python."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
from conftest import assert_close_mc

import mincam_sim as ms
from mincam_sim.configuration.world_config import load_world_config, world_example_toml
from mincam_sim.errors import ConfigError, InputError, StaleResultError
from mincam_sim.estimation.estimators import intrusion_position
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.updates import vertex_update
from mincam_sim.runs.jobs import run_world_config

ROOM = Path(__file__).resolve().parents[2] / "scenes" / "world"
CAM = ms.pair_layout(center=ms.Pose((0.0, 0.0, 0.4), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)))


def _room_copy(tmp_path: Path, xml_edit=None) -> Path:
    for name in ("room.xml", "room.toml", "toy_car.obj"):
        shutil.copy(ROOM / name, tmp_path / name)
    text = (tmp_path / "room.toml").read_text().replace('out_dir = "../../out/world_room"', 'out_dir = "out"')
    (tmp_path / "room.toml").write_text(text)
    if xml_edit is not None:
        (tmp_path / "room.xml").write_text(xml_edit((tmp_path / "room.xml").read_text()))
    return tmp_path / "room.toml"


def _estimates(sim: ms.Simulation, seed: int, spp: int = 1 << 18):
    m = sim.measure([{}], budget=ms.Budget(spp=spp, seed=seed, replicates=16))
    return m.irradiance_w_m2[0], m.stderr_w_m2[0]


def _room_dicts(toy: dict) -> dict:
    grey = lambda v: {"type": "diffuse", "reflectance": {"type": "spectrum", "value": v}}  # noqa: E731
    wall = ms.Pose((0.0, 0.6, 0.3), (0.0, -1.0, 0.0), (0.0, 0.0, 1.0)).matrix()
    return {
        "floor": {"type": "rectangle", "to_world": sd._transform(np.diag([0.6, 0.6, 1.0, 1.0])), "bsdf": grey(0.15)},
        "wall": {"type": "rectangle", "to_world": sd._transform(wall @ np.diag([0.6, 0.3, 1.0, 1.0])),
                 "bsdf": grey(0.5)},
        "lamp": sd.area_light(0.24, 0.24, ms.Pose((0.0, 0.0, 1.0), (0.0, 0.0, -1.0)).matrix(), 40.0),
        "toy_car": toy,
    }


def test_an_xml_scene_measures_as_the_same_scene_built_from_dicts():
    xml = ms.Simulation(CAM, world=ROOM / "room.xml")
    toy = {"type": "obj", "filename": str(ROOM / "toy_car.obj"), "face_normals": True,
           "to_world": sd._transform(np.array([[1, 0, 0, -0.12], [0, 1, 0, 0.02], [0, 0, 1, 0], [0, 0, 0, 1.0]])),
           "bsdf": {"type": "diffuse", "reflectance": {"type": "spectrum", "value": 0.85}}}
    built = ms.Simulation(CAM, world=_room_dicts(toy))
    (a, sa), (b, sb) = _estimates(xml, 1), _estimates(built, 2)
    assert np.all(sa / a < 3e-3)
    assert_close_mc(a, b, np.hypot(sa, sb), what="XML room vs the same room from dicts")
    assert {"floor.to_world", "wall.to_world", "toy_car.vertex_positions", "lamp.emitter.radiance.value"} <= set(
        xml.params)


@pytest.mark.parametrize("fmt", ["obj", "ply"])
def test_a_mesh_read_by_trimesh_measures_as_mitsubas_own_loader(tmp_path, fmt):
    """The toy car read with trimesh (as [[world.object]] meshes are) and handed over in memory, against the
    same file through Mitsuba's obj / ply plugin with face normals. (Mitsuba's loaders smooth the normals across
    vertices that faces share by default: on this box-shaped car that read 1.1-2.3 % brighter, 7-11 sigma;
    a trimesh mesh is shaded flat, as its geometry is: mitsuba3 #1787.)"""
    from mincam_sim.render.scene.scene_files import read_mesh

    path = tmp_path / f"toy.{fmt}"
    car = trimesh.load(ROOM / "toy_car.obj", force="mesh", process=False)
    car.apply_translation((0.02, -0.01, 0.0))
    car.export(path)
    vertices, faces = read_mesh(path)
    by_trimesh = ms.Simulation(CAM, world=_room_dicts(sd.mesh_object("toy_car", vertices, faces, 0.85)))
    by_mitsuba = ms.Simulation(CAM, world=_room_dicts(
        {"type": fmt, "filename": str(path), "face_normals": True,
         "bsdf": {"type": "diffuse", "reflectance": {"type": "spectrum", "value": 0.85}}}))
    (a, sa), (b, sb) = _estimates(by_trimesh, 3), _estimates(by_mitsuba, 4)
    assert_close_mc(a, b, np.hypot(sa, sb), what=f"trimesh vs Mitsuba's {fmt} loader")


def test_the_shipped_room_renders_and_the_eq4_ratio_rises_as_the_car_crosses(tmp_path):
    cfg = load_world_config(_room_copy(tmp_path))
    ch = run_world_config(cfg)
    dp, sigma = ch.dp.irradiance_w_m2, ch.dp.stderr_w_m2
    assert np.all(np.abs(dp) > 5 * sigma), "every frame's change is resolved"
    ratio = intrusion_position(dp[:, 0], dp[:, 1])
    assert np.all(np.diff(ratio) > 0), f"Eq. 4 ratio not monotonic: {ratio}"
    out = tmp_path / "out"
    for name in ("measurements.npz", "measurements.csv", "dP.png", "camera.npz", "measurements/run.json"):
        assert (out / name).is_file(), name
    assert sorted(out.rglob(".mincam.lock")) == [out / ".mincam.lock"]  # one lock for the record and the store
    with np.load(out / "measurements.npz") as data:
        assert data["delta_irradiance_w_m2"].shape == data["irradiance_w_m2"].shape == (cfg.n_frames, 2)
    header = (out / "measurements.csv").read_text().splitlines()[1].split(",")
    assert header[:3] == ["frame", "time_s", "toy_car_offset_x_m"] and "change_centroid_col_px" in header
    cols = np.array(ch.frame_columns["change_centroid_col_px"])
    assert np.all(np.diff(cols) > 0), "the ground-truth change moves across the camera image"
    np.testing.assert_allclose(ch.frame_columns["toy_car_centre_x_m"], -0.12 + np.linspace(0, 0.24, 13), atol=1e-6)


def test_rerun_reuses_and_a_changed_xml_or_mesh_is_refused(tmp_path):
    config = _room_copy(tmp_path)
    first = run_world_config(load_world_config(config))
    again = run_world_config(load_world_config(config))
    np.testing.assert_array_equal(first.dp.irradiance_w_m2, again.dp.irradiance_w_m2)
    xml = tmp_path / "room.xml"
    xml.write_text(xml.read_text().replace('value="0.15"', 'value="0.2"'))
    with pytest.raises(StaleResultError):
        run_world_config(load_world_config(config))
    xml.write_text(xml.read_text().replace('value="0.2"', 'value="0.15"'))
    mesh = tmp_path / "toy_car.obj"
    mesh.write_text(mesh.read_text().replace("v -0.03000000", "v -0.03100000", 1))  # a mesh the XML names
    with pytest.raises(StaleResultError):
        run_world_config(load_world_config(config))


def test_a_finished_run_shows_its_camera_again_and_renders_it_only_when_something_changed(tmp_path, monkeypatch):
    """A rerun of a finished world run reads ``camera.npz`` back (no camera render, the same centroids); other
    camera settings, ``overwrite``, or a damaged file render it again (the measurements are still reused, the
    user is told why); the file never answers for settings it was not rendered with."""
    config = _room_copy(tmp_path)
    text = config.read_text().replace("spp = 8192", "spp = 1024")
    config.write_text(text)
    first = run_world_config(load_world_config(config))
    renders, said = [], []
    real = ms.Simulation.camera_changes

    def counted(self, *args, **kwargs):
        renders.append(kwargs.get("spp"))
        return real(self, *args, **kwargs)

    monkeypatch.setattr(ms.Simulation, "camera_changes", counted)
    again = run_world_config(load_world_config(config), say=said.append)
    assert renders == [] and "without rendering" in said[0]
    for name in ("change_centroid_row_px", "change_centroid_col_px"):
        np.testing.assert_array_equal(again.frame_columns[name], first.frame_columns[name])
    config.write_text(text.replace("spp = 32", "spp = 16"))  # the camera's samples: the run itself is the same
    other = run_world_config(load_world_config(config), say=said.append)
    assert renders == [16] and "rendered for other settings" in said[-1]
    np.testing.assert_array_equal(other.dp.irradiance_w_m2, first.dp.irradiance_w_m2)
    run_world_config(load_world_config(config))
    assert renders == [16]
    run_world_config(load_world_config(config), overwrite=True)
    assert renders == [16, 16]
    kept = (tmp_path / "out" / "camera.npz").read_bytes()
    for damaged in (b"not a npz file", kept[:len(kept) // 2]):  # not a file numpy reads; a zip cut short
        (tmp_path / "out" / "camera.npz").write_bytes(damaged)
        run_world_config(load_world_config(config))
    assert renders == [16, 16, 16, 16]
    with np.load(tmp_path / "out" / "camera.npz") as data:
        assert data["frames"].shape == (13, 96, 96)


def _y_up(text: str) -> str:
    """The same room authored y-up: every shape's to_world followed by a turn taking z-up to y-up."""
    return re.sub(r"(<transform name=\"to_world\">)(.*?)(</transform>)",
                  lambda m: m.group(1) + m.group(2) + '    <rotate x="1" angle="-90"/>\n        ' + m.group(3),
                  text, flags=re.S)


def test_a_y_up_scene_measures_as_its_z_up_twin(tmp_path):
    z_up = ms.Simulation(CAM, world=ROOM / "room.xml")
    config = _room_copy(tmp_path, _y_up)
    cfg = load_world_config(config)
    from mincam_sim.runs.jobs import build_elements

    cfg.up = "y"
    turned = ms.Simulation(CAM, world=build_elements(cfg))
    cfg.up = "z"
    unturned = ms.Simulation(CAM, world=build_elements(cfg))
    (a, sa), (b, sb), (c, sc) = _estimates(z_up, 5), _estimates(turned, 6), _estimates(unturned, 6)
    assert_close_mc(b, a, np.hypot(sa, sb), what="y-up twin vs z-up room")
    assert np.any(np.abs(c - a) > 10 * np.hypot(sa, sc)), "without the turn the y-up room must look different"


def _write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


BAD_CONFIGS = {
    "missing xml": ('[world]\nscene = "nowhere.xml"\n[[world.mover]]\nid = "a"\noffsets_m = [[0, 0, 0]]\n',
                    "does not exist"),
    "no movers": ('[world]\nscene = "room.xml"\n', "at least one \\[\\[world.mover\\]\\]"),
    "count mismatch": ('[world]\nscene = "room.xml"\n[[world.mover]]\nid = "toy_car"\noffsets_m = [[0, 0, 0]]\n'
                       '[[world.mover]]\nid = "wall"\noffsets_m = [[0, 0, 0], [0, 0, 0.1]]\n', "frame counts differ"),
    "nan offset": ('[world]\nscene = "room.xml"\n[[world.mover]]\nid = "toy_car"\noffsets_m = [[0, nan, 0]]\n',
                   "finite"),
    "two trajectories": ('[world]\nscene = "room.xml"\n[[world.mover]]\nid = "toy_car"\noffsets_m = [[0, 0, 0]]\n'
                         'csv = "t.csv"\n', "exactly one of"),
    "unknown key": ('[world]\nscene = "room.xml"\nsceen = 1\n', "sceen"),
    "bad light": ('[world]\nscene = "room.xml"\n[[world.light]]\nid = "l"\nkind = "laser"\n', "kind"),
    "spp below replicates": ('[run]\nspp = 4\n[world]\nscene = "room.xml"\n', "fewer than its"),
}


@pytest.mark.parametrize("case", list(BAD_CONFIGS))
def test_bad_world_configs_are_one_clear_error(tmp_path, case):
    _room_copy(tmp_path)
    text, message = BAD_CONFIGS[case]
    with pytest.raises(ConfigError, match=message):
        load_world_config(_write(tmp_path, "bad.toml", text))


def test_bad_files_are_one_clear_error(tmp_path):
    _room_copy(tmp_path)
    broken = _write(tmp_path, "broken.xml", '<scene version="3.0.0">\n  <shape type="rectangle" id="a">\n'
                                            '  </shap>\n</scene>\n')
    with pytest.raises(InputError, match=r"broken.xml: Mitsuba could not load the scene.*line"):
        ms.Simulation(CAM, world=broken)
    cfg = load_world_config(_write(tmp_path, "c.toml", '[world]\nscene = "room.xml"\n[[world.mover]]\n'
                                                       'id = "car"\noffsets_m = [[0, 0, 0]]\n'))
    with pytest.raises(ConfigError, match="'car' is not a shape or light of the scene that can move; movable: "
                                          ".*toy_car"):
        run_world_config(cfg)
    _write(tmp_path, "junk.obj", "this is not a mesh\n")
    cfg = load_world_config(_write(tmp_path, "d.toml", '[world]\n[[world.object]]\nid = "junk"\nmesh = "junk.obj"\n'
                                                       '[[world.mover]]\nid = "junk"\noffsets_m = [[0, 0, 0]]\n'))
    from mincam_sim.runs.jobs import build_elements

    with pytest.raises(InputError, match="junk.obj"):
        build_elements(cfg)
    _write(tmp_path, "t.csv", "t_s,x_m,y_m,z_m\n0,0,0,0\n1,nan,0,0\n")
    with pytest.raises(ConfigError, match="NaN"):
        load_world_config(_write(tmp_path, "e.toml", '[world]\nscene = "room.xml"\n[[world.mover]]\n'
                                                     'id = "toy_car"\ncsv = "t.csv"\n'))


def test_keyframes_and_csv_trajectories_are_sampled_at_the_frame_rate(tmp_path):
    _room_copy(tmp_path)
    _write(tmp_path, "t.csv", "t_s,x_m,y_m,z_m\n0,0,0,0\n0.5,0.1,0,0\n")
    cfg = load_world_config(_write(tmp_path, "k.toml", '[world]\nscene = "room.xml"\nframe_rate_hz = 4.0\n'
                                                       '[[world.mover]]\nid = "toy_car"\ncsv = "t.csv"\n'))
    np.testing.assert_allclose(cfg.movers[0].offsets_m[:, 0], [0.0, 0.05, 0.1])


def test_the_example_world_config_parses_and_documents_every_key():
    text = world_example_toml()
    for key in ("solver", "spp", "scene", "up", "frame_rate_hz", "background", "offsets_m", "keyframes_m"):
        assert re.search(rf"^#? ?{key} = ", text, flags=re.M), key


def test_cli_renders_a_world_config(tmp_path):
    config = _room_copy(tmp_path)
    check = subprocess.run([sys.executable, "-m", "mincam_sim.cli", "render", str(config), "--check"],
                           capture_output=True, text=True, timeout=300)
    assert check.returncode == 0, check.stderr
    assert "world scene" in check.stdout and "mover toy_car: 13 frames" in check.stdout
    bad = _write(tmp_path, "bad.toml", '[world]\nscene = "room.xml"\n[[world.mover]]\nid = "toy_car"\n'
                                       'offsets_m = [[0, 0]]\n')
    done = subprocess.run([sys.executable, "-m", "mincam_sim.cli", "render", str(bad)], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 2 and done.stderr.count("\n") == 1 and "offsets_m[0]" in done.stderr, done.stderr


def test_measure_changes_in_world_coordinates_from_python():
    """The README's recipe: load the XML, move the car by id in world coordinates, measure changes."""
    sim = ms.Simulation(CAM, world=ROOM / "room.xml")
    v0 = sim.params["toy_car.vertex_positions"].reshape(-1, 3)
    frames = [vertex_update("toy_car", v0 + [dx, 0.0, 0.0]) for dx in (0.05, 0.1)]
    ch = sim.measure_changes(frames, background={}, budget=ms.Budget(spp=1 << 12))
    assert ch.dp.irradiance_w_m2.shape == (2, 2) and ch.info.solver == "stratified_change"


_TOP = """<scene version="3.0.0">
    <default name="mesh" value="toy.obj"/>
    <include filename="parts/light.xml"/>
    <shape type="rectangle" id="floor">
        <transform name="to_world"><scale x="0.6" y="0.6" z="1"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.3"/></bsdf>
    </shape>
    <shape type="obj" id="toy">
        <string name="filename" value="$mesh"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.8"/></bsdf>
    </shape>
</scene>
"""
_LIGHT = """<scene version="3.0.0">
    <shape type="rectangle" id="lamp">
        <transform name="to_world"><scale x="0.1" y="0.1" z="1"/><rotate x="1" angle="180"/>
            <translate z="1.0"/></transform>
        <emitter type="area"><rgb name="radiance" value="{radiance}"/></emitter>
    </shape>
</scene>
"""


def _scene_files(tmp_path: Path, radiance: float = 20.0, toy_z: float = 0.0) -> Path:
    (tmp_path / "parts").mkdir(exist_ok=True)
    (tmp_path / "parts" / "light.xml").write_text(_LIGHT.format(radiance=radiance))
    box = trimesh.creation.box((0.04, 0.04, 0.04))
    box.apply_translation((0.05, 0.0, 0.02 + toy_z))
    box.export(tmp_path / "toy.obj")
    (tmp_path / "scene.xml").write_text(_TOP)
    return tmp_path / "scene.xml"


def test_an_edited_include_or_a_mesh_named_through_a_parameter_is_never_the_same_run(tmp_path):
    """The run's identity hashes every file the scene names, recursively: an ``<include>``d file and a mesh
    named through a ``$parameter`` default. Editing either makes the next run refuse (never report the old
    result as 'this same run'); overwriting recomputes."""
    path = _scene_files(tmp_path)
    sim = ms.Simulation(CAM, world=path)
    files = sim.identity()["files"]
    assert set(files) == {"scene.xml", "parts/light.xml", "toy.obj"}
    vertices = np.asarray(sim.params["toy.vertex_positions"]).reshape(-1, 3)
    frames = [vertex_update("toy", vertices + [0.1, 0.0, 0.0])]
    budget = ms.Budget(spp=1 << 12, replicates=4)
    with ms.Run(tmp_path / "out") as run:
        first = run.measure_changes(sim, frames, None, ms.PlainChange(), budget)
    with ms.Run(tmp_path / "out") as run:  # unchanged files: the finished result, as it is
        again = run.measure_changes(ms.Simulation(CAM, world=path), frames, None, ms.PlainChange(), budget)
    np.testing.assert_array_equal(again.p.irradiance_w_m2, first.p.irradiance_w_m2)
    for edit in (lambda: _scene_files(tmp_path, radiance=21.0), lambda: _scene_files(tmp_path, toy_z=0.01)):
        edit()
        edited = ms.Simulation(CAM, world=path)
        assert edited.identity()["files"] != files
        with ms.Run(tmp_path / "out") as run, pytest.raises(StaleResultError, match="scene.files"):
            run.measure_changes(edited, frames, None, ms.PlainChange(), budget)
        _scene_files(tmp_path)  # back as it was: the same run again
    with ms.Run(tmp_path / "out") as run:
        back = run.measure_changes(ms.Simulation(CAM, world=path), frames, None, ms.PlainChange(), budget)
    np.testing.assert_array_equal(back.p.irradiance_w_m2, first.p.irradiance_w_m2)
    _scene_files(tmp_path, radiance=21.0)
    with ms.Run(tmp_path / "out", overwrite=True) as run:
        brighter = run.measure_changes(ms.Simulation(CAM, world=path), frames, None, ms.PlainChange(), budget)
    assert np.all(brighter.p.irradiance_w_m2 > first.p.irradiance_w_m2)
