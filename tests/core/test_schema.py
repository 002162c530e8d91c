"""One config mechanism (mincam_sim.configuration.schema) for the render, world, reproduce and study files.

Each file kind's documented example is written from the same dataclasses that hold the defaults and the checks:
the example must parse back to exactly the defaults, show every field with its comment, and every kind must
refuse an unknown section or key with the same one-line message (the closest allowed name as a hint).
"""

from __future__ import annotations

import dataclasses
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from mincam_sim.cli import app
from mincam_sim.configuration.config import EXAMPLE_TOML, RENDER_SCHEMA, load_config
from mincam_sim.configuration.schema import Schema, field_comment, plain, read_section, toml_value
from mincam_sim.configuration.world_config import WORLD_SCHEMA, load_world_config, world_example_toml
from mincam_sim.errors import ConfigError
from mincam_sim.experiments import REGISTRY, Setup, load_reproduce_config
from mincam_sim.experiments.reproduce_file import reproduce_example_toml, reproduce_schema
from mincam_sim.studies.spec import StudySection, load_study, study_example_toml, study_schema

ROOT = Path(__file__).resolve().parents[2]

SCHEMAS = {
    "render": (RENDER_SCHEMA, EXAMPLE_TOML),
    "world": (WORLD_SCHEMA, world_example_toml()),
    "reproduce": (reproduce_schema(), reproduce_example_toml()),
    "study": (study_schema(), study_example_toml()),
}
_COMMENTED = re.compile(r"^# (\[\[?[\w.]+\]\]?\s*$|[A-Za-z_]\w* = )")


def uncommented(text: str) -> str:
    """The example with every commented-out section header and key set (``# key = v`` -> ``key = v``)."""
    return "\n".join(line[2:] if _COMMENTED.match(line) else line for line in text.splitlines()) + "\n"


def part_table(doc: dict, name: str):
    head, _, sub = name.partition(".")
    value = doc.get(head, {})
    return value.get(sub, {}) if sub else value


def expected_value(f: dataclasses.Field):
    """What the example shows for a field: its default, or its example where the default is None."""
    return plain(f.metadata.get("example") if f.default is None else f.default)


def _normal(text: str) -> str:
    return re.sub(r"[#\s]+", " ", text).strip()


def blocks(text: str) -> dict[str, str]:
    """The example's text under each section header (``[name]``, ``[[name]]``, commented or not)."""
    out: dict[str, str] = {}
    current = None
    for line in text.splitlines():
        header = re.match(r"^(?:# )?\[\[?([\w.]+)\]\]?\s*$", line)
        if header:
            current = header.group(1)
            out[current] = ""
        elif current is not None:
            out[current] += line + "\n"
    return out


@pytest.mark.parametrize("kind", list(SCHEMAS))
def test_each_example_parses_back_to_exactly_the_defaults(kind):
    schema, text = SCHEMAS[kind]
    for doc in (tomllib.loads(text), tomllib.loads(uncommented(text))):
        for part in schema.parts:
            if part.cls is None:
                continue
            given = part_table(doc, part.name)
            tables = given if part.array else [given]
            if part.array and not tables:
                continue  # a commented-out [[name]] block in the first pass
            for table in tables:
                fields = {f.name: f for f in dataclasses.fields(part.cls)}
                free = [k for k in table if k not in fields and k not in schema.subparts(part.name)]
                assert not free or part.example, (kind, part.name, free)  # only a free table's example keys
                table = {k: v for k, v in table.items() if k in fields}
                for key, value in table.items():
                    assert value == expected_value(fields[key]), (kind, part.name, key, value)
                read = read_section(part.name, table, part.cls)  # every value passes its check
                if all(f.default is not None for f in fields.values()):
                    assert read == part.cls(), (kind, part.name)


def test_the_render_example_is_the_default_config():
    example, default = load_config(EXAMPLE_TOML), load_config({})
    assert example.run == default.run  # the solver object and the budget, every key at its default
    assert example.mincam.names == default.mincam.names
    assert [m.pose for m in example.mincam] == [m.pose for m in default.mincam]
    assert example.screen == default.screen and example.frames.shape == default.frames.shape


def test_the_reproduce_example_is_the_defaults_commented_or_not():
    for text in (reproduce_example_toml(), uncommented(reproduce_example_toml())):
        setup, params = load_reproduce_config(text)
        assert setup == Setup()
        assert params == {name: e.params(False) for name, e in REGISTRY.items()}
    quick_setup, quick = load_reproduce_config(reproduce_example_toml(), quick=True)  # commented: quick stays quick
    assert quick_setup.quick and quick == {name: e.params(True) for name, e in REGISTRY.items()}
    assert "# frames_per_toy = 100" in reproduce_example_toml() and "(--quick: 8)" in reproduce_example_toml()


def test_the_shipped_reproduce_file_is_the_generated_example():
    shipped = (ROOT / "scenes" / "experiments" / "reproduce.toml").read_text(encoding="utf-8")
    assert shipped == reproduce_example_toml(), ("scenes/experiments/reproduce.toml is out of date: regenerate it "
                                                 "with mincam-sim config-example --reproduce")


def test_the_study_example_runs_a_small_spacing_study_at_the_defaults():
    spec = load_study(study_example_toml())
    defaults = StudySection()
    assert (spec.seed, spec.replicates, spec.common_random_numbers) == (
        defaults.seed, defaults.replicates, defaults.common_random_numbers)
    assert spec.experiment.name == "spacing" and set(spec.dims) == {"spacing_m", "depth_m"}
    assert spec.out_dir == Path("out/studies/spacing")


@pytest.mark.parametrize("kind", list(SCHEMAS))
def test_every_field_appears_in_its_example_with_its_comment(kind):
    schema, text = SCHEMAS[kind]
    found = blocks(text)
    for part in schema.parts:
        assert part.name in found, (kind, part.name)
        if part.cls is None:
            continue
        block = found[part.name]
        for f in dataclasses.fields(part.cls):
            assert re.search(rf"^(# )?{f.name} = ", block, flags=re.M), (kind, part.name, f.name)
            comment = field_comment(part.cls, f)
            assert comment, f"{kind} [{part.name}] {f.name} has no comment"
            assert _normal(comment) in _normal(block), (kind, part.name, f.name, comment)


def _world_dir(tmp_path: Path) -> Path:
    for name in ("room.xml", "toy_car.obj"):
        (tmp_path / name).write_bytes((ROOT / "scenes" / "world" / name).read_bytes())
    return tmp_path


WORLD_BASE = '[world]\nscene = "room.xml"\n[[world.mover]]\nid = "toy_car"\noffsets_m = [[0, 0, 0]]\n'
UNKNOWN_KEYS = {
    "render [run]": ("render", "[run]\nsppp = 3\n", "[run]", "sppp", "spp"),
    "render [[mixel]]": ("render", "[mincam]\nlayout = 'custom'\n[[mixel]]\nmask = 'ramp:x'\nmsk_size_m = 0.002\n",
                         "[[mixel]] #1", "msk_size_m", "mask_size_m"),
    "render sinusoid mask": ("render", "[mincam]\nlayout = 'custom'\n[[mixel]]\n"
                             "mask = {kind = 'sinusoid', omega_rad_per_m = 1.0, phase_deg = 0.0}\n",
                             "[[mixel]] #1 mask", "phase_deg", "phase_rad"),
    "world [world]": ("world", WORLD_BASE.replace("scene =", "frame_rate_h = 3.0\nscene ="), "[world]",
                      "frame_rate_h", "frame_rate_hz"),
    "world [[world.light]]": ("world", WORLD_BASE + '[[world.light]]\nid = "l"\nkind = "point"\nintensity = 1.0\n',
                              "[[world.light]] #1", "intensity", "intensity_w_sr"),
    "world [world.camera]": ("world", WORLD_BASE + "[world.camera]\nposition_m = [0, 0, 1]\nlook_at_m = [0, 0, 0]\n"
                             "fov = 40.0\n", "[world.camera]", "fov", "fov_deg"),
    "reproduce [tracking]": ("reproduce", "[tracking]\nframes_per_toi = 3\n", "[tracking]", "frames_per_toi",
                             "frames_per_toy"),
    "reproduce [setup]": ("reproduce", "[setup]\ndepht_m = 0.4\n", "[setup]", "depht_m", "depth_m"),
    "study [study]": ("study", "[study]\nexperiment = 'spacing'\nreplicate = 3\n[grid]\ndepth_m = [0.5]\n",
                      "[study]", "replicate", "replicates"),
}


def _load(kind: str, text: str, tmp_path: Path):
    if kind == "render":
        return load_config(text, base_dir=tmp_path)
    if kind == "world":
        path = _world_dir(tmp_path) / "w.toml"
        path.write_text(text)
        return load_world_config(path)
    if kind == "reproduce":
        return load_reproduce_config(text)
    return load_study(text)


@pytest.mark.parametrize("case", list(UNKNOWN_KEYS))
def test_an_unknown_key_gets_the_same_error_in_every_file_kind(case, tmp_path):
    kind, text, section, key, hint = UNKNOWN_KEYS[case]
    with pytest.raises(ConfigError) as err:
        _load(kind, text, tmp_path)
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith(f"{section}: unknown key {key} (did you mean {hint}?); allowed keys are "), message
    assert hint in message.split("allowed keys are ", 1)[1].split(", ")


@pytest.mark.parametrize(("kind", "text", "wrong", "hint"), [
    ("render", "[scren]\n", "[scren]", "[screen]"),
    ("render", "[mixels]\n", "[mixels]", "[[mixel]]"),
    ("world", WORLD_BASE + "[wrld]\n", "[wrld]", "[world]"),
    ("reproduce", "[trackng]\n", "[trackng]", "[tracking]"),
    ("study", "[study]\nexperiment = 'spacing'\n[grd]\ndepth_m = [0.5]\n", "[grd]", "[grid]"),
])
def test_an_unknown_section_gets_the_same_error_in_every_file_kind(kind, text, wrong, hint, tmp_path):
    with pytest.raises(ConfigError) as err:
        _load(kind, text, tmp_path)
    message = str(err.value)
    assert message.startswith(f"unknown section {wrong} (did you mean {hint}?); allowed sections are "), message


def test_a_misspelt_study_parameter_and_choice_get_the_closest_name():
    with pytest.raises(ConfigError, match=r"\[grid\] depth_mm: not a parameter .*did you mean depth_m\?"):
        load_study({"study": {"experiment": "spacing"}, "grid": {"depth_mm": [0.5]}})
    with pytest.raises(ConfigError, match=r"solver = 'aperturr' is not one of .*did you mean 'aperture'\?"):
        load_config("[run]\nsolver = 'aperturr'\n")


@pytest.mark.parametrize("kind, text, fix", [
    ("display", "form = 'fast'", 'use [run] solver = "aperture"'),
    ("display", "form = 'response_map'", 'use [run] solver = "response_map"'),
    ("display", "form = 'reference'", 'use [run] solver = "reference"'),
    ("display", "form = 'fats'", 'use [run] solver = one of "reference", "aperture", "response_map"'),
    ("world", "estimator = 'stratified'", 'use [run] solver = "stratified_change"'),
    ("world", "estimator = 'plain'", 'use [run] solver = "plain_change"'),
])
def test_the_old_solver_keys_are_refused_naming_the_new_key_and_value(tmp_path, kind, text, fix):
    if kind == "display":
        with pytest.raises(ConfigError) as err:
            load_config(f"[run]\n{text}\n")
    else:
        path = _world_dir(tmp_path) / "w.toml"
        path.write_text(WORLD_BASE.replace("[run]\n", f"[run]\n{text}\n") if "[run]\n" in WORLD_BASE
                        else f"[run]\n{text}\n" + WORLD_BASE)
        with pytest.raises(ConfigError) as err:
            load_world_config(path)
    assert fix in str(err.value) and "\n" not in str(err.value)


def test_the_solver_of_a_config_is_a_solver_object_of_its_kind():
    import mincam_sim as ms

    assert load_config("[run]\nsolver = 'aperture'\n").run.solver == ms.Aperture()
    assert isinstance(load_config({}).run.solver, ms.ResponseMap)
    with pytest.raises(ConfigError, match="does not solve display scenes"):
        load_config("[run]\nsolver = 'stratified_change'\n")


def test_a_budget_refuses_fewer_samples_per_texel_than_replicates_in_python_and_toml():
    import mincam_sim as ms
    from mincam_sim.errors import InputError

    with pytest.raises(InputError, match="samples_per_texel = 16 is fewer than its 64 replicates"):
        ms.Budget(samples_per_texel=16, replicates=64)
    with pytest.raises(ConfigError, match=r"\[run\] samples_per_texel = 16 is fewer than its 64 replicates"):
        load_config("[run]\nreplicates = 64\nsamples_per_texel = 16\n")
    from mincam_sim.configuration.schema import IgnoredSettingWarning

    with pytest.warns(IgnoredSettingWarning, match=r"\[run\] samples_per_texel is ignored"):  # not its count
        load_config("[run]\nsolver = 'aperture'\nreplicates = 64\nsamples_per_texel = 16\n")


def test_config_example_prints_each_generated_file():
    runner = CliRunner()
    for flags, text in (([], EXAMPLE_TOML), (["--world"], world_example_toml()),
                        (["--reproduce"], reproduce_example_toml()), (["--study"], study_example_toml())):
        result = runner.invoke(app, ["config-example", *flags])
        assert result.exit_code == 0 and result.output == text, flags
    both = runner.invoke(app, ["config-example", "--world", "--study"])
    assert both.exit_code == 2 and "at most one of" in both.output


@settings(max_examples=300, deadline=None)
@given(value=st.one_of(st.floats(allow_nan=False, allow_infinity=False), st.integers(-2**63, 2**63 - 1),
                       st.booleans(), st.text(max_size=12),
                       st.lists(st.floats(allow_nan=False, allow_infinity=False), max_size=3)))
def test_example_values_are_written_exactly(value):
    assert tomllib.loads(f"x = {toml_value(value)}")["x"] == value


def test_small_floats_are_written_readably():
    assert toml_value(550e-9) == "550e-9" and toml_value(1e-4) == "0.0001" and toml_value(2.5e-7) == "250e-9"
    assert toml_value((0.033, 1 << 23)) == "[0.033, 8388608]"


def test_a_schema_refuses_a_table_where_an_array_of_tables_belongs():
    with pytest.raises(ConfigError, match=r"\[\[world.mover\]\] entries are an array of tables"):
        WORLD_SCHEMA.tables({"world": {"mover": {"id": "a"}}})
    assert isinstance(WORLD_SCHEMA, Schema)


def test_the_world_config_holds_the_movers_and_the_camera(tmp_path):
    """The typed config (what Run's identity reads) holds the trajectory and the camera."""
    path = _world_dir(tmp_path) / "w.toml"
    path.write_text(WORLD_BASE + "[world.camera]\nposition_m = [0, 0, 1]\nlook_at_m = [0, 0, 0]\n")
    cfg = load_world_config(path)
    assert cfg.camera is not None and cfg.camera.position_m == (0.0, 0.0, 1.0)
    np.testing.assert_array_equal(cfg.movers[0].offsets_m, [[0.0, 0.0, 0.0]])


def test_the_world_page_snippet_is_the_shipped_room_config():
    """docs/world.md shows part of scenes/world/room.toml: every key it shows has the file's value."""
    page = (ROOT / "docs" / "world.md").read_text(encoding="utf-8")
    (snippet,) = re.findall(r"```toml\n(.*?)```", page, flags=re.S)
    shown = tomllib.loads(snippet)
    room = tomllib.loads((ROOT / "scenes" / "world" / "room.toml").read_text(encoding="utf-8"))
    for section, keys in shown.items():
        if section == "world":
            movers = keys.pop("mover")
            for mover, shipped in zip(movers, room["world"]["mover"], strict=True):
                assert all(shipped[k] == v for k, v in mover.items()), mover
        for key, value in keys.items():
            assert room[section][key] == value, (section, key)


def test_the_configuration_page_shows_the_generated_examples():
    import importlib.util

    spec = importlib.util.spec_from_file_location("gen_pages", ROOT / "docs" / "gen_pages.py")
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    page = gen.config_reference()
    for text in (EXAMPLE_TOML, world_example_toml(), study_example_toml()):
        assert text.rstrip() in page
    config_md = (ROOT / "docs" / "config.md").read_text(encoding="utf-8")
    assert "literalinclude} ../scenes/experiments/reproduce.toml" in config_md  # the generated file, tested above
