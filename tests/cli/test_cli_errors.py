"""Bad inputs give one line ``error: ...`` on stderr, exit code 2, no traceback; good ones still work.

``CASES`` is a table of bad (and a few good) inputs a new user might give. The fast tests run a selection
in-process (typer's CliRunner) and a few through the real ``mincam-sim`` executable; the whole table runs as a
slow test. ``python tests/cli/test_cli_errors.py [--pythonpath DIR]`` counts the outcomes for the code at ``DIR``
(default: this checkout), e.g. to compare with an older version extracted elsewhere.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]

BASE = {"run": {"samples_per_texel": "16", "out_dir": '"out"'}, "frames": {"n": "2"},
        "screen": {"resolution": "[32, 18]"}}


def toml(tail: str = "", head: str = "", drop: tuple[str, ...] = (), **sections: dict) -> str:
    """A small valid config (32 x 18 screen, 2 frames) with keys overridden (value None removes a key)."""
    merged = {name: dict(keys) for name, keys in BASE.items()}
    for name, keys in sections.items():
        merged.setdefault(name, {}).update(keys)
    text = head
    for name in ("run", "mincam", "screen", "frames"):
        if name in merged and name not in drop:
            text += f"[{name}]\n" + "".join(f"{k} = {v}\n" for k, v in merged[name].items() if v is not None)
    return text + tail


CUSTOM = {"layout": '"custom"'}


def mixel(**keys: str) -> str:
    keys = {"mask": '"ramp:x"', **keys}
    return "[[mixel]]\n" + "".join(f"{k} = {v}\n" for k, v in keys.items())


@dataclass
class Case:
    """One input: files to create, commands to run first, the command, and what must come out."""

    name: str
    argv: list[str]
    files: dict[str, str | bytes | Callable[[Path], None]] = field(default_factory=dict)
    expect: str = "error"  # "error": one clear line, rc 2; "ok": rc 0
    keywords: tuple[str, ...] = ()  # one of them must be in the error line (case-insensitive)
    pre: list[list[str]] = field(default_factory=list)
    between: Callable[[Path], None] | None = None  # after ``pre``, before ``argv``
    env: dict[str, str] = field(default_factory=dict)
    notes: tuple[str, ...] = ()  # "ok" cases: each must be said on stderr (else "silent")
    outputs: tuple[str, ...] = ()  # "ok" cases: files that must exist and not be empty (else "silent")
    fsize_limit: int | None = None  # bytes: the command runs as on a full disk (writes past it fail)
    clean_stderr: bool = False  # stderr must be whole lines (no carriage returns) and show no source code


def _npy(array, **kw) -> Callable[[Path], None]:
    def write(path: Path) -> None:
        np.save(path, array, **kw)

    return write


def _exr_mask(path: Path, width_m: float) -> None:
    from mincam_sim.masks import ramp, save_exr

    save_exr(ramp("x", 32, width_m=width_m), path)


def _npz_named_npy(path: Path) -> None:
    with open(path, "wb") as fh:
        np.savez(fh, frames=np.zeros((1, 18, 32)))


def _png(path: Path) -> None:
    from PIL import Image

    Image.fromarray((np.linspace(0, 255, 64)[None, :] * np.ones((64, 1))).astype(np.uint8)).save(path)


def _png_shape(path: Path, rows: int, cols: int) -> None:
    from PIL import Image

    Image.fromarray((np.linspace(0, 255, cols)[None, :] * np.ones((rows, 1))).astype(np.uint8)).save(path)


def _write(rel: str, data: bytes | Callable[[Path], None]) -> Callable[[Path], None]:
    def act(tmp: Path) -> None:
        path = tmp / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        if callable(data):
            data(path)
        else:
            path.write_bytes(data)

    return act


def _both(*acts: Callable[[Path], None]) -> Callable[[Path], None]:
    def act(tmp: Path) -> None:
        for a in acts:
            a(tmp)

    return act


def _unlink(rel: str) -> Callable[[Path], None]:
    return lambda tmp: (tmp / rel).unlink(missing_ok=True)


def _cut(rel: str) -> Callable[[Path], None]:
    """Cut a file to half its length (as a copy or a disk that failed halfway leaves it)."""
    def act(tmp: Path) -> None:
        data = (tmp / rel).read_bytes()
        (tmp / rel).write_bytes(data[: len(data) // 2])

    return act


R = ["render", "c.toml"]
SINE = '{kind = "sinusoid", omega_rad_per_m = 3000.0, a0 = 0.5, a1 = 0.5, phase_rad = %s}'

CASES: list[Case] = [
    # --- config documents that are not the schema's shape
    Case("section_not_a_table", R, {"c.toml": toml(head="run = 5\n", drop=("run",))}, keywords=("[run]",)),
    Case("out_dir_integer", R, {"c.toml": toml(run={"out_dir": "5"})}, keywords=("out_dir",)),
    Case("mincam_d_f_string", R, {"c.toml": toml(mincam={"d_f_m": '"2mm"'})}, keywords=("d_f_m",)),
    Case("mixel_d_f_string", R, {"c.toml": toml(mixel(d_f_m='"2mm"'), mincam=CUSTOM)}, keywords=("d_f_m",)),
    Case("seed_boolean", R, {"c.toml": toml(run={"seed": "true"})}, keywords=("seed",)),
    Case("seed_negative", R, {"c.toml": toml(run={"seed": "-1"})}, keywords=("seed",)),
    Case("resolution_fractional", R, {"c.toml": toml(screen={"resolution": "[32.5, 18]"})},
         keywords=("resolution",)),
    Case("resolution_string", R, {"c.toml": toml(screen={"resolution": '"32x18"'})}, keywords=("resolution",)),
    Case("mixel_given_as_table", R, {"c.toml": toml('[mixel]\nmask = "ramp:x"\n', mincam=CUSTOM)},
         keywords=("[[mixel]]",)),
    Case("mixel_entries_not_tables", R, {"c.toml": toml(head="mixel = [1, 2]\n", mincam=CUSTOM)},
         keywords=("mixel",)),
    Case("aspect_strings", R, {"c.toml": toml(screen={"aspect": '["16", 9]'})}, keywords=("aspect",)),
    Case("n_fractional", R, {"c.toml": toml(frames={"n": "2.5"})}, keywords=("n ",)),
    Case("start_m_string", R, {"c.toml": toml(frames={"start_m": '[0, "a"]'})}, keywords=("start_m",)),
    Case("form_integer", R, {"c.toml": toml(run={"form": "3"})}, keywords=("form",)),
    Case("layout_list", R, {"c.toml": toml(mincam={"layout": '["pair"]'})}, keywords=("layout",)),
    Case("variant_integer", R, {"c.toml": toml(run={"variant": "1"})}, keywords=("variant",)),
    Case("mixel_mask_integer", R, {"c.toml": toml(mixel(mask="5"), mincam=CUSTOM)}, keywords=("mask",)),
    Case("sinusoid_omega_string", R,
         {"c.toml": toml(mixel(mask='{kind = "sinusoid", omega_rad_per_m = "fast"}'), mincam=CUSTOM)},
         keywords=("omega",)),
    Case("sinusoid_a0_boolean", R,
         {"c.toml": toml(mixel(mask='{kind = "sinusoid", omega_rad_per_m = 1000.0, a0 = true}'), mincam=CUSTOM)},
         keywords=("a0",)),
    Case("constant_not_a_number", R, {"c.toml": toml(mixel(mask='"constant:abc"'), mincam=CUSTOM)},
         keywords=("constant",)),
    Case("file_mask_empty_path", R, {"c.toml": toml(mixel(mask='"file:"'), mincam=CUSTOM)}, keywords=("file",)),
    Case("file_mask_missing", R, {"c.toml": toml(mixel(mask='"file:nope.png"'), mincam=CUSTOM)},
         keywords=("nope.png",)),
    Case("file_mask_not_an_image", R,
         {"c.toml": toml(mixel(mask='"file:junk.png"'), mincam=CUSTOM), "junk.png": "not a png"},
         keywords=("junk.png",)),
    Case("file_mask_relative_to_config", ["render", "sub/c.toml"],
         {"sub/c.toml": toml(mixel(mask='"file:m.png"'), mincam=CUSTOM), "sub/m.png": _png}, expect="ok"),
    Case("mask_resolution_huge", R, {"c.toml": toml(mincam={"mask_resolution": "1000000000"})},
         keywords=("mask_resolution",)),
    Case("frames_n_huge", R, {"c.toml": toml(frames={"n": "100000000"})}, keywords=("n =", "frames")),
    Case("screen_resolution_huge", R, {"c.toml": toml(screen={"resolution": "[100000, 100000]"})},
         keywords=("resolution",)),
    Case("spp_float", R, {"c.toml": toml(run={"spp": "1e6"})}, keywords=("spp",)),
    Case("spp_zero", R, {"c.toml": toml(run={"spp": "0"})}, keywords=("spp",)),
    Case("replicates_boolean", R, {"c.toml": toml(run={"replicates": "true"})}, keywords=("replicates",)),
    Case("target_string", R, {"c.toml": toml(run={"target_rel_stderr": '"0.1"'})},
         keywords=("target_rel_stderr",)),
    Case("target_nan", R, {"c.toml": toml(run={"target_rel_stderr": "nan"})}, keywords=("target_rel_stderr",)),
    Case("form_unknown", R, {"c.toml": toml(run={"form": '"magic"'})}, keywords=("form",)),
    Case("run_nested_table", R, {"c.toml": toml("[run.extra]\na = 1\n")}, keywords=("extra",)),
    Case("spacing_list", R, {"c.toml": toml(mincam={"spacing_m": "[1]"})}, keywords=("spacing_m",)),
    Case("mixel_position_two_numbers", R, {"c.toml": toml(mixel(position_m="[0, 0]"), mincam=CUSTOM)},
         keywords=("position_m",)),
    Case("mixel_forward_zero", R, {"c.toml": toml(mixel(forward="[0, 0, 0]"), mincam=CUSTOM)},
         keywords=("forward",)),
    Case("mixel_up_parallel", R, {"c.toml": toml(mixel(up="[0, 0, -1]"), mincam=CUSTOM)}, keywords=("up",)),
    Case("mixel_duplicate_names", R,
         {"c.toml": toml(mixel(name='"a"') + mixel(name='"a"', position_m="[0.01, 0, 0]"), mincam=CUSTOM)},
         keywords=("unique",)),
    Case("mixel_name_integer", R, {"c.toml": toml(mixel(name="5"), mincam=CUSTOM)}, keywords=("name",)),
    Case("mixel_detector_larger_than_mask", R, {"c.toml": toml(mixel(detector_size_m="0.01"), mincam=CUSTOM)},
         keywords=("detector",)),
    Case("mixel_facing_away", R, {"c.toml": toml(mixel(forward="[0, 0, 1]"), mincam=CUSTOM)},
         keywords=("field of view", "behind")),
    Case("grid_nx_zero", R, {"c.toml": toml(frames={"kind": '"grid_sweep"', "nx": "0"})}, keywords=("nx",)),
    Case("out_dir_empty", R, {"c.toml": toml(run={"out_dir": '""'})}, keywords=("out_dir",)),
    # --- frame files
    Case("npy_path_empty", R, {"c.toml": toml(frames={"kind": '"npy"'})}, keywords=("path",)),
    Case("npy_path_integer", R, {"c.toml": toml(frames={"kind": '"npy"', "path": "5"})}, keywords=("path",)),
    Case("npy_zero_bytes", R, {"c.toml": toml(frames={"kind": '"npy"', "path": '"f.npy"'}), "f.npy": b""},
         keywords=("f.npy",)),
    Case("npy_text_file", R, {"c.toml": toml(frames={"kind": '"npy"', "path": '"f.npy"'}), "f.npy": "1 2 3\n"},
         keywords=("f.npy",)),
    Case("npy_wrong_shape", R, {"c.toml": toml(frames={"kind": '"npy"', "path": '"f.npy"'}),
                                "f.npy": _npy(np.zeros((2, 5, 5)))}, keywords=("shape",)),
    Case("npy_nan", R, {"c.toml": toml(frames={"kind": '"npy"', "path": '"f.npy"'}),
                        "f.npy": _npy(np.full((1, 18, 32), np.nan))}, keywords=("nan",)),
    Case("npy_pickled_objects", R, {"c.toml": toml(frames={"kind": '"npy"', "path": '"f.npy"'}),
                                    "f.npy": _npy(np.array([{"a": 1}], dtype=object), allow_pickle=True)},
         keywords=("f.npy",)),
    Case("npy_is_an_npz", R, {"c.toml": toml(frames={"kind": '"npy"', "path": '"f.npy"'}), "f.npy": _npz_named_npy},
         keywords=("f.npy",)),
    Case("npy_one_dimensional", R, {"c.toml": toml(frames={"kind": '"npy"', "path": '"f.npy"'}),
                                    "f.npy": _npy(np.zeros(5))}, keywords=("shape",)),
    # --- config files themselves
    Case("config_is_a_directory", ["render", "d.toml"], {"d.toml/x": "x"}, keywords=("directory",)),
    Case("config_missing", ["render", "missing.toml"], keywords=("missing.toml",)),
    Case("config_not_utf8", R, {"c.toml": b"\xff\xfe\x00[run]\n"}, keywords=("utf-8",)),
    Case("config_invalid_toml", R, {"c.toml": "a = = 1\n"}, keywords=("toml",)),
    Case("config_named_txt", ["render", "c.txt"], {"c.txt": toml()}, expect="ok"),
    # --- options and output locations
    Case("variant_option_bogus", ["--variant", "bogus", *R], {"c.toml": toml()}, keywords=("bogus",)),
    Case("variant_cuda_without_gpu", R, {"c.toml": toml(run={"variant": '"cuda_ad_mono"'})}, keywords=("cuda",)),
    Case("variant_env_bogus", R, {"c.toml": toml()}, env={"MINCAM_VARIANT": "bogus"}, keywords=("bogus",)),
    Case("out_is_a_file", [*R, "--out", "afile"], {"c.toml": toml(), "afile": "x"}, keywords=("afile",)),
    Case("out_parent_is_a_file", [*R, "--out", "afile/sub"], {"c.toml": toml(), "afile": "x"},
         keywords=("afile",)),
    Case("render_unknown_option", [*R, "--bogus"], {"c.toml": toml()}, keywords=("bogus",)),
    Case("render_missing_argument", ["render"], keywords=("config",)),
    Case("reproduce_unknown_experiment", ["reproduce", "bogus"], keywords=("bogus",)),
    Case("reproduce_negative_spacing", ["reproduce", "intrusion", "--quick", "--spacing-m", "-1"],
         keywords=("spacing",)),
    Case("reproduce_into_results_of_an_older_version", ["reproduce", "speed", "--quick", "--out", "rp"],
         {"rp/results.json": '{"speed": {"max_error_pct": 1.0}}'}, keywords=("older", "--overwrite")),
    Case("reproduce_into_another_setup", ["reproduce", "speed", "--quick", "--seed", "3", "--out", "rp"],
         pre=[["reproduce", "speed", "--quick", "--out", "rp"]], keywords=("seed",)),
    Case("reproduce_rerun_after_torn_results", ["reproduce", "speed", "--quick", "--out", "rp"],
         pre=[["reproduce", "speed", "--quick", "--out", "rp"]], between=_write("rp/results.json", b'{"spe'),
         keywords=("torn",)),
    Case("reproduce_out_is_a_file", ["reproduce", "intrusion", "--quick", "--out", "afile"], {"afile": "x"},
         keywords=("afile",)),
    Case("study_unknown", ["study", "bogus"], keywords=("bogus",)),
    Case("masks_export_unknown_ramp", ["masks", "export", "ramp:z", "--out", "x.png"], keywords=("ramp",)),
    Case("masks_export_out_parent_is_a_file", ["masks", "export", "ramp:x", "--out", "afile/x.png"],
         {"afile": "x"}, keywords=("afile",)),
    Case("masks_generate_resolution_zero", ["masks", "generate", "--resolution", "0", "--out", "lib"],
         keywords=("resolution",)),
    Case("masks_generate_out_is_a_file", ["masks", "generate", "--resolution", "8", "--out", "afile"],
         {"afile": "x"}, keywords=("afile",)),
    # --- reruns into the same output directory
    Case("rerun_other_seed", ["render", "c2.toml"], {"c.toml": toml(), "c2.toml": toml(run={"seed": "1"})},
         pre=[R], keywords=("seed",)),
    Case("rerun_changed_mask_phase", ["render", "c2.toml"],
         {"c.toml": toml(mixel(mask=SINE % "0.0"), mincam=CUSTOM),
          "c2.toml": toml(mixel(mask=SINE % "1.0"), mincam=CUSTOM)}, pre=[R], keywords=("mask",)),
    Case("rerun_same_config_with_target_noise", R, {"c.toml": toml(run={"target_rel_stderr": "0.05"})},
         pre=[R], expect="ok"),
    Case("rerun_after_torn_run_json", R, {"c.toml": toml()}, pre=[R],
         between=_both(_unlink("out/measurements.npz"), _write("out/measurements/run.json", b"")),
         keywords=("run.json",)),
    Case("rerun_after_empty_values_npy", R, {"c.toml": toml()}, pre=[R],
         between=_both(_unlink("out/measurements.npz"), _write("out/measurements/values.npy", b"")),
         keywords=("values.npy",)),
    Case("rerun_after_text_values_npy", R, {"c.toml": toml()}, pre=[R],
         between=_both(_unlink("out/measurements.npz"), _write("out/measurements/values.npy", b"hello\n")),
         keywords=("values.npy",)),
    Case("rerun_after_wrong_shape_values_npy", R, {"c.toml": toml()}, pre=[R],
         between=_both(_unlink("out/measurements.npz"), _write("out/measurements/values.npy", _npy(np.zeros((5, 5))))),
         keywords=("values.npy",)),
    Case("rerun_after_empty_measurements_npz", R, {"c.toml": toml()}, pre=[R],
         between=_write("out/measurements.npz", b""), expect="ok", notes=("measurements.npz is damaged",),
         outputs=("out/measurements.npz",)),
    Case("rerun_after_torn_measurements_npz", R, {"c.toml": toml()}, pre=[R], between=_cut("out/measurements.npz"),
         expect="ok", notes=("measurements.npz is damaged",), outputs=("out/measurements.npz",)),
    Case("rerun_after_the_response_maps_were_lost", R, {"c.toml": toml()}, pre=[R],
         between=_both(_unlink("out/response_maps.png"), _unlink("out/response_maps/response_x.exr")), expect="ok",
         notes=("response maps again",), outputs=("out/response_maps.png", "out/response_maps/response_x.exr")),
    # --- inputs a new user tried (outputs, print sheets, budgets, what runs)
    Case("config_with_utf8_bom", R, {"c.toml": b"\xef\xbb\xbf" + toml().encode()}, expect="ok"),
    Case("reproduce_bit_depth_1", ["reproduce", "intrusion", "--quick", "--bit-depth", "1"],
         keywords=("--bit-depth",)),
    Case("reproduce_negative_car_speed", ["reproduce", "intrusion", "--quick", "--config", "r.toml"],
         {"r.toml": "[intrusion]\nspeeds_m_s = [-0.3, 0.4]\n"}, keywords=("speeds_m_s[0]",)),
    Case("reproduce_boundary_far_away", ["reproduce", "intrusion", "--quick", "--config", "r.toml"],
         {"r.toml": "[intrusion]\nboundary_x_m = 5.0\n"}, keywords=("boundary_x_m",)),
    Case("reproduce_boundary_out_of_view", ["reproduce", "intrusion", "--quick", "--config", "r.toml"],
         {"r.toml": "[intrusion]\nboundary_x_m = 0.6\n"}, keywords=("boundary_x_m",)),
    Case("reproduce_mask_period_too_fine", ["reproduce", "speed", "--quick", "--config", "r.toml"],
         {"r.toml": "[speed]\nmask_period_m = 1e-7\n"}, keywords=("mask_period_m",)),
    Case("world_config_unknown_mover", R,
         {"c.toml": '[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.mover]]\nid = "car"\n'
                    'offsets_m = [[0, 0, 0]]\n',
          "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"}, keywords=("'car' is not a shape",)),
    Case("world_config_offsets_count", R,
         {"c.toml": '[world]\n[[world.object]]\nid = "a"\nmesh = "m.obj"\n[[world.object]]\nid = "b"\n'
                    'mesh = "m.obj"\n[[world.mover]]\nid = "a"\noffsets_m = [[0, 0, 0]]\n[[world.mover]]\n'
                    'id = "b"\noffsets_m = [[0, 0, 0], [0, 0, 1]]\n',
          "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"}, keywords=("frame counts differ",)),
    Case("world_config_missing_xml", R, {"c.toml": '[world]\nscene = "room.xml"\n[[world.mover]]\nid = "a"\n'
                                                   'offsets_m = [[0, 0, 0]]\n'}, keywords=("does not exist",)),
    Case("masks_export_levels_70000", ["masks", "export", "ramp:x", "--out", "m.png", "--levels", "70000"],
         keywords=("--levels",)),
    Case("masks_export_out_jpg", ["masks", "export", "ramp:x", "--out", "m.jpg"], keywords=(".png",)),
    Case("masks_export_writes_a_sheet", ["masks", "export", "ramp:x", "--out", "m.png"], expect="ok",
         outputs=("m.png", "m_sheet.png", "m_sheet.txt")),
    Case("masks_export_pdf_sheet", ["masks", "export", "ramp:x", "--out", "m.png", "--sheet", "s.pdf"],
         expect="ok", outputs=("s.pdf", "s.txt")),
    Case("sinusoid_direction_1e308", R, {"c.toml": toml(mixel(
        mask='{kind = "sinusoid", omega_rad_per_m = 3000.0, direction_deg = 1e308}'), mincam=CUSTOM)},
         keywords=("direction_deg",)),
    Case("file_mask_not_square", R, {"c.toml": toml(mixel(mask='"file:m.png"'), mincam=CUSTOM),
                                     "m.png": lambda p: _png_shape(p, 32, 64)}, keywords=("mask_size_m",)),
    Case("file_mask_not_square_with_its_size", R,
         {"c.toml": toml(mixel(mask='"file:m.png"', mask_size_m="[0.002, 0.001]"), mincam=CUSTOM),
          "m.png": lambda p: _png_shape(p, 32, 64)}, expect="ok"),
    Case("mixel_mask_size_three_numbers", R,
         {"c.toml": toml(mixel(mask_size_m="[0.002, 0.002, 0.002]"), mincam=CUSTOM)}, keywords=("mask_size_m",)),
    Case("file_mask_srgb", R, {"c.toml": toml(mixel(mask='"file:m.png"', mask_encoding='"srgb"'), mincam=CUSTOM),
                               "m.png": _png}, expect="ok"),
    Case("mask_encoding_unknown", R, {"c.toml": toml(mincam={"mask_encoding": '"gamma"'})},
         keywords=("mask_encoding",)),
    Case("samples_per_texel_rounded", R, {"c.toml": toml()}, expect="ok", notes=("traces 8",)),
    Case("render_writes_its_figures", R, {"c.toml": toml()}, expect="ok",
         outputs=("out/measurements.png", "out/response_maps.png", "out/measurements.csv")),
    Case("fast_spp_2_40", R, {"c.toml": toml(run={"solver": '"aperture"', "spp": str(2**40)})},
         keywords=("--time-limit-s",)),
    Case("render_warning_is_one_line", R, {"c.toml": toml(frames={"start_m": "[0.0, 0.3]", "end_m": "[0.0, 0.3]"})},
         expect="ok", notes=("warning: ",), clean_stderr=True),
    Case("progress_into_a_file_is_lines", R, {"c.toml": toml()}, expect="ok", notes=("frames",), clean_stderr=True),
    Case("masks_generate_on_a_full_disk", ["masks", "generate", "--resolution", "64", "--out", "lib"],
         fsize_limit=2000, keywords=("lib/",)),
    Case("masks_export_on_a_full_disk", ["masks", "export", "ramp:x", "--out", "m.png", "--dpi", "4800",
                                         "--size-m", "0.02", "--no-sheet"], fsize_limit=20000,
         keywords=("m.png", "m_sheet")),
    # masks and prints
    Case("masks_export_too_few_dots", ["masks", "export", "ramp:x", "--out", "m.png", "--size-m", "0.0001",
                                       "--dpi", "50"], keywords=("--dpi >= 2032",)),
    Case("masks_export_too_few_dots_at_any_dpi", ["masks", "export", "ramp:x", "--out", "m.png", "--size-m", "1e-5"],
         keywords=("no dpi up to 4800",)),
    Case("masks_export_sheet_too_large", ["masks", "export", "ramp:x", "--out", "m.png", "--size-m", "0.085",
                                          "--dpi", "2400"], keywords=("--dpi <= 1538",)),
    Case("masks_export_4800_dpi_sheet", ["masks", "export", "ramp:x", "--out", "m.png", "--dpi", "4800"],
         keywords=("--no-sheet",)),
    Case("masks_export_4800_dpi_no_sheet", ["masks", "export", "ramp:x", "--out", "m.png", "--dpi", "4800",
                                            "--no-sheet"], expect="ok", outputs=("m.png",)),
    Case("masks_export_sheet_and_no_sheet", ["masks", "export", "ramp:x", "--out", "m.png", "--sheet", "s.png",
                                             "--no-sheet"], keywords=("--no-sheet",)),
    Case("masks_export_srgb_generated_mask", ["masks", "export", "ramp:x", "--out", "m.png", "--srgb"], expect="ok",
         notes=("warning: --srgb does not apply",), outputs=("m.png", "m_sheet.png")),
    Case("masks_export_levels_with_halftone", ["masks", "export", "ramp:x", "--out", "m.png", "--halftone",
                                               "--levels", "4"], expect="ok",
         notes=("warning: --levels 4 does not apply with --halftone",), outputs=("m.png",)),
    Case("masks_export_exr_other_size", ["masks", "export", "file:m.exr", "--out", "m.png", "--size-m", "0.002"],
         {"m.exr": lambda p: _exr_mask(p, 0.004)}, expect="ok", notes=("records a 4 x 4 mm mask",),
         outputs=("m.png",)),
    Case("masks_export_srgb_exr", ["masks", "export", "file:m.exr", "--out", "m.png", "--srgb"],
         {"m.exr": lambda p: _exr_mask(p, 0.002)}, keywords=("sRGB",)),
    # worlds: a lamp and a card in cm (s.xml), its parameters, units and movers
    Case("world_parameter_unknown", R, {
        "s.xml": (_CARD_XML := '<scene version="3.0.0"><default name="lamp" value="3"/><shape type="rectangle" '
                  'id="lamp"><transform name="to_world"><scale x="55" y="31"/></transform><emitter type="area">'
                  '<spectrum name="radiance" value="$lamp"/></emitter></shape><shape type="rectangle" id="card">'
                  '<transform name="to_world"><scale x="5" y="2.5"/><rotate x="1" angle="180"/><translate z="25"/>'
                  '</transform></shape></scene>'),
        "c.toml": (_CARD_TOML := '[run]\nspp = 1024\nreplicates = 4\nout_dir = "out"\n[mincam]\n'
                   'position_m = [0.0, 0.0, 0.5]\n[world]\nscene = "s.xml"\nunit_m = 0.01\n')
        + '[world.parameters]\nlmp = 0\n[[world.mover]]\nid = "card"\noffsets_m = [[0, 0, 0]]\n'},
        keywords=("lmp",)),
    Case("world_mover_is_the_camera", R, {"s.xml": _CARD_XML, "c.toml": _CARD_TOML
                                          + '[world.camera]\nposition_m = [0, -1, 1]\nlook_at_m = [0, 0, 0]\n'
                                          '[[world.mover]]\nid = "ground_truth_camera"\noffsets_m = [[0, 0, 0]]\n'},
         keywords=("movable: card, lamp",)),
    Case("world_unit_m_zero", R, {"s.xml": _CARD_XML, "c.toml": _CARD_TOML.replace("unit_m = 0.01", "unit_m = 0")
                                  + '[[world.mover]]\nid = "card"\noffsets_m = [[0, 0, 0]]\n'}, keywords=("unit_m",)),
    Case("world_max_depth_one", R, {"s.xml": _CARD_XML,
                                    "c.toml": _CARD_TOML.replace("[run]\n", "[run]\nmax_depth = 1\n")
                                    + '[[world.mover]]\nid = "card"\noffsets_m = [[0, 0, 0]]\n'},
         keywords=("max_depth",)),
    Case("world_instances", R, {"s.xml": _CARD_XML.replace(
        "</scene>", '<shape type="shapegroup" id="g"><shape type="sphere"/></shape><shape type="instance" id="i">'
        '<ref id="g"/><transform name="to_world"><translate z="10"/></transform></shape></scene>'),
        "c.toml": _CARD_TOML + '[[world.mover]]\nid = "i"\noffsets_m = [[0, 0, 0], [0.02, 0, 0]]\n'},
        expect="ok", outputs=("out/measurements.csv",)),  # an instance moves (they were refused)
    Case("world_without_light", R, {"c.toml": '[run]\nspp = 1024\nreplicates = 4\n[world]\n[[world.object]]\n'
                                              'id = "toy"\nmesh = "m.obj"\n[[world.mover]]\nid = "toy"\n'
                                              'offsets_m = [[0, 0, 0]]\n',
                                    "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
         keywords=("no light",)),
    Case("world_card_and_lamp_move", R, {"s.xml": _CARD_XML, "c.toml": _CARD_TOML + '[world.parameters]\nlamp = 2.0\n'
                                         '[[world.mover]]\nid = "card"\noffsets_m = [[0, 0, 0], [0.05, 0, 0]]\n'
                                         '[[world.mover]]\nid = "lamp"\noffsets_m = [[0, 0, 0], [0, 0.02, 0]]\n'},
         expect="ok", outputs=("out/measurements.csv", "out/dP.png")),
    # studies (one block; study: a one-point study file, run: its command, big: a 60-point tracking grid,
    # about 30 h at the tracking target's typical 1800 s a point)
    *(lambda study, run, big: [
        Case("study_workers_zero", [*run, "--workers", "0"], {"s.toml": study}, keywords=("--workers",)),
        Case("study_workers_negative", [*run, "--workers", "-2"], {"s.toml": study}, keywords=("--workers",)),
        Case("study_workers_with_scheduler", [*run, "--workers", "2", "--scheduler", "tcp://127.0.0.1:9"],
             {"s.toml": study}, keywords=("--workers 2 does not apply with --scheduler",)),
        Case("study_scheduler_unreachable", [*run, "--scheduler", "tcp://127.0.0.1:9"], {"s.toml": study},
             keywords=("tcp://127.0.0.1:9 within 5 s",)),
        Case("study_scheduler_without_port", [*run, "--scheduler", "localhost"], {"s.toml": study},
             keywords=("--scheduler localhost",)),
        Case("study_scheduler_http_address", [*run, "--scheduler", "http://127.0.0.1:8786"], {"s.toml": study},
             keywords=("http://127.0.0.1:8786",)),
        Case("study_estimated_over_the_time_limit", ["study", "run", "big.toml"], {"big.toml": big},
             keywords=("--time-limit-s",)),
        Case("study_time_limit_zero", [*run, "--time-limit-s", "0"], {"s.toml": study}, keywords=("--time-limit-s",)),
        Case("study_store_lacks_a_variable", [*run, "--out", "so"], {"s.toml": study}, pre=[[*run, "--out", "so"]],
             between=lambda tmp: [f.unlink() for f in (tmp / "so/results.zarr/avg_after_pct_stderr").iterdir()],
             keywords=("lacks variable(s) avg_after_pct_stderr",)),
        Case("study_store_lacks_a_coordinate", [*run, "--out", "so"], {"s.toml": study},
             pre=[[*run, "--out", "so"]],
             between=lambda tmp: [f.unlink() for f in (tmp / "so/results.zarr/depth_m").iterdir()],
             keywords=("lacks coordinate(s) depth_m",)),
        Case("study_workers_above_the_cores", [*run, "--workers", "99", "--out", "so"], {"s.toml": study},
             expect="ok", notes=("warning: --workers 99 is more than the",), outputs=("so/study.png",)),
    ])('[study]\nexperiment = "spacing"\nreplicates = 1\n[grid]\ndepth_m = [0.5]\n[metrics]\n'
       'keep = ["avg_after_pct"]\n', ["study", "run", "s.toml", "--quick"],
       '[study]\nexperiment = "tracking"\n[grid]\nspacing_m = ['
       + ", ".join(f"{0.001 * i:.3f}" for i in range(1, 61)) + "]\n"),
    # guards: sizes and times refused with the estimate, budgets refused as in Python, 30+ bad values of each
    # section named by their key, and keys or options that do not apply said in one warning line
    Case("guard_frames_and_texels_over_the_time_limit", R,
         {"c.toml": toml(frames={"n": "10000000"}, screen={"resolution": "[4096, 4096]"})},
         keywords=("--time-limit-s",)),
    Case("guard_grid_sweep_frames", R, {"c.toml": toml(frames={"kind": '"grid_sweep"', "nx": "100000", "ny": "100000",
                                                              "n": None})}, keywords=("nx x ny",)),
    Case("guard_mixels_over_the_free_memory", [*R, "--time-limit-s", "1e9"],
         {"c.toml": toml("".join(mixel(position_m=f"[{0.0025 * (i % 20):.4f}, {0.0025 * (i // 20):.4f}, 0]",
                                       name=f'"m{i}"') for i in range(400)),
                         mincam=CUSTOM, screen={"resolution": "[4096, 4096]"})}, keywords=("GiB",)),
    Case("guard_world_spp_over_the_time_limit", R,
         {"c.toml": '[run]\nspp = 262144\n[world]\nframe_rate_hz = 100000.0\n[[world.object]]\nid = "toy"\n'
                    'mesh = "m.obj"\n[[world.mover]]\nid = "toy"\ntimes_s = [0.0, 1.2]\n'
                    'keyframes_m = [[0, 0, 0], [0.2, 0, 0]]\n', "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
         keywords=("--time-limit-s",)),
    Case("guard_world_camera_over_the_free_memory", [*R, "--time-limit-s", "1e9"],
         {"c.toml": '[world]\nframe_rate_hz = 82.5\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n'
                    '[[world.mover]]\nid = "toy"\ntimes_s = [0.0, 1.2]\nkeyframes_m = [[0, 0, 0], [0.2, 0, 0]]\n'
                    '[world.camera]\nposition_m = [0, 0, 1]\nlook_at_m = [0, 0, 0]\nwidth_px = 8192\n'
                    'height_px = 8192\nspp = 1\n', "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
         keywords=("GiB",)),
    Case("guard_check_says_over_the_limit", [*R, "--check", "--time-limit-s", "10"],
         {"c.toml": toml(run={"solver": '"aperture"', "spp": str(2**30)})}, expect="ok"),
    Case("guard_samples_per_texel_below_default_replicates", R, {"c.toml": toml(run={"samples_per_texel": "4"})},
         keywords=("samples_per_texel",)),
    Case("guard_spp_below_replicates", R, {"c.toml": toml(run={"solver": '"aperture"', "spp": "3"})},
         keywords=("spp",)),
    Case("guard_replicates_5000", R, {"c.toml": toml(run={"replicates": "5000"})}, keywords=("replicates",)),
    Case("guard_samples_per_texel_one", R, {"c.toml": toml(run={"samples_per_texel": "1"})},
         keywords=("samples_per_texel",)),
    Case("guard_target_1_5", R, {"c.toml": toml(run={"target_rel_stderr": "1.5"})}, keywords=("target_rel_stderr",)),
    Case("guard_seed_fractional", R, {"c.toml": toml(run={"seed": "1.5"})}, keywords=("seed",)),
    Case("guard_solver_capitalised", R, {"c.toml": toml(run={"solver": '"Aperture"'})}, keywords=("solver",)),
    Case("guard_variant_llvm", R, {"c.toml": toml(run={"variant": '"llvm"'})}, keywords=("variant",)),
    Case("guard_out_dir_list", R, {"c.toml": toml(run={"out_dir": '["a"]'})}, keywords=("out_dir",)),
    Case("guard_frames_kind_video", R, {"c.toml": toml(frames={"kind": '"video"'})}, keywords=("kind",)),
    Case("guard_frames_n_zero", R, {"c.toml": toml(frames={"n": "0"})}, keywords=("[frames] n",)),
    Case("guard_square_negative", R, {"c.toml": toml(frames={"square_m": "-1.0"})}, keywords=("square_m",)),
    Case("guard_radiance_inf", R, {"c.toml": toml(frames={"radiance_w_m2_sr": "inf"})},
         keywords=("radiance_w_m2_sr",)),
    Case("guard_start_three_numbers", R, {"c.toml": toml(frames={"start_m": "[0, 0, 0]"})}, keywords=("start_m",)),
    Case("guard_background_negative", R, {"c.toml": toml(frames={"background_w_m2_sr": "-1.0"})},
         keywords=("background_w_m2_sr",)),
    Case("guard_diagonal_zero", R, {"c.toml": toml(screen={"diagonal_in": "0"})}, keywords=("diagonal_in",)),
    Case("guard_aspect_zero", R, {"c.toml": toml(screen={"aspect": "[16, 0]"})}, keywords=("aspect",)),
    Case("guard_distance_negative", R, {"c.toml": toml(screen={"distance_m": "-1.0"})}, keywords=("distance_m",)),
    Case("guard_layout_triangle", R, {"c.toml": toml(mincam={"layout": '"triangle"'})}, keywords=("layout",)),
    Case("guard_spacing_negative", R, {"c.toml": toml(mincam={"spacing_m": "-0.1"})}, keywords=("spacing_m",)),
    Case("guard_d_f_zero", R, {"c.toml": toml(mincam={"d_f_m": "0"})}, keywords=("d_f_m",)),
    Case("guard_detector_larger_than_mask", R, {"c.toml": toml(mincam={"detector_size_m": "1.0"})},
         keywords=("detector_size_m",)),
    Case("guard_wavelength_in_mm", R, {"c.toml": toml(mincam={"optics": '"wave"', "wavelengths_m": "[1e-3]"})},
         keywords=("wavelengths_m",)),
    Case("guard_mask_resolution_zero", R, {"c.toml": toml(mincam={"mask_resolution": "0"})},
         keywords=("mask_resolution",)),
    Case("guard_spacing_with_a_unit", R, {"c.toml": toml(mincam={"spacing_m": '"3cm"'})}, keywords=("spacing_m",)),
    Case("guard_mixel_optics_unknown", R, {"c.toml": toml(mixel(optics='"quantum"'), mincam=CUSTOM)},
         keywords=("optics",)),
    Case("guard_mixel_negative_omega", R,
         {"c.toml": toml(mixel(mask='{kind = "sinusoid", omega_rad_per_m = -1.0}'), mincam=CUSTOM)},
         keywords=("omega_rad_per_m",)),
    Case("guard_mixel_d_f_negative", R, {"c.toml": toml(mixel(d_f_m="-1.0"), mincam=CUSTOM)}, keywords=("d_f_m",)),
    Case("guard_mixels_overlapping", R,
         {"c.toml": toml(mixel(name='"a"') + mixel(name='"b"'), mincam=CUSTOM)}, keywords=("position_m",)),
    Case("guard_mixel_forward_1e308", R, {"c.toml": toml(mixel(forward="[1e308, 1e308, 0]"), mincam=CUSTOM)},
         keywords=("forward",)),
    Case("guard_world_frame_rate_zero", R,
         {"c.toml": '[world]\nframe_rate_hz = 0\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.mover]]\n'
                    'id = "toy"\noffsets_m = [[0, 0, 0]]\n', "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
         keywords=("frame_rate_hz",)),
    Case("guard_world_up_x", R,
         {"c.toml": '[world]\nup = "x"\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.mover]]\nid = "toy"\n'
                    'offsets_m = [[0, 0, 0]]\n', "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
         keywords=("[world] up",)),
    Case("guard_world_background_none", R,
         {"c.toml": '[world]\nbackground = "none"\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.mover]]\n'
                    'id = "toy"\noffsets_m = [[0, 0, 0]]\n', "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
         keywords=("background",)),
    Case("guard_world_scene_integer", R,
         {"c.toml": '[world]\nscene = 5\n[[world.mover]]\nid = "toy"\noffsets_m = [[0, 0, 0]]\n'},
         keywords=("scene",)),
    Case("guard_mover_offsets_two_numbers", R,
         {"c.toml": '[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.mover]]\nid = "toy"\n'
                    'offsets_m = [[0, 0]]\n', "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
         keywords=("offsets_m",)),
    Case("guard_mover_times_decreasing", R,
         {"c.toml": '[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.mover]]\nid = "toy"\n'
                    'times_s = [1.0, 0.0]\nkeyframes_m = [[0, 0, 0], [0.1, 0, 0]]\n',
          "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"}, keywords=("times_s",)),
    Case("guard_mover_csv_missing", R,
         {"c.toml": '[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.mover]]\nid = "toy"\n'
                    'csv = "path.csv"\n', "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"}, keywords=("path.csv",)),
    Case("guard_mover_rotations_count", R,
         {"c.toml": '[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.mover]]\nid = "toy"\n'
                    'offsets_m = [[0, 0, 0], [0.1, 0, 0]]\nrotations_deg = [[0, 0, 0]]\n',
          "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"}, keywords=("rotations_deg",)),
    Case("guard_mover_offsets_nan", R,
         {"c.toml": '[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.mover]]\nid = "toy"\n'
                    'offsets_m = [[nan, 0, 0]]\n', "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
         keywords=("offsets_m",)),
    Case("guard_mover_id_with_a_dot", R,
         {"c.toml": '[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.mover]]\nid = "a.b"\n'
                    'offsets_m = [[0, 0, 0]]\n', "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
         keywords=("id",)),
    Case("guard_world_max_depth_one", R,
         {"c.toml": '[run]\nmax_depth = 1\n[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.mover]]\n'
                    'id = "toy"\noffsets_m = [[0, 0, 0]]\n', "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
         keywords=("max_depth",)),
    Case("guard_world_samples_per_texel", R,
         {"c.toml": '[run]\nsamples_per_texel = 64\n[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n'
                    '[[world.mover]]\nid = "toy"\noffsets_m = [[0, 0, 0]]\n',
          "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"}, keywords=("samples_per_texel",)),
    Case("guard_world_replicates_one", R,
         {"c.toml": '[run]\nreplicates = 1\n[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.mover]]\n'
                    'id = "toy"\noffsets_m = [[0, 0, 0]]\n', "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
         keywords=("replicates",)),
    Case("guard_object_scale_zero", R,
         {"c.toml": '[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\nscale = 0\n[[world.mover]]\nid = "toy"\n'
                    'offsets_m = [[0, 0, 0]]\n', "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
         keywords=("scale",)),
    Case("guard_object_albedo_two", R,
         {"c.toml": '[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\nalbedo = 2.0\n[[world.mover]]\n'
                    'id = "toy"\noffsets_m = [[0, 0, 0]]\n', "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
         keywords=("albedo",)),
    Case("guard_object_mesh_garbage", R,
         {"c.toml": '[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.mover]]\nid = "toy"\n'
                    'offsets_m = [[0, 0, 0]]\n', "m.obj": "this is not a mesh\n"}, keywords=("m.obj",)),
    Case("guard_camera_fov_180", R,
         {"c.toml": '[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.mover]]\nid = "toy"\n'
                    'offsets_m = [[0, 0, 0]]\n[world.camera]\nposition_m = [0, 0, 1]\nlook_at_m = [0, 0, 0]\n'
                    'fov_deg = 180.0\n', "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"}, keywords=("fov_deg",)),
    Case("guard_camera_up_along_its_view", R,  # named Pose's up and numpy reprs (np.float64(0.0), ...)
         {"c.toml": '[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.mover]]\nid = "toy"\n'
                    'offsets_m = [[0, 0, 0]]\n[world.camera]\nposition_m = [0, 0, 1]\nlook_at_m = [0, 0, 0]\n'
                    'up = [0, 0, 1]\n', "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
         keywords=("[world.camera]: up = [0.0, 0.0, 1.0] is parallel",)),
    Case("guard_light_beyond_a_float", R,  # was refused as "lamp.emitter.radiance.value = [inf]"
         {"c.toml": '[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.light]]\nid = "lamp"\n'
                    'kind = "area"\nposition_m = [0, 0, 1]\nradiance_w_m2_sr = 1e300\n[[world.mover]]\n'
                    'id = "toy"\noffsets_m = [[0, 0, 0]]\n', "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
         keywords=("radiance_w_m2_sr must be a number <= 1e+30",)),
    Case("guard_world_out_dir_empty", R,  # wrote the outputs beside the config
         {"c.toml": '[run]\nout_dir = ""\n[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n'
                    '[[world.mover]]\nid = "toy"\noffsets_m = [[0, 0, 0]]\n',
          "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"}, keywords=("[run] out_dir must not be empty",)),
    Case("guard_world_mesh_without_triangles", R,  # a Dr.Jit gather error (traceback) with face normals
         {"c.toml": '[world]\nscene = "s.xml"\n[[world.mover]]\nid = "toy"\noffsets_m = [[0, 0, 0]]\n',
          "s.xml": '<scene version="3.0.0"><shape type="obj" id="toy"><string name="filename" value="m.obj"/>'
                   '<boolean name="face_normals" value="true"/></shape><emitter type="constant"/></scene>',
          "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\n"}, keywords=("a mesh without a single triangle",)),
    Case("export_maps_psf_grid_finer_than_the_texels", ["export-maps", "c.toml", "--out", "em", "--psf-grid",
                                                        "20000", "20000"],  # killed at 24 GB of memory
         {"c.toml": toml()}, keywords=("--psf-grid",)),
    Case("guard_warns_spp_with_response_map", [*R, "--check"], {"c.toml": toml(run={"spp": "1024"})}, expect="ok",
         notes=("warning: [run] spp is ignored",)),
    Case("guard_warns_grid_keys_in_a_line_sweep", [*R, "--check"], {"c.toml": toml(frames={"nx": "4"})},
         expect="ok", notes=("warning: [frames] nx is ignored",)),
    Case("guard_warns_wavelengths_without_wave_optics", [*R, "--check"],
         {"c.toml": toml(mincam={"wavelengths_m": "[600e-9]"})}, expect="ok",
         notes=("warning: [mincam] wavelengths_m is ignored",)),
    Case("guard_warns_world_light_keys_of_another_kind", [*R, "--check"],
         {"c.toml": '[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.light]]\nid = "bulb"\n'
                    'kind = "point"\nsize_m = [1.0, 1.0]\n[[world.mover]]\nid = "toy"\noffsets_m = [[0, 0, 0]]\n',
          "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"}, expect="ok", notes=("size_m is ignored",)),
    Case("guard_warns_times_with_offsets", [*R, "--check"],
         {"c.toml": '[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.mover]]\nid = "toy"\n'
                    'offsets_m = [[0, 0, 0]]\ntimes_s = [0.0, 1.0]\n', "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
         expect="ok", notes=("times_s is ignored",)),
]

MESH = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
WORLD = '[world]\n[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.mover]]\nid = "toy"\n'
RT = ["reproduce", "tracking", "--quick", "--config", "r.toml"]

#: Values a user types that reached a deep ValueError (a traceback) or ran silently: refused at the boundary.
BOUNDARY = [
    Case("reproduce_unknown_toy", RT, {"r.toml": '[tracking]\ntoys = ["dragon"]\n'}, keywords=("[tracking] toys",)),
    Case("reproduce_detector_larger_than_mask", RT, {"r.toml": "[setup]\ndetector_size_m = 0.003\n"},
         keywords=("[setup] detector_size_m",)),
    Case("reproduce_screen_resolution_zero", RT, {"r.toml": "[setup]\nscreen_resolution = [0, 0]\n"},
         keywords=("[setup] screen_resolution",)),
    Case("reproduce_mask_period_named", ["reproduce", "speed", "--quick", "--config", "r.toml"],
         {"r.toml": "[speed]\nmask_period_m = 1e-7\n"}, keywords=("mask_period_m",)),
    # each was a ValueError traceback after the scene was built (some after rendering), or named a derived value
    Case("reproduce_mincam_above_the_lamp", ["reproduce", "intrusion", "--quick", "--depth-m", "1000"],
         keywords=("--depth-m",)),
    Case("reproduce_table_unlit", RT, {"r.toml": "[setup]\ntable_light_radiance_w_m2_sr = 0\n"},
         keywords=("[setup] table_light_radiance_w_m2_sr",)),
    Case("reproduce_race_starting_at_the_line", ["reproduce", "intrusion", "--quick", "--config", "r.toml"],
         {"r.toml": "[intrusion]\nstart_distance_m = 0.0\noverrun_m = 0.0\n"}, keywords=("start_distance_m",)),
    Case("reproduce_one_frame_per_toy", RT, {"r.toml": "[tracking]\nframes_per_toy = 1\n"},
         keywords=("frames_per_toy >= 2",)),
    Case("reproduce_toy_steps_longer_than_its_area", RT, {"r.toml": "[tracking]\nframe_interval_s = 100\n"},
         keywords=("[tracking] toy_speed_m_s x frame_interval_s",)),
    Case("reproduce_toy_larger_than_the_field", RT, {"r.toml": "[tracking]\ntoy_size_m = 1.0\n"},
         keywords=("toy_size_m",)),
    Case("reproduce_spp_below_the_replicates", ["reproduce", "intrusion", "--quick", "--config", "r.toml"],
         {"r.toml": "[setup]\nspp = 255\n"}, keywords=("[setup] spp = 255",)),
    Case("reproduce_display_jitter_beyond_a_reading", ["reproduce", "speed", "--quick", "--config", "r.toml"],
         {"r.toml": "[speed]\ndisplay_jitter_s = 10\n"}, keywords=("jitter_s",)),
    Case("masks_export_print_grid_too_large", ["masks", "export", "ramp:x", "--out", "m.png", "--size-m", "1",
                                               "--dpi", "2400"], keywords=("--size-m",)),
    Case("render_replicates_above_samples_per_texel", R,
         {"c.toml": toml(run={"replicates": "64", "samples_per_texel": "16"})}, keywords=("samples_per_texel",)),
    Case("render_old_form_key", R, {"c.toml": toml(run={"form": '"fast"'})}, keywords=('solver = "aperture"',)),
    Case("render_world_solver_in_a_display_file", R, {"c.toml": toml(run={"solver": '"stratified_change"'})},
         keywords=("display",)),
    Case("world_old_estimator_key", R, {"c.toml": '[run]\nestimator = "plain"\n' + WORLD + "offsets_m = [[0, 0, 0]]\n",
                                        "m.obj": MESH}, keywords=('solver = "plain_change"',)),
    Case("world_absolute_solver", R, {"c.toml": '[run]\nsolver = "aperture"\n' + WORLD + "offsets_m = [[0, 0, 0]]\n",
                                      "m.obj": MESH}, keywords=("absolute P",)),
    Case("world_spp_2_40", R, {"c.toml": f"[run]\nspp = {2**40}\n" + WORLD + "offsets_m = [[0, 0, 0]]\n",
                               "m.obj": MESH}, keywords=("--time-limit-s",)),
    Case("world_frame_rate_1e9_keyframes", R,
         {"c.toml": WORLD.replace("[world]\n", "[world]\nframe_rate_hz = 1e9\n")
          + "times_s = [0.0, 1.2]\nkeyframes_m = [[0, 0, 0], [0.2, 0, 0]]\n", "m.obj": MESH},
         keywords=("frame_rate_hz",)),
    Case("design_config_key_outside_tracking", ["design", "tracking", "--config", "d.toml"],
         {"d.toml": "dpi = 300.0\n"}, keywords=("[tracking]",)),
    Case("design_config_unknown_field", ["design", "tracking", "--config", "d.toml"],
         {"d.toml": "[tracking]\ndpii = 300.0\n"}, keywords=("dpii",)),
    Case("design_config_not_toml", ["design", "tracking", "--config", "d.toml"], {"d.toml": "dpi = = 3\n"},
         keywords=("not valid TOML",)),
    Case("design_dpi_whose_sheet_is_too_large", ["design", "tracking", "--quick", "--dpi", "4800", "--out", "d"],
         keywords=("print sheet", "dpi")),
    Case("empty_config_says_it_is_the_default_job", ["render", "c.toml", "--check"], {"c.toml": ""}, expect="ok",
         notes=("default job",)),
]
CASES += BOUNDARY

_PROGRESS = re.compile(r"(\d+%\||/s\]|s/\w+\]|\d+\w* \[\d+:\d+)")  # any tqdm bar: "42%|", "it/s]", "3chunk [00:01"


def _prepare(case: Case, tmp: Path) -> None:
    for rel, data in case.files.items():
        path = tmp / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        if callable(data):
            data(path)
        elif isinstance(data, bytes):
            path.write_bytes(data)
        else:
            path.write_text(data)


def _message_lines(stderr: str) -> list[str]:
    """Lines of stderr that are not progress bars."""
    parts = re.split(r"[\r\n]+", stderr)
    return [p.strip() for p in parts if p.strip() and not _PROGRESS.search(p)]


_SOURCE = re.compile(r"\.py:\d+:|^\s{2,}\S.*\(.*\)\s*$", re.M)  # a warning's "file.py:12:" or its code line


def classify(case: Case, rc: int, stderr: str, tmp: Path | None = None) -> str:
    """"ok" (the expected outcome), or "traceback", "silent", "unclear", "failed" (an ok case that failed).

    An "ok" case that does not say its ``notes`` or lacks one of its ``outputs`` is "silent"; one whose stderr
    should be clean but holds carriage returns or source code is "unclear". An error case must leave no empty
    file behind (a half-written output: "unclear")."""
    if "Traceback" in stderr:
        return "traceback"
    if case.clean_stderr and ("\r" in stderr or _SOURCE.search(stderr)):
        return "unclear"
    if case.expect == "ok":
        if rc != 0:
            return "failed"
        if not all(n.lower() in stderr.lower() for n in case.notes):
            return "silent"
        if tmp is not None and not all((tmp / o).is_file() and (tmp / o).stat().st_size > 0 for o in case.outputs):
            return "silent"
        return "ok"
    if rc == 0:
        return "silent"
    if tmp is not None and case.fsize_limit is not None and any(
            p.is_file() and p.stat().st_size == 0 for p in tmp.rglob("*")):
        return "unclear"
    lines = _message_lines(stderr)
    clear = (rc == 2 and len(lines) == 1 and lines[0].startswith("error: ")
             and (not case.keywords or any(k.lower() in lines[0].lower() for k in case.keywords)))
    return "ok" if clear else "unclear"


def run_case(case: Case, tmp: Path, pythonpath: Path | None = None, timeout: float = 300) -> tuple[str, int, str]:
    """Run ``case`` through ``python -m mincam_sim.cli`` in ``tmp``; return (verdict, rc, stderr)."""
    env = {**os.environ, **case.env, "PYTHONPATH": str(pythonpath or ROOT), "COLUMNS": "200"}
    env.pop("MINCAM_DEBUG", None)
    if "MINCAM_VARIANT" not in case.env:
        env.pop("MINCAM_VARIANT", None)
    _prepare(case, tmp)
    cmd = [sys.executable, "-m", "mincam_sim.cli"]
    for argv in case.pre:
        subprocess.run([*cmd, *argv], cwd=tmp, env=env, capture_output=True, timeout=timeout, check=False)
    if case.between is not None:
        case.between(tmp)
    limit = None
    if case.fsize_limit is not None:
        import resource

        def limit() -> None:  # writes past the limit fail with EFBIG, as on a full disk (Python ignores SIGXFSZ)
            resource.setrlimit(resource.RLIMIT_FSIZE, (case.fsize_limit, case.fsize_limit))

    proc = subprocess.run([*cmd, *case.argv], cwd=tmp, env=env, capture_output=True, timeout=timeout,
                          check=False, preexec_fn=limit)
    stderr = proc.stderr.decode("utf-8", errors="replace")  # bytes: text mode would turn "\r" into "\n"
    return classify(case, proc.returncode, stderr, tmp), proc.returncode, stderr


# ---------------------------------------------------------------------------------------------------- tests


def _cli(argv: list[str], cwd: Path):
    from typer.testing import CliRunner

    from mincam_sim.cli import app

    old = Path.cwd()
    os.chdir(cwd)
    try:
        return CliRunner().invoke(app, argv)
    finally:
        os.chdir(old)


FAST = [c for c in CASES if not c.pre and c.argv[0] in ("render", "--variant", "study", "masks")
        and "reproduce" not in c.argv and not c.env and c.expect == "error" and c.fsize_limit is None
        and c.name not in ("variant_cuda_without_gpu", "masks_generate_out_is_a_file")]


def _stderr(result) -> str:
    try:
        return result.stderr
    except ValueError:  # older click: stderr mixed into output
        return result.output


def _assert_one_clear_answer(case, tmp_path) -> None:
    _prepare(case, tmp_path)
    result = _cli(case.argv, tmp_path)
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    verdict = classify(case, result.exit_code, _stderr(result))
    assert verdict == "ok", f"{case.name}: rc {result.exit_code}, stderr {_stderr(result)!r}"


@pytest.mark.parametrize("case", FAST, ids=lambda c: c.name)
def test_bad_input_is_one_line_in_process(case, tmp_path):
    _assert_one_clear_answer(case, tmp_path)


@pytest.mark.parametrize("case", BOUNDARY, ids=lambda c: c.name)
def test_a_value_that_reached_deep_code_is_refused_at_the_boundary(case, tmp_path):
    """Each is refused (or said) before anything runs: one ``error:`` line, exit code 2, no traceback."""
    _assert_one_clear_answer(case, tmp_path)


def test_debug_flag_shows_the_traceback(tmp_path):
    (tmp_path / "c.toml").write_text(toml(run={"seed": "true"}))
    result = _cli(["--debug", "render", "c.toml"], tmp_path)
    from mincam_sim.errors import ConfigError

    assert isinstance(result.exception, ConfigError)


def test_help_keeps_units(tmp_path):
    result = _cli(["reproduce", "--help"], tmp_path)
    assert result.exit_code == 0
    assert "[m]" in result.output


def test_render_check_validates_without_rendering(tmp_path):
    (tmp_path / "c.toml").write_text(toml())
    result = _cli(["render", "c.toml", "--check"], tmp_path)
    assert result.exit_code == 0, _stderr(result)
    for word in ("mixel x", "screen:", "frames: 2", "solver: response_map", "out dir:"):
        assert word in result.output
    assert not (tmp_path / "out").exists()


def test_quiet_silences_progress(tmp_path):
    (tmp_path / "c.toml").write_text(toml())
    loud = _cli(["render", "c.toml"], tmp_path)
    quiet = _cli(["--quiet", "render", "c.toml", "--overwrite"], tmp_path)
    assert loud.exit_code == 0 and quiet.exit_code == 0
    assert "frames" in _stderr(loud)  # the bar's label
    # --quiet keeps only the one note that the sample count traced is not the one asked (16 -> 8 per texel)
    assert [line for line in _stderr(quiet).splitlines() if line.strip()] == [
        "mincam-sim: [run] samples_per_texel = 16 traces 8 samples per texel (8 replicates x 1x1 strata, rounded "
        "down); ask 8 or 32 to get exactly what runs"]


@pytest.mark.parametrize("name", ["seed_boolean", "npy_zero_bytes", "variant_cuda_without_gpu", "out_is_a_file"])
def test_bad_input_is_one_line_in_a_real_process(name, tmp_path):
    case = next(c for c in CASES if c.name == name)
    verdict, rc, stderr = run_case(case, tmp_path)
    if name == "variant_cuda_without_gpu" and rc == 0:
        pytest.skip("this machine has a CUDA GPU")
    assert verdict == "ok", f"rc {rc}, stderr {stderr!r}"
    assert rc == 2 and "Traceback" not in stderr


def test_real_executable_exit_code(tmp_path):
    exe = Path(sys.executable).with_name("mincam-sim")
    if not exe.exists():
        pytest.skip("mincam-sim console script not installed beside this Python")
    (tmp_path / "c.toml").write_text(toml(screen={"resolution": "[32.5, 18]"}))
    proc = subprocess.run([str(exe), "render", "c.toml"], cwd=tmp_path, capture_output=True, text=True, check=False)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith("error: [screen] resolution")



def _truncated_exr(path: Path) -> None:
    """The first half of a valid EXR mask (its header whole, its pixel data cut short)."""
    from mincam_sim.masks import ramp, save_exr

    save_exr(ramp("x", 256, width_m=0.002), path)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def test_a_truncated_exr_mask_is_our_one_line_and_nothing_of_openexr(tmp_path, capfd):
    """OpenEXR printed its own lines about the damaged file (``m.exr: (EXR_ERR_BAD_CHUNK_LEADER) ...`` on the
    standard error, ``Warning: Exception raised reading pixel data ...`` on the standard output) before our one
    ``error:`` line. They are written by C++ straight to the file descriptors: capfd sees them, CliRunner not."""
    import ctypes

    _truncated_exr(tmp_path / "m.exr")
    (tmp_path / "c.toml").write_text(toml(mixel(mask='"file:m.exr"'), mincam=CUSTOM))
    capfd.readouterr()
    for argv in (["masks", "export", "file:m.exr", "--out", "m.png"], ["render", "c.toml", "--check"]):
        result = _cli(argv, tmp_path)
        ctypes.CDLL(None).fflush(None)  # what C++ buffered on the standard output
        fd_out, fd_err = capfd.readouterr()
        lines = [line for line in _stderr(result).splitlines() if line.strip()]
        assert result.exit_code == 2 and len(lines) == 1, (argv, _stderr(result))
        assert lines[0].startswith("error: ") and "m.exr" in lines[0] and "truncated or corrupt" in lines[0]
        assert (fd_out, fd_err) == ("", "") and "Warning" not in result.output, (argv, result.output)
    assert not (tmp_path / "m.png").exists()


def test_ctrl_c_while_typer_builds_the_commands_is_one_line_and_130(monkeypatch, capsys):
    """The window after the imports and before a command runs (typer reading every command's signature): a
    Ctrl-C there is one line and exit code 130 too, not a traceback."""
    import typer.main

    from mincam_sim import cli

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(typer.main, "get_command", interrupted)
    try:
        cli.main(["render", "--help"])
    except SystemExit as exit_info:
        assert exit_info.code == 130
    except KeyboardInterrupt:
        pytest.fail("a Ctrl-C while typer builds the commands escaped as a KeyboardInterrupt (a traceback)")
    else:
        pytest.fail("main returned after a Ctrl-C")
    stderr = capsys.readouterr().err
    assert stderr == cli.INTERRUPTED_WHILE_STARTING + "\n"


@pytest.mark.parametrize("delay_s", [0.0, 0.1])
def test_ctrl_c_while_the_package_imports_is_one_line_and_130(delay_s, tmp_path):
    """A Ctrl-C in the first second (Python still importing numpy, scipy, typer, or typer building the commands)
    ends like any interrupt: exit code 130 and one line, no traceback."""
    import signal
    import time

    exe = Path(sys.executable).with_name("mincam-sim")
    if not exe.exists():
        pytest.skip("mincam-sim console script not installed beside this Python")
    proc = subprocess.Popen([str(exe), "render", "--help"], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    # numpy mapped into the process: the package is importing, past the console entry's handler (a Ctrl-C during
    # Python's own start-up, before any of this project's code runs, is Python's to answer; a fixed delay hit
    # that window on a loaded machine)
    maps = Path(f"/proc/{proc.pid}/maps")
    deadline = time.monotonic() + 60
    while maps.exists() and time.monotonic() < deadline and proc.poll() is None:
        try:
            if "_multiarray_umath" in maps.read_text():
                break
        except OSError:
            break
        time.sleep(0.005)
    time.sleep(delay_s)
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr and stderr.count("\n") == 1 and stderr.startswith("error: interrupted")


def test_an_error_after_a_ctrl_c_is_reported_as_the_interrupt(monkeypatch, capsys):
    """A Ctrl-C that lands inside an import can leave a module half-imported; its next use fails with another
    error (scipy.ndimage: "NameError: name '_ndimage_api' is not defined", seen once in 30 Ctrl-Cs of a study
    run). After a Ctrl-C such an error is the interrupt's: one line and exit code 130, no traceback."""
    import mincam_sim.studies.cli as study_cli
    from mincam_sim import cli, interrupts

    def half_imported(*args, **kwargs):
        interrupts.note()  # what the CLI's SIGINT handler counts
        raise NameError("name '_ndimage_api' is not defined")

    monkeypatch.setattr(study_cli, "run_study_command", half_imported)
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["study", "run", "any.toml"])
    assert exit_info.value.code == 130
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: interrupted") and "NameError" not in err


def test_the_same_error_without_a_ctrl_c_is_still_a_bugs_traceback(monkeypatch):
    import mincam_sim.studies.cli as study_cli
    from mincam_sim import cli

    def broken(*args, **kwargs):
        raise NameError("name '_ndimage_api' is not defined")

    monkeypatch.setattr(study_cli, "run_study_command", broken)
    with pytest.raises(NameError):
        cli.main(["study", "run", "any.toml"])


SWALLOWING_CLI = """
import os, signal, time
try:  # an import guard that catches BaseException swallows the Ctrl-C
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(5)
except BaseException:
    pass

def main():
    print("the command ran")
"""


def test_a_ctrl_c_swallowed_while_the_package_imports_still_stops_the_command(tmp_path):
    """The console entry records a SIGINT that arrives while the CLI is imported: if an import guard swallowed
    it, nothing runs (one line, exit code 130), as when the import fails because of it."""
    fake = tmp_path / "mincam_sim"
    fake.mkdir()
    (fake / "__init__.py").write_text("")
    (fake / "cli.py").write_text(SWALLOWING_CLI)
    env = {**os.environ, "PYTHONPATH": f"{tmp_path}{os.pathsep}{ROOT}"}
    proc = subprocess.run([sys.executable, "-c", "import mincam_sim_console; mincam_sim_console.main()"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60, check=False)
    assert proc.returncode == 130, proc.stderr
    assert "the command ran" not in proc.stdout
    assert proc.stderr == "error: interrupted while starting; nothing was run\n"


@pytest.mark.slow
@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
def test_every_case(case, tmp_path):
    verdict, rc, stderr = run_case(case, tmp_path)
    if case.name == "variant_cuda_without_gpu" and rc == 0:
        pytest.skip("this machine has a CUDA GPU")
    assert verdict == "ok", f"{case.name}: {verdict}, rc {rc}, stderr {stderr[-2000:]!r}"


def main(argv: list[str] | None = None) -> int:
    import argparse
    import tempfile

    parser = argparse.ArgumentParser(description="Count clear errors over CASES for the code at --pythonpath.")
    parser.add_argument("--pythonpath", type=Path, default=ROOT)
    parser.add_argument("--only", nargs="*", default=None)
    parser.add_argument("--timeout", type=float, default=300, help="seconds per case (over it: 'timeout')")
    args = parser.parse_args(argv)
    counts: dict[str, int] = {}
    for case in CASES:
        if args.only and case.name not in args.only:
            continue
        with tempfile.TemporaryDirectory() as tmp:
            try:
                verdict, rc, stderr = run_case(case, Path(tmp), args.pythonpath, args.timeout)
            except subprocess.TimeoutExpired:
                verdict, rc, stderr = "timeout", -1, ""
        counts[verdict] = counts.get(verdict, 0) + 1
        lines = _message_lines(stderr)
        shown = lines[-1] if lines else ""
        print(f"{verdict:9s} rc={rc:<3d} {case.name:40s} {shown[:150]}", flush=True)
    total = sum(counts.values())
    print(f"# {total} cases: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
