"""An empty (or blank) path given to an option or argument of the command line is refused in one line naming it;
before, the parser took ``--out ""`` for ``.`` and wrote into the working directory."""

from __future__ import annotations

import os

import pytest
from typer.testing import CliRunner

import mincam_sim  # noqa: F401  (before Dr.Jit / Mitsuba)

CASES = [
    (["render", "{config}", "--out", ""], "--out"),
    (["render", "{config}", "--out="], "--out"),
    (["render", ""], "config"),
    (["export-maps", "{config}", "--out", "", "--ideal"], "--out"),
    (["masks", "generate", "--out", ""], "--out"),
    (["masks", "export", "ramp:x", "--out", " "], "--out"),
    (["masks", "export", "ramp:x", "--out", "m.png", "--sheet", ""], "--sheet"),
    (["reproduce", "--quick", "--out", ""], "--out"),
    (["reproduce", "--quick", "--config", ""], "--config"),
    (["study", "run", "{config}", "--out", ""], "--out"),
    (["design", "tracking", "--out", ""], "--out"),
    (["demo", "--out", ""], "--out"),
    (["figures", "--out", ""], "--out"),
]


@pytest.mark.parametrize(("args", "named"), CASES, ids=[" ".join(a) for a, _ in CASES])
def test_an_empty_path_is_refused_naming_the_option_and_nothing_is_written(tmp_path, monkeypatch, args, named):
    from mincam_sim.cli import app

    config = tmp_path / "c.toml"
    config.write_text("[screen]\nresolution = [16, 9]\n")
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    result = CliRunner().invoke(app, [a.format(config=config) for a in args])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: Invalid value for '{named}': "), result.output
    assert "path; give a file or folder name" in lines[0]
    assert os.listdir(work) == []
