"""A study whose render config (``[study] config``) has a mistake: the one error line names that file as well as
the key; before, it named the key alone (``unknown section [wrld] ...``), as if the study file were wrong."""

from __future__ import annotations

import pytest

from mincam_sim.errors import ConfigError
from mincam_sim.studies import load_study


@pytest.mark.parametrize(("text", "problem"), [
    ("[wrld]\n", r"unknown section \[wrld\]"),
    ("[mincam]\nd_f_m = -1\n", r"\[mincam\] d_f_m must be a number > 0"),
])
def test_a_mistake_in_the_render_config_names_the_file(tmp_path, text, problem):
    config = tmp_path / "sweep.toml"
    config.write_text(text)
    spec = {"study": {"name": "t", "experiment": "render", "config": str(config)},
            "grid": {"mincam.spacing_m": [0.03, 0.04]}}
    with pytest.raises(ConfigError, match=rf"^\[study\] config = '{config}': {problem}") as err:
        load_study(spec, quick=True)
    assert "\n" not in str(err.value)


def test_a_missing_render_config_keeps_its_own_message(tmp_path):
    spec = {"study": {"name": "t", "experiment": "render", "config": str(tmp_path / "nope.toml")},
            "grid": {"mincam.spacing_m": [0.03]}}
    with pytest.raises(ConfigError, match=r"^\[study\] config = '.*nope.toml': no such render config file$"):
        load_study(spec, quick=True)
