"""Every documented set-up option runs through the tabletop pipeline (the plain dP estimator ended every
tabletop experiment in KeyError: 'rays_per_mixel_per_frame')."""

from __future__ import annotations

import dataclasses

import pytest

from mincam_sim.experiments import Setup, reproduce

SMALL = {"quick": True, "spp": 1 << 15}


@pytest.mark.parametrize("solver", ["plain_change", "stratified_change"])
def test_tracking_runs_with_either_dp_solver(tmp_path, solver):
    results = reproduce(["tracking"], Setup(dp_solver=solver, **SMALL), tmp_path)
    summary = results["tracking"]
    text = repr(summary)
    assert "rays_per_mixel_per_frame" in text and solver in text


# a value other than the default for every Setup field (what the paper leaves open, within its valid range)
OTHER = {"depth_m": 0.45, "spacing_m": 0.03, "d_f_m": 0.0022, "detector_size_m": 1.2e-4, "mask_size_m": 0.0021,
         "mask_resolution": 128, "field_m": 0.45, "bit_depth": 10, "exposure_fill": 0.6,
         "screen_resolution": (192, 108), "table_light_radiance_w_m2_sr": 15.0, "camera_px": 120, "seed": 3}


def test_every_setup_field_is_covered():
    fields = {f.name for f in dataclasses.fields(Setup)} - {"quick", "spp", "dp_solver"}
    assert fields <= set(OTHER), f"Setup fields without a case here: {sorted(fields - set(OTHER))}"


@pytest.mark.slow
@pytest.mark.parametrize("field", sorted(OTHER))
def test_every_setup_option_runs_through_the_pipeline(tmp_path, field):
    results = reproduce(["intrusion", "tracking"], Setup(**{**SMALL, field: OTHER[field]}), tmp_path)
    assert set(results) >= {"intrusion", "tracking"}


def test_quick_over_a_file_that_says_full_is_said():
    """--quick wins over ``[setup] quick = false``, and says so (it was silent)."""
    from mincam_sim.errors import IgnoredSettingWarning
    from mincam_sim.experiments import load_reproduce_config

    with pytest.warns(IgnoredSettingWarning, match=r"\[setup\] quick = false is ignored"):
        setup, _ = load_reproduce_config({"setup": {"quick": False}}, quick=True)
    assert setup.quick
