"""The tracking design's print sheet: a spacing or dpi inside the shared ranges whose sheet cannot be written is
refused up front as one error naming both fields and the values that do work, which then do work."""

from __future__ import annotations

import re

import pytest

import mincam_sim  # noqa: F401  (before drjit/mitsuba)
from mincam_sim.design import checks
from mincam_sim.design.run import check_printable, make_task


def _refusal(**fields) -> checks.FieldError:
    with pytest.raises(checks.FieldError) as info:
        check_printable(make_task(True, 0, **fields))
    return info.value


def test_widest_shared_spacing_names_both_fields_and_what_fits():
    """``spacing_m = 0.2`` (the top of the shared range) at the default 600 dpi was an InputError about the
    sheet that named neither field; now both, with the largest spacing at 600 dpi and the dpis at 0.2 m."""
    err = _refusal(spacing_m=0.2)
    assert err.fields == ("spacing_m", "dpi")
    text = str(err)
    largest = float(re.search(r"at 600 dpi the spacing can be at most ([\d.]+) m", text).group(1))
    low, high = map(float, re.search(r"at spacing 0.2 m the dpi can be (\d+) to (\d+)", text).groups())
    assert 0.1 < largest < 0.2 and low == 102 and 300 < high < 600
    check_printable(make_task(True, 0, spacing_m=largest))  # what it names works
    check_printable(make_task(True, 0, spacing_m=0.2, dpi=high))
    check_printable(make_task(True, 0, spacing_m=0.2, dpi=low))
    assert _refusal(spacing_m=0.2, dpi=high + 1).fields == ("spacing_m", "dpi")


def test_dpi_too_low_for_the_masks_names_the_dpi_alone():
    err = _refusal(dpi=50)
    assert err.fields == ("dpi",) and "at least 102 dots per inch" in str(err)
    check_printable(make_task(True, 0, dpi=102))


def test_every_task_refuses_a_dpi_that_prints_too_few_dots():
    """``dpi = 50`` (inside 50-4800) printed counting's and depth's 2 mm masks as 4 x 4 dots, below the 8 a side
    that every print function asks for, while tracking refused it only through its sheet."""
    from mincam_sim.design import counting, depth
    from mincam_sim.design.scene_run import make_sizes

    assert checks.lowest_printable_dpi() == 102
    for module in (counting, depth):
        spec = next(v for v in vars(module).values() if type(v).__name__ == "TaskSpec")
        with pytest.raises(checks.FieldError, match="at least 102 dots per inch") as info:
            make_sizes(spec, True, 0, dpi=50)
        assert info.value.fields == ("dpi",)
        assert make_sizes(spec, True, 0, dpi=102).film().grid_shape(2e-3, 2e-3) == (8, 8)


def test_dpi_that_no_spacing_can_print_says_so():
    err = _refusal(dpi=2400)
    assert "no spacing fits at 2400 dpi" in str(err)
    high = int(re.search(r"the dpi can be 102 to (\d+)", str(err)).group(1))
    check_printable(make_task(True, 0, dpi=high))


def test_cli_names_the_options(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    import mincam_sim.design
    from mincam_sim.cli import app

    def started(*args, **kwargs):
        raise AssertionError("the design started instead of refusing its sheet")

    monkeypatch.setattr(mincam_sim.design, "run_design", started)
    out = tmp_path / "o"
    r = CliRunner().invoke(app, ["--quiet", "design", "tracking", "--quick", "--spacing-m", "0.2", "--out", str(out)])
    lines = [line for line in r.output.splitlines() if line.strip()]
    assert r.exit_code == 2 and len(lines) == 1, r.output
    assert lines[0].startswith("error: --spacing-m and dpi (default) must give a print sheet")
    assert "the spacing can be at most" in lines[0] and not out.exists()
