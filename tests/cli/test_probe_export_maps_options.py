"""``export-maps`` checks and warns about a display file as the export reads it, whatever the file's own
``[run] solver``: ``--ideal`` uses ``[run.dot_product]`` (and says nothing about it), the physics export ignores it
(and says so), and a key only the file's own solver reads is not refused."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

import mincam_sim  # noqa: F401  (before Dr.Jit / Mitsuba)

SCREEN = "[screen]\nresolution = [16, 9]\n"


def _export(config: Path, out: Path, *extra: str):
    from mincam_sim.cli import app

    return CliRunner().invoke(app, ["--quiet", "export-maps", str(config), "--out", str(out), *extra])


def _warnings(result) -> list[str]:
    return [line for line in result.output.splitlines() if line.startswith("warning: ")]


def test_ideal_export_uses_the_dot_product_options_of_a_file_written_for_another_solver_without_a_false_warning(
        tmp_path):
    """Before, the line ``warning: [run.dot_product] parallax is ignored: they are the options of solver =
    "dot_product", and this file's solver is "response_map"`` came while the export used parallax."""
    config = tmp_path / "c.toml"
    config.write_text(SCREEN + '[run]\nsolver = "response_map"\n[run.dot_product]\nparallax = true\n')
    result = _export(config, tmp_path / "out", "--ideal")
    assert result.exit_code == 0, result.output
    assert not any("dot_product" in line for line in _warnings(result)), result.output
    source = json.loads((tmp_path / "out" / "maps.json").read_text())["source"]
    assert source["solver"] == "dot_product" and "parallax" in source["effects"]


def test_ideal_export_does_not_refuse_a_sample_budget_it_does_not_trace(tmp_path):
    """Before: ``error: [run] samples_per_texel = 4 is fewer than its 8 replicates ...`` for a key --ideal
    ignores (and says it ignores)."""
    config = tmp_path / "c.toml"
    config.write_text(SCREEN + '[run]\nsolver = "response_map"\nsamples_per_texel = 4\n')
    result = _export(config, tmp_path / "out", "--ideal")
    assert result.exit_code == 0, result.output
    assert _warnings(result) == ["warning: [run] samples_per_texel is ignored: --ideal exports the idealised "
                                 "dot-product model: deterministic quadrature (no samples) (IgnoredSettingWarning)"]


def test_physics_export_says_that_it_ignores_the_dot_product_options_of_a_dot_product_file(tmp_path):
    """Before: silence, while the maps were traced without the options the file sets."""
    from mincam_sim.render import backend

    if not backend.is_jit():
        pytest.skip("response maps need a JIT variant (LLVM or CUDA)")
    config = tmp_path / "c.toml"
    config.write_text(SCREEN + '[run]\nsolver = "dot_product"\nsamples_per_texel = 32\nreplicates = 2\n'
                      "[run.dot_product]\nparallax = true\n")
    result = _export(config, tmp_path / "out")
    assert result.exit_code == 0, result.output
    assert _warnings(result) == ["warning: [run.dot_product] parallax is ignored: they are the options of the "
                                 "idealised model, which export-maps writes with --ideal; without it, it traces "
                                 "response maps (IgnoredSettingWarning)"]
    assert json.loads((tmp_path / "out" / "maps.json").read_text())["source"]["samples_per_texel"] == 32


def test_a_bad_solver_name_is_still_refused_by_both_exports(tmp_path):
    config = tmp_path / "c.toml"
    config.write_text(SCREEN + '[run]\nsolver = "respons_map"\n')
    for extra in ([], ["--ideal"]):
        result = _export(config, tmp_path / f"out{len(extra)}", *extra)
        assert result.exit_code == 2, result.output
        assert result.output.startswith("error: [run] solver = 'respons_map'"), result.output
        assert not (tmp_path / f"out{len(extra)}").exists()


def test_the_physics_export_says_how_many_samples_it_traces_where_that_is_not_the_count_asked(tmp_path):
    """As ``render`` does; before, export-maps traced 8 of the 16 asked (rounded to replicates x k^2) silently."""
    from mincam_sim.render import backend

    if not backend.is_jit():
        pytest.skip("response maps need a JIT variant (LLVM or CUDA)")
    config = tmp_path / "c.toml"
    config.write_text(SCREEN + "[run]\nsamples_per_texel = 16\n")
    result = _export(config, tmp_path / "out")
    assert result.exit_code == 0, result.output
    assert ("mincam-sim: [run] samples_per_texel = 16 traces 8 samples per texel (8 replicates x 1x1 strata, "
            "rounded down); ask 8 or 32 to get exactly what runs") in result.output.splitlines()
    assert json.loads((tmp_path / "out" / "maps.json").read_text())["source"]["samples_per_texel"] == 8
    exact = tmp_path / "exact.toml"
    exact.write_text(SCREEN + "[run]\nsamples_per_texel = 32\n")
    assert "traces" not in _export(exact, tmp_path / "out2").output
