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
    from ..experiments.common import Setup, fit_calibration_1d, intrusion_mincam, mincam_on_screen, screen_sweep_1d
    from ..geometry import Pose
    from ..metrics import error_rates
    from ..render.screen_engine import response_maps
    from ..screen import Screen

    setup = Setup(depth_m=float(params["calibration_depth_m"]), spacing_m=float(params["spacing_m"]),
                  d_f_m=float(params["d_f_m"]), detector_size_m=float(params["detector_size_m"]),
                  bit_depth=int(params["bit_depth"]), seed=seed, quick=quick)
    n = 15 if quick else 41
    spt = 16 if quick else 64

    def observe(depth_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        scale = depth_m / setup.depth_m
        cam = mincam_on_screen(intrusion_mincam(setup, 0.0, 0.03), setup)
        scaled = setup.with_(field_m=setup.field_m * scale)
        sweep = screen_sweep_1d(scaled, 0.0, n, 0.03 * scale)
        side = 1.3 * scaled.field_m
        screen = Screen(side, side, (96, 96) if quick else (160, 160), Pose((0.0, 0.0, -depth_m), (0.0, 0.0, 1.0)))
        irradiance = response_maps(cam, screen, samples_per_texel=spt, seed=seed).measure(
            sweep.frame_stack(screen)).irradiance_w_m2
        sensor = setup.sensor().auto_exposed(float(irradiance.max()), setup.exposure_fill)
        sensor = replace(sensor, read_noise_e=float(params["read_noise_e"]))
        noisy = sensor.measure(irradiance, np.random.default_rng(seed))
        return irradiance, noisy, sweep.positions_m[:, 1]

    irr_cal, _, true_cal = observe(setup.depth_m)
    obs_cal = intrusion_position(irr_cal[:, 0], irr_cal[:, 1])
    ok = np.isfinite(obs_cal)
    cal = fit_calibration_1d(obs_cal[ok], true_cal[ok], {"spacing_m": setup.spacing_m})
    depth = float(params["depth_m"])
    irr, noisy, true = observe(depth)
    scale = depth / setup.depth_m
    field = setup.field_m * scale
    out = {}
    for label, values in (("", irr), ("noisy_", noisy)):
        obs = intrusion_position(values[:, 0], values[:, 1])
        good = np.isfinite(obs)
        before = (obs - 0.5) * setup.mask_size_m * depth / setup.d_f_m
        after = cal.apply(obs) * scale
        e_before = error_rates(before[good], true[good], field)
        e_after = error_rates(after[good], true[good], field)
        out[f"{label}avg_before_pct"] = float(e_before["avg_error_pct"])
        out[f"{label}max_before_pct"] = float(e_before["max_error_pct"])
        out[f"{label}avg_after_pct"] = float(e_after["avg_error_pct"])
        out[f"{label}max_after_pct"] = float(e_after["max_error_pct"])
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
