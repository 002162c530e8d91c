"""``export-maps`` (and ``Simulation.export_maps``) into a folder that holds an earlier export: the folder ends up
holding one complete export, the earlier export's files the new one does not write removed (saying so), a user's
own files kept, an interrupted export's leftovers removed by the next one; and a second export into a folder
another process holds is refused, naming the holder."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import mincam_sim as ms
from mincam_sim.render.kernels import map_export

SCREEN = ms.Screen(resolution=(16, 9))
PAIR = ("maps/x.npy", "maps/x_stderr.npy", "maps/1-x.npy", "maps/1-x_stderr.npy")
CROSS_ONLY = ("maps/y.npy", "maps/y_stderr.npy", "maps/1-y.npy", "maps/1-y_stderr.npy")
CONFIG = '[mincam]\nlayout = "{layout}"\n[screen]\nresolution = [16, 9]\n'


def _files(folder: Path) -> set[str]:
    return {p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()}


def _export_cli(tmp_path: Path, layout: str, out: Path, *extra: str):
    from mincam_sim.cli import app

    config = tmp_path / f"{layout}.toml"
    config.write_text(CONFIG.format(layout=layout))
    return CliRunner().invoke(app, ["export-maps", str(config), "--out", str(out), "--ideal", *extra])


def _user_files(out: Path) -> dict[Path, bytes]:
    """A user's own files in the folder: beside the export, in maps/ (an .npy no maps.json lists) and one named
    like a map in a folder the package does not write."""
    files = {out / "notes.txt": b"mine", out / "maps" / "mine.npy": b"not a map", out / "other" / "x.npy": b"x"}
    for path, data in files.items():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    return files


def test_a_second_export_removes_the_earlier_exports_stale_maps_and_psfs_and_says_so(tmp_path):
    out = tmp_path / "em"
    first = _export_cli(tmp_path, "cross", out, "--psf-grid", "2", "2")
    assert first.exit_code == 0, first.output
    assert np.load(out / "psfs.npy").shape == (2, 2, 4)
    mine = _user_files(out)

    second = _export_cli(tmp_path, "pair", out)
    assert second.exit_code == 0, second.output
    files = _files(out)
    assert not files & {*CROSS_ONLY, "psfs.npy"}, files
    assert files == {*PAIR, "forward_matrix.npy", "maps.json", ".mincam.lock",
                     *(p.relative_to(out).as_posix() for p in mine)}
    assert all(path.read_bytes() == data for path, data in mine.items())  # a user's files are kept as they were
    meta = json.loads((out / "maps.json").read_text())
    assert meta["mixel_names"] == ["x", "1-x"] and "psfs" not in meta
    assert np.load(out / "forward_matrix.npy").shape == (2, 16 * 9)
    said = [line for line in second.output.splitlines() if "removed" in line]
    assert len(said) == 1 and "5 files of the earlier export" in said[0] and "psfs.npy" in said[0], second.output
    assert all(rel in said[0] for rel in CROSS_ONLY)

    again = _export_cli(tmp_path, "pair", out)  # the same export again: nothing to remove, nothing said
    assert again.exit_code == 0 and "removed" not in again.output and _files(out) == files


def test_the_python_api_keeps_the_folder_one_export_too(tmp_path):
    said: list[str] = []
    ms.Simulation(ms.cross_layout(spacing_m=0.033), screen=SCREEN).export_maps(
        tmp_path, solver=ms.DotProduct(), psf_grid=(3, 2), say=said.append)
    assert said == []
    (tmp_path / "keep.npy").write_bytes(b"user")
    sidecar = ms.Simulation(ms.pair_layout(spacing_m=0.033), screen=SCREEN).export_maps(
        tmp_path, solver=ms.DotProduct(), say=said.append)
    assert _files(tmp_path) == {*PAIR, "forward_matrix.npy", "maps.json", "keep.npy"}
    assert json.loads(sidecar.read_text())["mixel_names"] == ["x", "1-x"]
    assert len(said) == 1 and "removed 5 files" in said[0]


def test_only_names_the_package_writes_are_taken_from_an_earlier_maps_json(tmp_path):
    out = tmp_path / "em"
    (out / "maps").mkdir(parents=True)
    outside = tmp_path / "outside.npy"
    kept = [outside, out / "notes.txt", out / "maps" / "a.b.npy", out / "maps" / "z.txt", out / "maps" / "z.npy"]
    for path in kept:
        path.write_bytes(b"user")
    listed = ["../outside.npy", "notes.txt", "maps/a.b.npy", "maps/z.txt", "maps/../maps/z.npy", str(out / "x.npy")]
    (out / "maps.json").write_text(json.dumps({"files": {"z": {"map": listed[0], "stderr": listed[1]},
                                                         "w": dict(enumerate(listed[2:]))},
                                               "psfs": {"file": "../outside.npy"}}))
    assert map_export.earlier_export_files(out) == set()
    ms.Simulation(ms.pair_layout(spacing_m=0.033), screen=SCREEN).export_maps(out, solver=ms.DotProduct())
    assert all(path.read_bytes() == b"user" for path in kept)


def test_the_next_export_removes_what_an_interrupted_one_left(tmp_path, monkeypatch):
    ms.Simulation(ms.pair_layout(spacing_m=0.033), screen=SCREEN).export_maps(tmp_path, solver=ms.DotProduct())
    save, calls = map_export._save, []

    def failing_save(path: Path, array: np.ndarray) -> None:
        calls.append(path)
        if len(calls) > 5:  # x, 1-x and y.npy are written, then the disk is full
            raise OSError(28, "No space left on device", str(path))
        save(path, array)

    monkeypatch.setattr(map_export, "_save", failing_save)
    with pytest.raises(OSError, match="No space"):
        ms.Simulation(ms.cross_layout(spacing_m=0.033), screen=SCREEN).export_maps(tmp_path, solver=ms.DotProduct(),
                                                                                    psf_grid=(2, 2))
    assert not (tmp_path / "maps.json").exists()  # no sidecar describes the half-written folder
    assert (tmp_path / map_export.PENDING).is_file()
    monkeypatch.setattr(map_export, "_save", save)
    said: list[str] = []
    ms.Simulation(ms.single(ms.masks.constant(1.0)), screen=SCREEN).export_maps(
        tmp_path, solver=ms.DotProduct(), say=said.append)
    name = ms.single(ms.masks.constant(1.0)).names[0]
    assert _files(tmp_path) == {f"maps/{name}.npy", f"maps/{name}_stderr.npy", "forward_matrix.npy", "maps.json"}
    assert len(said) == 1 and "maps/x.npy" in said[0] and "maps/y.npy" in said[0]  # y.npy: only pending lists it


def _hold_lock(folder: Path) -> subprocess.Popen:
    folder.mkdir(parents=True, exist_ok=True)
    code = ("import sys, time; from mincam_sim.storage.store import lock_out_dir; l = lock_out_dir(sys.argv[1]); "
            "print('locked', flush=True); time.sleep(60)")
    holder = subprocess.Popen([sys.executable, "-c", code, str(folder)], stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline().strip() == "locked"
    return holder


def test_an_export_into_a_folder_another_process_holds_is_refused_naming_it(tmp_path):
    out = tmp_path / "em"
    assert _export_cli(tmp_path, "cross", out, "--psf-grid", "2", "2").exit_code == 0
    before = {rel: (out / rel).read_bytes() for rel in _files(out) if rel != ".mincam.lock"}
    holder = _hold_lock(out)
    try:
        result = _export_cli(tmp_path, "pair", out)
        assert result.exit_code == 2, result.output
        errors = [line for line in result.output.splitlines() if line.startswith("error: ")]
        assert len(errors) == 1 and f"PID {holder.pid}" in errors[0] and "in use by another run" in errors[0]
    finally:
        holder.kill()
        holder.wait()
        holder.stdout.close()
    assert {rel: (out / rel).read_bytes() for rel in _files(out) if rel != ".mincam.lock"} == before  # untouched


def _warnings(result) -> list[str]:
    return [line for line in result.output.splitlines() if line.startswith("warning: ")]


def test_ignored_run_keys_are_named_as_the_file_writes_them_and_the_export_reads_its_own(tmp_path):
    """A file written for another solver: the warning said ``Budget.spp`` (the Python API's name) where the
    file says ``[run] spp``, also for an spp the file never wrote; and the file's samples_per_texel was dropped
    (the maps were traced at the default 64) while a warning said it was ignored."""
    from mincam_sim.cli import app
    from mincam_sim.render import backend

    if not backend.is_jit():
        pytest.skip("response maps need a JIT variant (LLVM or CUDA)")
    head = CONFIG.format(layout="pair") + '[run]\nsolver = "aperture"\n'
    cases = {  # [run] keys -> the warnings of export-maps (and of export-maps --ideal)
        "spp = 1000\n": (['warning: [run] spp is ignored: export-maps traces response maps at samples_per_texel '
                          '(spp is for the "aperture" and "reference" solvers of render) (IgnoredSettingWarning)'],
                         ["warning: [run] spp is ignored: --ideal exports the idealised dot-product model: "
                          "deterministic quadrature (no samples) (IgnoredSettingWarning)"]),
        "samples_per_texel = 16\nreplicates = 4\n": ([], ["warning: [run] samples_per_texel, replicates are "
                                                          "ignored: --ideal exports the idealised dot-product model: "
                                                          "deterministic quadrature (no samples) "
                                                          "(IgnoredSettingWarning)"]),
        "seed = 3\n": ([], ["warning: [run] seed is ignored: --ideal exports the idealised dot-product model: "
                            "deterministic quadrature (no samples) (IgnoredSettingWarning)"]),
    }
    for k, (keys, (physics, ideal)) in enumerate(cases.items()):
        config = tmp_path / f"c{k}.toml"
        config.write_text(head + keys)
        for extra, expected in (([], physics), (["--ideal"], ideal)):
            out = tmp_path / f"out{k}{len(extra)}"
            result = CliRunner().invoke(app, ["--quiet", "export-maps", str(config), "--out", str(out), *extra])
            assert result.exit_code == 0, result.output
            assert _warnings(result) == expected, (keys, extra, result.output)
    source = json.loads((tmp_path / "out10" / "maps.json").read_text())["source"]
    assert source["samples_per_texel"] == 16 and source["replicate_blocks"] == 4  # the file's, not the defaults
