"""No silent answers for prints: a mask that prints as too few dots, an option that does not apply, a file's own size
overridden, and a sheet too large are each refused or said, in one line, before anything is written."""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import pytest

import mincam_sim.masks as M
from mincam_sim.errors import InputError
from mincam_sim.masks import sheet as sheet_mod
from mincam_sim.masks.printing import MIN_PRINT_DOTS, PrintWarning, check_print_dots, few_print_dots
from mincam_sim.masks.sheet import check_print_sheet, write_print_sheet
from mincam_sim.storage import imageio

INCH_M = 0.0254


def test_too_few_dots_names_size_dpi_and_the_smallest_dpi():
    with pytest.raises(InputError) as err:
        check_print_dots(1e-4, 1e-4, 50)
    message = str(err.value)
    # 0.1 mm at 50 dpi is 0.2 dots, rounded up to one; 8 dots over 0.1 mm need 8 * 25.4 / 0.1 = 2032 dpi
    for part in ("0.1 x 0.1 mm", "1 x 1 dots", "50 dpi", "dpi >= 2032", "4.06 mm"):
        assert part in message, (part, message)
    assert "\n" not in message


def test_the_threshold_is_eight_dots_on_the_short_side():
    dpi = 600.0
    eight_m, seven_m = 8 * INCH_M / dpi, 7 * INCH_M / dpi
    assert few_print_dots(eight_m, 1e-3, dpi) is None
    assert "7 x " in few_print_dots(seven_m, 1e-3, dpi)  # cols x rows: the narrow side is named
    assert few_print_dots(1e-3, seven_m, dpi) is not None
    assert MIN_PRINT_DOTS == 8


def test_no_dpi_can_print_a_tiny_mask():
    message = few_print_dots(1e-5, 1e-5, 600)
    assert "no dpi up to 4800" in message and "0.339 mm" in message


def test_export_of_too_few_dots_warns_in_one_line(tmp_path):
    with pytest.warns(PrintWarning, match=r"1 x 1 dots at 50 dpi") as record:
        path = M.export_print_png(M.ramp("x", 16, width_m=1e-4), tmp_path / "m.png", dpi=50)
    assert len(record) == 1 and path.is_file()
    with pytest.warns(PrintWarning, match="2032"):
        write_print_sheet([M.ramp("x", 16, width_m=1e-4)], [(0.0, 0.0)], 50, None, tmp_path / "s.png")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a mask of enough dots says nothing
        M.export_print_png(M.ramp("x", 16), tmp_path / "ok.png", dpi=600)


def test_check_print_sheet_refuses_before_anything_is_written(tmp_path, monkeypatch):
    with pytest.raises(InputError, match="too few"):
        check_print_sheet([M.ramp("x", 16, width_m=1e-4)], [(0.0, 0.0)], 50)
    check_print_sheet([M.ramp("x", 16)], [(0.0, 0.0)], 600)  # a 2 mm mask at 600 dpi: 47 dots, fine
    monkeypatch.setattr(sheet_mod, "MAX_TEXELS", 10_000)
    with pytest.raises(InputError, match=r"print sheet of \d+ x \d+ dots at 600 dpi is too large"):
        check_print_sheet([M.ramp("x", 16)], [(0.0, 0.0)], 600)
    with pytest.raises(InputError, match="too large"):
        write_print_sheet([M.ramp("x", 16)], [(0.0, 0.0)], 600, None, tmp_path / "s.png")
    # masks far apart make the sheet large whatever the dpi: the message says so (it blamed the dpi alone for
    # `design tracking --spacing-m 0.2`, inside the documented range)
    with pytest.raises(InputError, match=r"masks at their places, 40(\.\d)? x 0\.2 cm apart.*bring the mixels closer"):
        check_print_sheet([M.ramp("x", 16)] * 2, [(-0.2, 0.0), (0.2, 0.0)], 50)
    assert not any(tmp_path.iterdir())


def test_sheet_refusals_are_input_errors(tmp_path):
    with pytest.raises(InputError, match="overlap"):
        check_print_sheet([M.ramp("x"), M.ramp("y")], [(0.0, 0.0), (0.001, 0.0)], 600)
    with pytest.raises(InputError, match="50 to 4800"):
        check_print_sheet([M.ramp("x")], [(0.0, 0.0)], 10)
    with pytest.raises(InputError, match=".pdf"):
        write_print_sheet([M.ramp("x")], [(0.0, 0.0)], 600, None, tmp_path / "s.jpg")


# ------------------------------------------------------------------------------------------------ the command


def _export(args: list[str], cwd: Path):
    from typer.testing import CliRunner

    from mincam_sim.cli import app

    old = Path.cwd()
    os.chdir(cwd)
    try:
        return CliRunner().invoke(app, ["masks", "export", *args])
    finally:
        os.chdir(old)


def _lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.strip()]


def test_cli_refuses_too_few_dots_and_writes_nothing(tmp_path):
    r = _export(["ramp:x", "--out", "m.png", "--size-m", "0.0001", "--dpi", "50"], tmp_path)
    assert r.exit_code == 2
    assert _lines(r.stderr) == [
        "error: --size-m 0.0001 at --dpi 50: mask of 0.1 x 0.1 mm prints as 1 x 1 dots at 50 dpi, too few to show "
        "it (at least 8 dots a side): give --dpi >= 2032, or make the mask at least 4.06 mm a side at 50 dpi"]
    assert not any(tmp_path.iterdir())


def test_cli_refuses_a_sheet_too_large_before_writing_the_mask(tmp_path):
    # 85 mm at 2400 dpi: the mask (8031 dots a side) fits a print file, its sheet (margins, notes) does not
    r = _export(["ramp:x", "--out", "m.png", "--size-m", "0.085", "--dpi", "2400"], tmp_path)
    assert r.exit_code == 2
    assert _lines(r.stderr) == [
        "error: --size-m 0.085 at --dpi 2400: the print sheet (the mask, its marks and notes) would hold more dots "
        "than a print file does; give --dpi <= 1538, or --no-sheet to write the mask alone"]
    assert not any(tmp_path.iterdir())


def test_cli_names_the_largest_dpi_of_a_sheet_and_it_works(tmp_path):
    """A 2 mm mask at 4800 dpi (in the allowed range) wrote its PNG and then a traceback for the sheet; now it is
    refused first, naming the largest dpi, which then works (and --no-sheet writes the mask alone)."""
    r = _export(["ramp:x", "--out", "m.png", "--dpi", "4800"], tmp_path)
    assert r.exit_code == 2 and not any(tmp_path.iterdir())
    largest = int(r.stderr.split("--dpi <= ")[1].split(",")[0])
    assert 2000 < largest < 4800
    mask, title = M.ramp("x", 512), "mask ramp:x"  # what the command prints (writing a 67 M-dot sheet takes long)
    check_print_sheet([mask], [(0.0, 0.0)], largest, M.PrintedFilm(dpi=largest), title=title)
    with pytest.raises(InputError, match="too large"):
        check_print_sheet([mask], [(0.0, 0.0)], largest + 1, M.PrintedFilm(dpi=largest + 1), title=title)
    alone = _export(["ramp:x", "--out", "a.png", "--dpi", "4800", "--no-sheet"], tmp_path)
    assert alone.exit_code == 0 and not (tmp_path / "a_sheet.png").exists()
    assert imageio.read_png(tmp_path / "a.png")[0].shape == (378, 378)  # 2 mm at 4800 dpi


def test_cli_says_srgb_does_not_apply_to_a_generated_mask(tmp_path):
    r = _export(["ramp:x", "--out", "m.png", "--srgb"], tmp_path)
    assert r.exit_code == 0
    assert _lines(r.stderr) == ["warning: --srgb does not apply to 'ramp:x': it decodes the values of a file: mask's "
                                "PNG; a generated mask is transmission already (--srgb ignored)"]
    plain = _export(["ramp:x", "--out", "p.png"], tmp_path)
    assert plain.exit_code == 0 and _lines(plain.stderr) == []
    assert (tmp_path / "m.png").read_bytes() == (tmp_path / "p.png").read_bytes()


def test_cli_says_levels_do_not_apply_with_halftone(tmp_path):
    r = _export(["ramp:x", "--out", "m.png", "--halftone", "--levels", "4"], tmp_path)
    assert r.exit_code == 0
    [line] = _lines(r.stderr)
    assert line.startswith("warning: --levels 4 does not apply with --halftone")
    arr, _ = imageio.read_png(tmp_path / "m.png")
    assert set(np.unique(arr)) <= {0.0, 1.0}  # halftoned, not four levels
    alone = _export(["ramp:x", "--out", "h.png", "--halftone"], tmp_path)
    assert alone.exit_code == 0 and _lines(alone.stderr) == []


def test_cli_prints_an_exr_at_the_size_it_records(tmp_path):
    M.save_exr(M.ramp("x", 64, width_m=4e-3), tmp_path / "m4.exr")
    r = _export(["file:m4.exr", "--out", "own.png"], tmp_path)
    assert r.exit_code == 0 and _lines(r.stderr) == []
    arr, info = imageio.read_png(tmp_path / "own.png")
    assert arr.shape == (round(4e-3 / INCH_M * 600),) * 2  # 94 dots: 4 mm, not the 2 mm default
    asked = _export(["file:m4.exr", "--out", "asked.png", "--size-m", "0.002"], tmp_path)
    assert asked.exit_code == 0
    assert _lines(asked.stderr) == ["warning: m4.exr records a 4 x 4 mm mask; printing it 2 mm wide as --size-m asks "
                                    "(leave --size-m out to print it at its own size)"]
    assert imageio.read_png(tmp_path / "asked.png")[0].shape == (47, 47)
    same = _export(["file:m4.exr", "--out", "same.png", "--size-m", "0.004"], tmp_path)
    assert same.exit_code == 0 and _lines(same.stderr) == []


def test_cli_png_file_keeps_the_default_size(tmp_path):
    imageio.write_png(tmp_path / "m.png", np.tile(np.linspace(0, 1, 32), (32, 1)), bit_depth=8)
    r = _export(["file:m.png", "--out", "p.png"], tmp_path)
    assert r.exit_code == 0 and _lines(r.stderr) == []
    assert imageio.read_png(tmp_path / "p.png")[0].shape == (47, 47)  # 2 mm at 600 dpi, as before
