"""The documentation's generated pages (docs/gen_pages.py) come from the benchmark JSON and the code, not from
text typed in by hand: a value changed in the JSON changes the page, and every entry of the JSON appears."""

from __future__ import annotations

import copy
import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def gen():
    spec = importlib.util.spec_from_file_location("gen_pages", ROOT / "docs" / "gen_pages.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def validation():
    return json.loads((ROOT / "benchmarks" / "validation.json").read_text(encoding="utf-8"))


def test_validation_tables_follow_the_json(gen, validation):
    text = gen.validation_tables(validation)
    on_axis = validation["open_aperture_on_axis"]
    assert gen._g(on_axis["closed_form_w_m2"]) in text
    for form in ("reference", "fast", "response_map"):
        assert gen._pm(on_axis[form]["value_w_m2"], on_axis[form]["sigma_w_m2"]) in text
    assert "Other entries" not in text  # every entry of today's JSON has its table
    changed = copy.deepcopy(validation)
    changed["open_aperture_on_axis"]["fast"]["value_w_m2"] = 1.234567
    assert "1.23457 ±" in gen.validation_tables(changed)
    changed["a_new_check"] = {"value_w_m2": 0.5}
    assert "`a_new_check`" in gen.validation_tables(changed)  # an unknown entry is shown, not dropped


def test_performance_tables_follow_the_json(gen):
    results = json.loads((ROOT / "benchmarks" / "results.json").read_text(encoding="utf-8"))
    text = gen.performance_tables(results)
    assert f"**{results['sweep']['sweep_seconds']:.2f} s**" in text
    assert f"**{results['moving_object']['frames_per_second']:.1f} frames/s**" in text
    assert results["machine"]["cpu_model"] in text


def test_cli_and_config_reference_come_from_the_code(gen):
    from mincam_sim.configuration.config import EXAMPLE_TOML
    from mincam_sim.experiments import REGISTRY

    cli = gen.cli_reference()
    for command in ("render", "config-example", "reproduce", "demo", "design", "figures", "masks export",
                    "study run"):
        assert f"## `mincam-sim {command}`" in cli
    config = gen.config_reference()
    assert EXAMPLE_TOML.strip() in config
    for name in REGISTRY:
        assert f"### `[{name}]`" in config


def test_changelog_page_only_with_a_changelog(gen, tmp_path, monkeypatch):
    monkeypatch.setattr(gen, "ROOT", tmp_path)
    assert "changelog" not in gen.reference_toc()
    (tmp_path / "CHANGELOG.md").write_text("# Changelog\n")
    assert "changelog" in gen.reference_toc()
