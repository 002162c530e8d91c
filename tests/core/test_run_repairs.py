"""A rerun repairs an output directory: a damaged result file is computed again (from the run's store) and
replaced, outputs a killed run never wrote (the response maps) are written, ``overwrite`` deletes the outputs of
the run it replaces (and nothing else), and a damaged ``camera.npz`` is called damaged."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

import mincam_sim as ms
from mincam_sim.configuration.config import load_config
from mincam_sim.configuration.world_config import CameraSpec
from mincam_sim.measurements import Measurements
from mincam_sim.render.kernels import map_tracing
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.updates import vertex_update
from mincam_sim.render.solvers import DotProduct
from mincam_sim.runs.jobs import _camera_dict, _ground_truth, maps_outputs, remove_outputs, run_render_config
from mincam_sim.scene.display import line_sweep
from mincam_sim.storage.imageio import read_exr

SCREEN = ms.Screen(resolution=(32, 18))
MAPS = ("response_maps/response_x.exr", "response_maps/response_1-x.exr")
#: A 16 x 16 ground-truth camera over the table, 4 samples a pixel.
CAMERA = CameraSpec((0.0, 0.0, 0.6), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 60.0, 16, 16, 4, 0.05)


def _config(tmp_path: Path, **run):
    """A 32 x 18 screen, 2 frames, 16 samples a texel for the response map solver."""
    budget = {"samples_per_texel": 16} if run.get("solver", "response_map") == "response_map" else {}
    return load_config({"run": {**budget, "out_dir": str(tmp_path / "out"), **run},
                        "frames": {"n": 2}, "screen": {"resolution": [32, 18]}})


def _no_tracing(monkeypatch) -> None:
    """Tracing a response map or a frame's rays fails the test: a rerun reads what the run kept."""
    def refuse(*args, **kwargs):
        raise AssertionError("traced again although the run's store and cache hold everything")

    monkeypatch.setattr(map_tracing._MapTracer, "trace", refuse)


def _world(camera: CameraSpec | None = None):
    """(world, frames, background): a table under a sky, and a box moved over it in two frames (parked far off in
    the background); with ``camera``, the ground-truth camera as well."""
    box = trimesh.creation.box((0.05, 0.05, 0.05))
    park = box.vertices + [5.0, 5.0, 0.0]
    elements = {"table": sd.textured_plane(np.full((4, 4), 0.5), 1.0, 1.0, ms.Pose((0, 0, 0), (0, 0, 1)).matrix()),
                "sky": sd.sky(2.0), "box": sd.mesh_object("box", park, box.faces, 0.9)}
    world = ms.Simulation(ms.cross_layout(center=ms.Pose((0, 0, 0.5), (0, 0, -1), (0, 1, 0))), world=elements,
                          camera=None if camera is None else _camera_dict(camera))
    frames = [vertex_update("box", box.vertices + [x, 0.02, 0.025]) for x in (-0.08, 0.08)]
    return world, frames, vertex_update("box", park)


def _damage(path: Path, how: str) -> None:
    data = path.read_bytes()
    path.write_bytes({"empty": b"", "cut": data[: len(data) // 2], "garbage": b"not an npz file"}[how])


# ----------------------------------------------------------------------------- a damaged result file


@pytest.mark.parametrize("how", ["empty", "cut", "garbage"])
def test_a_damaged_measurements_npz_is_computed_again_from_the_store(how, tmp_path, monkeypatch):
    """An empty file (EOFError), one cut short (BadZipFile) or garbage (ValueError) in place of the finished
    result: the rerun rebuilds it from the run's per-frame store and map cache (nothing traced), with the same
    numbers, and says so."""
    first, _ = run_render_config(_config(tmp_path))
    out = tmp_path / "out"
    _damage(out / "measurements.npz", how)
    _no_tracing(monkeypatch)
    said: list[str] = []
    again, _ = run_render_config(_config(tmp_path), say=said.append)
    np.testing.assert_array_equal(again.irradiance_w_m2, first.irradiance_w_m2)
    np.testing.assert_array_equal(again.stderr_w_m2, first.stderr_w_m2)
    kept = Measurements.load_npz(out / "measurements.npz")  # replaced by a whole file
    np.testing.assert_array_equal(kept.irradiance_w_m2, first.irradiance_w_m2)
    assert any("measurements.npz is damaged or unreadable" in line for line in said), said


def test_a_damaged_result_of_a_run_is_replaced_for_displays_and_worlds(tmp_path):
    """Through ``Run`` itself: a result file cut short is named in ``run.unreadable``, computed again and
    replaced (a display measurement and a world change run alike)."""
    sim = ms.Simulation(ms.pair_layout(), screen=SCREEN)
    frames = line_sweep((-0.2, 0.0), (0.2, 0.0), 2, 0.05).frame_stack(SCREEN)
    world, world_frames, background = _world()
    budget = ms.Budget(spp=256, replicates=4)
    with ms.Run(tmp_path) as run:
        m = run.measure(sim, frames, ms.Aperture(), budget, name="display")
        ch = run.measure_changes(world, world_frames, background, ms.PlainChange(), budget, name="world")
    for name in ("display", "world"):
        _damage(tmp_path / f"{name}.npz", "cut")
    with ms.Run(tmp_path) as run:
        m2 = run.measure(sim, frames, ms.Aperture(), budget, name="display")
        ch2 = run.measure_changes(world, world_frames, background, ms.PlainChange(), budget, name="world")
        assert sorted(run.unreadable) == ["display", "world"] and run.reused == []
        assert "BadZipFile" in run.unreadable["display"]
    np.testing.assert_array_equal(m2.irradiance_w_m2, m.irradiance_w_m2)
    np.testing.assert_array_equal(ch2.dp.irradiance_w_m2, ch.dp.irradiance_w_m2)
    with ms.Run(tmp_path) as run:  # whole again: reused as they are
        run.measure(sim, frames, ms.Aperture(), budget, name="display")
        run.measure_changes(world, world_frames, background, ms.PlainChange(), budget, name="world")
        assert sorted(run.reused) == ["display", "world"] and run.unreadable == {}


# ------------------------------------------------------------------------- outputs a killed run never wrote


def test_a_finished_results_missing_csv_is_written_again(tmp_path):
    sim = ms.Simulation(ms.pair_layout(), screen=SCREEN)
    frames = line_sweep((-0.2, 0.0), (0.2, 0.0), 2, 0.05).frame_stack(SCREEN)
    budget = ms.Budget(samples_per_texel=8)
    with ms.Run(tmp_path) as run:
        run.measure(sim, frames, ms.ResponseMap(), budget)
    written = (tmp_path / "measurements.csv").read_text()
    (tmp_path / "measurements.csv").unlink()
    with ms.Run(tmp_path) as run:
        run.measure(sim, frames, ms.ResponseMap(), budget)
        assert run.reused == ["measurements"]
    assert (tmp_path / "measurements.csv").read_text() == written


@pytest.mark.parametrize("solver", ["response_map", "dot_product"])
def test_response_maps_missing_from_a_finished_run_are_written_again(solver, tmp_path, monkeypatch):
    """A run killed (or a disk filled) after ``measurements.npz`` but before its maps: the rerun reuses the
    measurements and writes the maps again, the response map solver's from the run's cache (nothing traced), with
    the same values; it says what was missing."""
    cfg = _config(tmp_path, solver=solver)
    _, maps = run_render_config(cfg)
    out = tmp_path / "out"
    written = {name: read_exr(out / name) for name in MAPS}
    for name in MAPS[1:]:  # killed between the two mixels' files
        (out / name).unlink()
    _no_tracing(monkeypatch)
    said: list[str] = []
    m, again = run_render_config(_config(tmp_path, solver=solver), say=said.append)
    assert "without rendering" in said[0] and "response_maps/response_1-x.exr" in said[1], said
    assert again is not None and m.maps is None  # the measurements were reused; the maps made again
    np.testing.assert_array_equal(again.weights_sr, maps.weights_sr)
    for name in MAPS:
        for a, b in zip(read_exr(out / name), written[name], strict=True):
            np.testing.assert_array_equal(a, b)


def test_the_maps_outputs_looked_for_are_the_files_the_maps_write(tmp_path):
    """``maps_outputs`` names each mixel's OpenEXR as ``ResponseMaps.save_exr`` writes it, odd names included."""
    mincam = ms.Mincam(tuple(dataclasses.replace(mixel, name=name)
                             for mixel, name in zip(ms.pair_layout(), ("a b/c", "ü.2"), strict=True)))
    maps = DotProduct().maps(mincam, SCREEN)
    written = maps.save_exr(tmp_path / "response_maps")
    assert maps_outputs(tmp_path, mincam.names) == [*written, tmp_path / "response_maps.png"]


def test_a_finished_run_with_all_its_outputs_makes_no_maps(tmp_path, monkeypatch):
    run_render_config(_config(tmp_path))
    (tmp_path / "out" / "response_maps.png").write_bytes(b"the figure render draws")

    def refuse(*args, **kwargs):
        raise AssertionError("maps made again although every output of theirs is there")

    monkeypatch.setattr(ms.ResponseMap, "maps", refuse)
    _, maps = run_render_config(_config(tmp_path))
    assert maps is None


# ---------------------------------------------------------------------------- overwrite replaces a run


def test_overwrite_deletes_the_replaced_runs_outputs_and_no_other_file(tmp_path):
    """A response-map run, then an aperture run with ``overwrite``: the maps (files and figure) and any other
    output of the earlier run are gone; the user's own files, even inside ``response_maps/``, are kept."""
    run_render_config(_config(tmp_path))
    out = tmp_path / "out"
    assert all((out / name).is_file() for name in MAPS)
    stale = ["response_maps.png", "measurements.png", "camera.npz", "dP.png"]  # a figure; a world run's files
    for name in stale:
        (out / name).write_bytes(b"an earlier run's")
    (out / "notes.txt").write_text("mine")
    (out / "response_maps" / "my_edit.exr").write_bytes(b"mine too")
    m, maps = run_render_config(_config(tmp_path, solver="aperture", spp=256), overwrite=True)
    assert maps is None and m.meta["solver"] == "aperture"
    assert not any((out / name).exists() for name in (*MAPS, *stale))
    assert (out / "notes.txt").read_text() == "mine" and (out / "response_maps" / "my_edit.exr").is_file()
    assert Measurements.load_npz(out / "measurements.npz").meta["solver"] == "aperture"
    assert (out / "measurements.csv").is_file()


def test_remove_outputs_removes_an_emptied_maps_folder_and_refuses_what_it_cannot_delete(tmp_path):
    run_render_config(_config(tmp_path, solver=DotProduct.name))
    out = tmp_path / "out"
    removed = remove_outputs(out)
    assert sorted(p.relative_to(out).as_posix() for p in removed) == sorted(
        ["measurements.npz", "measurements.csv", *MAPS])
    assert not (out / "response_maps").exists() and (out / "measurements" / "run.json").is_file()
    (out / "measurements.png").mkdir()  # not a file: left alone, as a user's folder would be
    assert remove_outputs(out) == []


# ----------------------------------------------------------------------------------- the world's camera


def test_a_damaged_camera_npz_is_called_damaged_not_other_settings(tmp_path):
    """A ``camera.npz`` cut short or empty is rendered again and called damaged; one with another key was
    rendered for other settings; one without the key is not a camera file of this version."""
    sim, frames, background = _world(CAMERA)
    said: list[str] = []

    def ground_truth(key: str):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # an undefined centroid: not what is tested here
            return _ground_truth(sim, CAMERA, frames, background, tmp_path, key, True, said.append)

    first = ground_truth("k" * 16)
    assert said == []
    path = tmp_path / "camera.npz"
    _damage(path, "cut")
    again = ground_truth("k" * 16)
    assert said[-1] == (f"mincam-sim: {path} is damaged or unreadable (BadZipFile: File is not a zip file): "
                        "rendering it again")
    np.testing.assert_array_equal(again[1], first[1])
    _damage(path, "empty")
    ground_truth("k" * 16)
    assert "is damaged or unreadable (EOFError" in said[-1]
    ground_truth("k" * 16)
    assert len(said) == 2  # whole again: read back, nothing said
    ground_truth("other" * 4)
    assert said[-1] == (f"mincam-sim: {path} was rendered for other settings (camera, scene or method): rendering "
                        "it again")
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files if k != "identity_key"}  # an older file's arrays
    np.savez(path, **arrays)
    ground_truth("other" * 4)
    assert "is not a camera file of this version (identity_key is not a file in the archive)" in said[-1]
