"""Display files that are user mistakes get one ConfigError naming the key: a mincam length near a float's largest
(an OverflowError traceback before) and mixel names that would be written to the same files (one mixel's response
map silently replaced the other's before)."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

import mincam_sim  # noqa: F401  (before Dr.Jit / Mitsuba)
from mincam_sim.configuration.config import load_config
from mincam_sim.errors import ConfigError

CUSTOM = {"layout": "custom"}


@pytest.mark.parametrize(("section", "key"), [("mincam", "d_f_m"), ("mincam", "mask_size_m"),
                                              ("mincam", "detector_size_m"), ("mincam", "spacing_m")])
def test_a_mincam_length_near_a_floats_largest_is_a_config_error_naming_the_key(section, key):
    with pytest.raises(ConfigError, match=rf"^\[{section}\] {key} must be a number <= 100, got 1e\+300$"):
        load_config({section: {key: 1e300}})


@pytest.mark.parametrize(("key", "value", "named"), [("d_f_m", 1e300, "d_f_m"), ("mask_size_m", [1e300, 1e-3],
                                                                                     r"mask_size_m\[0\]"),
                                                    ("mask_size_m", 1e300, "mask_size_m")])
def test_a_mixels_own_length_near_a_floats_largest_is_a_config_error(key, value, named):
    with pytest.raises(ConfigError, match=rf"^\[\[mixel\]\] #1 {named} must be a number <= 100"):
        load_config({"mincam": CUSTOM, "mixel": [{"mask": "ramp:x", key: value}]})


def test_the_render_command_answers_a_huge_d_f_in_one_line(tmp_path):
    from mincam_sim.cli import app

    config = tmp_path / "c.toml"
    config.write_text("[mincam]\nd_f_m = 1e300\n")
    result = CliRunner().invoke(app, ["render", str(config), "--check"])
    assert result.exit_code == 2, result.output
    assert result.output == "error: [mincam] d_f_m must be a number <= 100, got 1e+300\n"


@pytest.mark.parametrize(("names", "pair"), [(("a_b", "a/b"), (1, 2)), (("left", "Left"), (1, 2)),
                                            (("a", None, "M1"), (2, 3))])
def test_mixel_names_that_give_the_same_file_name_are_refused_naming_both_tables(names, pair):
    mixels = [{"mask": "ramp:x", "position_m": [0.01 * i, 0.0, 0.0], **({} if n is None else {"name": n})}
              for i, n in enumerate(names)]
    with pytest.raises(ConfigError, match=rf"^\[\[mixel\]\] #{pair[0]} name .* and #{pair[1]} name .* would "
                                          "write the same files"):
        load_config({"mincam": CUSTOM, "mixel": mixels})


def test_distinct_names_and_exact_duplicates_keep_their_own_answers():
    ok = load_config({"mincam": CUSTOM, "mixel": [{"mask": "ramp:x", "name": "a_b"},
                                                  {"mask": "ramp:x", "name": "a-b", "position_m": [0.01, 0, 0]}]})
    assert [mx.name for mx in ok.mincam] == ["a_b", "a-b"]
    with pytest.raises(ConfigError, match="mixel names must be unique"):
        load_config({"mincam": CUSTOM, "mixel": [{"mask": "ramp:x", "name": "a"},
                                                 {"mask": "ramp:x", "name": "a", "position_m": [0.01, 0, 0]}]})


@pytest.mark.parametrize("key", ["radiance_w_m2_sr", "background_w_m2_sr"])
def test_a_sweep_radiance_beyond_a_float32_is_refused_naming_the_key(key):
    """Before: ``frame 0 contains NaN, infinite, negative or too large ... radiance``, naming no key."""
    with pytest.raises(ConfigError, match=rf"^\[frames\] {key} must be a number <= 3\.40282e\+38, got 1e\+300$"):
        load_config({"frames": {key: 1e300}})
