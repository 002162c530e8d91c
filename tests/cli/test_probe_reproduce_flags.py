"""``reproduce`` options with values out of any range: one line naming the option as typed. Before, a huge
``--seed`` or ``--bit-depth`` was named ``[command line] seed``, and ``--spacing-m 1e300`` printed an overflow
warning and blamed ``[setup] detector_size_m = 0.0001, mask_size_m = 0.002``."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

import mincam_sim  # noqa: F401  (before Dr.Jit / Mitsuba)
from mincam_sim.errors import ConfigError


@pytest.mark.parametrize(("args", "line"), [
    (["--seed", "99999999999999999999999"], "error: --seed must be at most 9223372036854775807, got "
                                             "99999999999999999999999"),
    (["--bit-depth", "99999999999999999999999"], "error: --bit-depth must be at most 9223372036854775807, got "
                                                  "99999999999999999999999"),
    (["--spacing-m", "1e300"], "error: [setup] spacing_m (--spacing-m) = 1e+300 m: a mincam's lengths are at most "
                               "100 m; give it in metres (the default: 0.033 m)"),
])
def test_an_option_out_of_any_range_is_one_line_naming_it(tmp_path, args, line):
    from mincam_sim.cli import app

    out = tmp_path / "repro"
    result = CliRunner().invoke(app, ["reproduce", "--quick", "--out", str(out), *args])
    assert result.exit_code == 2, result.output
    assert result.output.splitlines() == [line]
    assert not out.exists()


def test_a_mincam_the_layout_refuses_names_every_length_of_the_setup():
    from mincam_sim.experiments.input_checks import check_reproduce
    from mincam_sim.experiments.setup import Setup

    with pytest.raises(ConfigError, match=r"^\[setup\] detector_size_m = 0\.003, mask_size_m = 0\.002, d_f_m = "
                                          r"0\.002, spacing_m = 0\.033: "):
        check_reproduce(Setup(detector_size_m=0.003), {})


def test_a_table_light_too_bright_is_named_as_too_bright():
    """Before: ``give the table's light a radiance > 0`` for a radiance of 1e300."""
    from mincam_sim.experiments.input_checks import check_reproduce
    from mincam_sim.experiments.setup import Setup

    with pytest.raises(ConfigError, match=r"^\[setup\] table_light_radiance_w_m2_sr = 1e\+300: give the table's "
                                          r"light a radiance below 1e\+30 W m\^-2 sr\^-1"):
        check_reproduce(Setup(table_light_radiance_w_m2_sr=1e300), {})
    with pytest.raises(ConfigError, match=r"radiance > 0"):
        check_reproduce(Setup(table_light_radiance_w_m2_sr=0.0), {})
