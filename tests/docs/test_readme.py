"""The README's and the guide pages' Python snippets run as printed."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[2] / "README.md"


def test_readme_python_snippet_runs(capsys):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    assert blocks, "README has no python snippet"
    exec(compile(blocks[0], "README.md", "exec"), {})
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 9 and all("W/m²" in line for line in out)


def test_every_readme_python_snippet_runs(tmp_path, monkeypatch):
    """Every ```python block after the first runs too (from the repository root, as a reader would); blocks
    that need a finished run or a cluster are marked ```py instead."""
    monkeypatch.chdir(README.parent)
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    for i, block in enumerate(blocks[1:], start=2):
        exec(compile(block, f"README.md python block {i}", "exec"), {})


DOCS = README.parent / "docs"
PAGES = sorted(p.name for p in DOCS.glob("*.md") if p.name != "python_api.md"  # run as one namespace elsewhere
               and "```python" in p.read_text())


@pytest.mark.parametrize("page", PAGES)
def test_every_docs_page_python_block_runs(page, monkeypatch):
    """The guide pages' ```python blocks run as printed, from the repository root (``py`` blocks are shown only)."""
    monkeypatch.chdir(README.parent)
    for i, block in enumerate(re.findall(r"```python\n(.*?)```", (DOCS / page).read_text(), flags=re.S), start=1):
        exec(compile(block, f"docs/{page} python block {i}", "exec"), {})
