"""Spacing study: 1D intrusion error against mixel spacing and scene depth, before and after calibration.

For each spacing the two-mixel intrusion mincam (band masks y | 1 - y, paper Fig. 3a) is calibrated on the
screen at ``calibration_depth_m``, then a white square is swept along the boundary on screens at other
depths (same angular positions). "Before calibration" maps the observed relative position linearly to the
mask's field ``(x_obs - 0.5) * mask_size * d / d_f`` (the ideal co-located mixel); "after" applies the cubic
fitted at the calibration depth, scaled by ``d / calibration_depth``. Errors are % of the calibrated range
at each depth. Measurements are response-map irradiances through the noiseless sensor (``expected``), so the
study isolates geometry: field-of-view offsets, vignetting and the detector's blur.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..estimators import intrusion_position
from ..geometry import Pose
from ..metrics import error_rates
from ..progress import progress
from ..screen import Screen
from .common import Setup, fit_calibration_1d, intrusion_mincam, mincam_on_screen, screen_sweep_1d

BOUNDARY_X_M = 0.0


def _observe(setup: Setup, spacing_m: float, depth_m: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    from ..render.screen_engine import response_maps

    scale = depth_m / setup.depth_m
    s = setup.with_(spacing_m=spacing_m)
    cam = mincam_on_screen(intrusion_mincam(s, BOUNDARY_X_M, 0.03), s)
    scaled = s.with_(field_m=setup.field_m * scale)
    sweep = screen_sweep_1d(scaled, BOUNDARY_X_M * scale, n, 0.03 * scale)
    side = 1.3 * scaled.field_m  # a square display covering the swept boundary at this depth
    screen = Screen(side, side, (160, 160), Pose((0.0, 0.0, -depth_m), (0.0, 0.0, 1.0)))
    maps = response_maps(cam, screen, samples_per_texel=16 if setup.quick else 64, seed=setup.seed)
    irradiance = maps.measure(sweep.frame_stack(screen)).irradiance_w_m2
    dn = setup.sensor().auto_exposed(float(irradiance.max()), setup.exposure_fill).expected(irradiance)
    return intrusion_position(dn[:, 0], dn[:, 1]), sweep.positions_m[:, 1]


def run(setup: Setup, out_dir: Path, show_progress: bool = False) -> dict:
    from ..plots import plot_spacing

    out_dir.mkdir(parents=True, exist_ok=True)
    spacings = np.array([0.0, 0.02, 0.033, 0.06, 0.1]) if setup.quick else np.arange(0.0, 0.1001, 0.01)
    depths = (0.5, 1.0) if setup.quick else (0.3, 0.5, 1.0)
    n = 21 if setup.quick else 41
    by_depth: dict = {str(d): {k: [] for k in ("avg_before_pct", "max_before_pct", "avg_after_pct",
                                               "max_after_pct")} for d in depths}
    for spacing in progress(spacings, desc="spacings", disable=not show_progress):
        obs_cal, true_cal = _observe(setup, float(spacing), setup.depth_m, n)
        cal = fit_calibration_1d(obs_cal, true_cal, {"spacing_m": float(spacing)})
        for depth in depths:
            obs, true = _observe(setup, float(spacing), depth, n)
            scale = depth / setup.depth_m
            field = setup.field_m * scale
            before = (obs - 0.5) * setup.mask_size_m * depth / setup.d_f_m
            after = cal.apply(obs) * scale
            ok = np.isfinite(obs)
            e_before = error_rates(before[ok], true[ok], field)
            e_after = error_rates(after[ok], true[ok], field)
            rows = by_depth[str(depth)]
            rows["avg_before_pct"].append(e_before["avg_error_pct"])
            rows["max_before_pct"].append(e_before["max_error_pct"])
            rows["avg_after_pct"].append(e_after["avg_error_pct"])
            rows["max_after_pct"].append(e_after["max_error_pct"])
    study = {"spacing_m": spacings.tolist(), "depths_m": list(depths), "calibration_depth_m": setup.depth_m,
             "positions_per_sweep": n, "by_depth": by_depth, "setup": setup.as_dict()}
    (out_dir / "spacing_study.json").write_text(json.dumps(study, indent=1, default=float))
    plot_spacing(study, out_dir / "spacing_study.png")
    return study
