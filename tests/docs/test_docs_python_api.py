"""docs/python_api.md documents the whole front door (its blocks run, in order, in test_docs_code_blocks.py, which
also checks what they print)."""

from __future__ import annotations

import re
from pathlib import Path

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
