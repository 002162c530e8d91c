"""What one study point computes: ``point(params, seed, quick) -> {metric: value}`` (plain floats).

A point function is a pure function of its parameters and seed (so a point gives the same numbers on any
worker, in any order). Each one declares its parameters with defaults and units, and the metrics it returns.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

PointFunction = Callable[[dict, int, bool], dict]


@dataclass(frozen=True)
class StudyExperiment:
    """A study-able experiment: its point function, parameters (name -> default) and metric names."""

    name: str
    description: str
    parameters: dict
    metrics: tuple[str, ...]
    point: PointFunction


def _intrusion_point(params: dict, seed: int, quick: bool) -> dict:
    """Two-mixel intrusion (band masks y | 1 - y) calibrated on a screen at ``calibration_depth_m``, then a
    white square swept along the boundary on a screen at ``depth_m``: position errors (% of the calibrated
    range at that depth) before / after the cubic calibration, noiseless and through the sensor model."""
    from ..estimators import intrusion_position
    from ..experiments import Setup
    from ..experiments.screen_calibration import fit_calibration_1d
    from ..experiments.spacing import boundary_errors, boundary_sweep_irradiance

    setup = Setup(depth_m=float(params["calibration_depth_m"]), spacing_m=float(params["spacing_m"]),
                  d_f_m=float(params["d_f_m"]), detector_size_m=float(params["detector_size_m"]),
                  bit_depth=int(params["bit_depth"]), seed=seed, quick=quick)
    sweep = {"positions": 15 if quick else 41, "samples_per_texel": 16 if quick else 64,
             "screen_texels": 96 if quick else 160}
    irr_cal, true_cal = boundary_sweep_irradiance(setup, setup.depth_m, **sweep)
    cal = fit_calibration_1d(intrusion_position(irr_cal[:, 0], irr_cal[:, 1]), true_cal,
                             {"spacing_m": setup.spacing_m})
    depth = float(params["depth_m"])
    irr, true = boundary_sweep_irradiance(setup, depth, **sweep)
    sensor = setup.sensor().auto_exposed(float(irr.max()), setup.exposure_fill)
    sensor = replace(sensor, read_noise_e=float(params["read_noise_e"]))
    noisy = sensor.measure(irr, np.random.default_rng(seed))
    out = {}
    for label, values in (("", irr), ("noisy_", noisy)):
        before, after = boundary_errors(setup, cal, intrusion_position(values[:, 0], values[:, 1]), true, depth)
        out[f"{label}avg_before_pct"] = float(before["avg_error_pct"])
        out[f"{label}max_before_pct"] = float(before["max_error_pct"])
        out[f"{label}avg_after_pct"] = float(after["avg_error_pct"])
        out[f"{label}max_after_pct"] = float(after["max_error_pct"])
    return out


INTRUSION = StudyExperiment(
    name="intrusion",
    description="1D intrusion error vs mincam geometry and sensor noise (calibrated at one depth, used at another)",
    parameters={"spacing_m": 0.033, "depth_m": 0.5, "calibration_depth_m": 0.5, "d_f_m": 2e-3,
                "detector_size_m": 1e-4, "bit_depth": 12, "read_noise_e": 2.5},
    metrics=tuple(f"{p}{k}" for p in ("", "noisy_") for k in ("avg_before_pct", "max_before_pct", "avg_after_pct",
                                                              "max_after_pct")),
    point=_intrusion_point,
)

#: The experiments a study can sweep, by name (an explicit registry: nothing is loaded by name).
STUDY_EXPERIMENTS: dict[str, StudyExperiment] = {INTRUSION.name: INTRUSION}
