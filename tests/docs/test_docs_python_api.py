"""docs/python_api.md: every ```python block on the page runs, in order, in one namespace, from the repository
root (so the page never shows code that does not work), and the page documents the whole front door."""

from __future__ import annotations

import os
import re
import warnings
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "python_api.md"
BLOCK = re.compile(r"^```python\n(.*?)^```$", re.S | re.M)


def _blocks() -> list[str]:
    return BLOCK.findall(PAGE.read_text(encoding="utf-8"))


def test_page_has_code_and_names_the_front_door():
    text = PAGE.read_text(encoding="utf-8")
    assert len(_blocks()) >= 8
    for name in ("Simulation", "ResponseMap", "Aperture", "Reference", "StratifiedChange", "PlainChange", "Budget",
                 "Changes", "RunInfo", "ms.Run", "FallbackWarning", "HeavyTailWarning", "InputError", "ConfigError",
                 "world coordinates"):
        assert name in text, name
    index = (ROOT / "docs" / "index.md").read_text(encoding="utf-8")
    assert "{doc}`python_api`" in index and re.search(r"^forms\npython_api$", index, re.M)


def test_every_block_runs_from_the_repository_root(capsys):
    namespace: dict = {"__name__": "python_api_page"}
    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the page's blocks catch and check what they expect
            for i, code in enumerate(_blocks()):
                try:
                    exec(compile(code, f"{PAGE.name}[block {i}]", "exec"), namespace)
                except Exception as err:  # noqa: BLE001 - name the block that failed
                    pytest.fail(f"block {i} of {PAGE.name} raised {type(err).__name__}: {err}\n{code}")
    finally:
        os.chdir(cwd)
    out = capsys.readouterr().out
    # the errors block prints each refusal: three InputErrors and one ConfigError, each naming the fix
    assert out.count("InputError:") >= 4 and "ConfigError:" in out
    assert "did you mean 'toy_car.vertex_positions'" in out


def test_config_reference_holds_the_world_schema():
    import sys

    sys.path.insert(0, str(ROOT / "docs"))
    try:
        import gen_pages
    finally:
        sys.path.remove(str(ROOT / "docs"))
    from mincam_sim.configuration.world_config import world_example_toml

    text = gen_pages.config_reference()
    assert world_example_toml().rstrip() in text
    for target in ("spacing", "intrusion", "tracking", "speed", "design", "render"):
        assert f"| `{target}` |" in text
