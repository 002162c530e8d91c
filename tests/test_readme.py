"""The README's Python snippet runs as printed."""

from __future__ import annotations

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_python_snippet_runs(capsys):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    assert blocks, "README has no python snippet"
    exec(compile(blocks[0], "README.md", "exec"), {})
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 9 and all("W/m²" in line for line in out)


def test_readme_schema_matches_config_keys():
    from mincam_sim.config import _SCHEMA

    text = README.read_text()
    for section, keys in _SCHEMA.items():
        assert f"[{section}]" in text
        for key in keys:
            assert re.search(rf"^{key} = ", text, flags=re.M), f"README schema lacks [{section}] {key}"


def test_every_readme_python_snippet_runs(tmp_path, monkeypatch):
    """Every ```python block after the first runs too (from the repository root, as a reader would); blocks
    that need a finished run or a cluster are marked ```py instead."""
    monkeypatch.chdir(README.parent)
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    for i, block in enumerate(blocks[1:], start=2):
        exec(compile(block, f"README.md python block {i}", "exec"), {})
