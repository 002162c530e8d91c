"""Spacing study: 1D intrusion error against mixel spacing and scene depth, before and after calibration.

For each spacing the two-mixel intrusion mincam (band masks y | 1 - y, paper Fig. 3a) is calibrated on the
screen at the set-up's depth, then a white square is swept along the boundary on screens at other depths (same
angular positions). "Before calibration" maps the observed relative position linearly to the mask's field
``(x_obs - 0.5) * mask_size * d / d_f`` (the ideal co-located mixel); "after" applies the cubic fitted at the
calibration depth, scaled by ``d / calibration_depth``. Errors are % of the calibrated range at each depth.
Measurements are response-map irradiances through the noiseless sensor (``expected``), so the study isolates
geometry: field-of-view offsets, vignetting and the detector's blur.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..calibration import Calibration1D
from ..estimators import intrusion_position
from ..geometry import Pose
from ..metrics import error_rates
from ..plots import plot_spacing
from ..progress import progress
from ..render.screen_engine import response_maps
from ..scene.display import Screen
from .base import Experiment, ExperimentResult
from .layouts import intrusion_mincam, mincam_on_screen
from .screen_calibration import fit_calibration_1d, screen_sweep_1d
from .setup import Setup


@dataclass(frozen=True)
class SpacingParams:
    """Parameters of the spacing study (``[spacing]`` in a reproduce config).

    Attributes
    ----------
    spacings_m : tuple of float
        Mixel spacings [m].
    depths_m : tuple of float
        Screen depths the calibrated mincam is used at [m] (calibration at the set-up's ``depth_m``).
    positions : int
        Square positions per sweep.
    samples_per_texel : int
        Response-map samples per screen texel.
    screen_texels : int
        Texels per side of the square test screen.
    boundary_x_m, band_m, square_m : float
        The boundary line, the masks' band and the swept square at the calibration depth [m].
    """

    spacings_m: tuple[float, ...] = tuple(np.round(np.arange(0.0, 0.1001, 0.01), 3).tolist())
    depths_m: tuple[float, ...] = (0.3, 0.5, 1.0)
    positions: int = 41
    samples_per_texel: int = 64
    screen_texels: int = 160
    boundary_x_m: float = 0.0
    band_m: float = 0.03
    square_m: float = 0.03

    def __post_init__(self) -> None:
        if min(self.spacings_m) < 0 or min(self.depths_m) <= 0:
            raise ValueError("spacings_m must be >= 0 and depths_m > 0 metres")
        if self.positions < 5 or self.samples_per_texel < 1 or self.screen_texels < 8:
            raise ValueError("need positions >= 5, samples_per_texel >= 1 and screen_texels >= 8")


def boundary_sweep_irradiance(setup: Setup, depth_m: float, positions: int, samples_per_texel: int,
                              screen_texels: int, boundary_x_m: float = 0.0, band_m: float = 0.03,
                              square_m: float = 0.03) -> tuple[np.ndarray, np.ndarray]:
    """Irradiance [W/m^2] (positions, 2) of the intrusion pair of ``setup`` (calibrated for its ``depth_m``) as a
    white square sweeps the boundary on a square screen at ``depth_m`` (geometry scaled with depth), and the
    square's true positions along the boundary [m]."""
    scale = depth_m / setup.depth_m
    cam = mincam_on_screen(intrusion_mincam(setup, boundary_x_m, band_m), setup)
    scaled = setup.with_(field_m=setup.field_m * scale)
    sweep = screen_sweep_1d(scaled, boundary_x_m * scale, positions, square_m * scale)
    side = 1.3 * scaled.field_m  # a square display covering the swept boundary at this depth
    screen = Screen(side, side, (screen_texels, screen_texels), Pose((0.0, 0.0, -depth_m), (0.0, 0.0, 1.0)))
    maps = response_maps(cam, screen, samples_per_texel=samples_per_texel, seed=setup.seed)
    return maps.measure(sweep.frame_stack(screen)).irradiance_w_m2, sweep.positions_m[:, 1]


def boundary_errors(setup: Setup, calibration: Calibration1D, observed: np.ndarray, true_m: np.ndarray,
                    depth_m: float) -> tuple[dict, dict]:
    """Error rates at ``depth_m`` before (ideal co-located mixel) and after the calibration fitted at the
    set-up's depth, as % of the calibrated range scaled to that depth."""
    scale = depth_m / setup.depth_m
    before = (observed - 0.5) * setup.mask_size_m * depth_m / setup.d_f_m
    after = calibration.apply(observed) * scale
    field = setup.field_m * scale  # positions without an observation (NaN) count as n_missing, not scored
    return error_rates(before, true_m, field), error_rates(after, true_m, field)


class Spacing(Experiment):
    """How far apart mixels may sit: intrusion error vs spacing and depth (not in the paper)."""

    name = "spacing"
    paper_section = "- (extends 4.1: the paper's mixels are 3.3 cm apart)"
    in_paper = False
    Params = SpacingParams
    quick_overrides = {"spacings_m": (0.0, 0.02, 0.033, 0.06, 0.1), "depths_m": (0.5, 1.0), "positions": 21,
                       "samples_per_texel": 16}

    def scene(self, setup: Setup, params: SpacingParams, rng: np.random.Generator) -> None:
        """White squares on screens, built per depth by :func:`boundary_sweep_irradiance`."""
        return None

    def _observe(self, setup: Setup, params: SpacingParams, depth_m: float) -> tuple[np.ndarray, np.ndarray]:
        irradiance, true = boundary_sweep_irradiance(setup, depth_m, params.positions, params.samples_per_texel,
                                                     params.screen_texels, params.boundary_x_m, params.band_m,
                                                     params.square_m)
        sensor = setup.sensor().auto_exposed(float(irradiance.max()), setup.exposure_fill)
        dn = sensor.expected(irradiance) - sensor.expected(np.zeros(irradiance.shape[1]))  # minus the dark level
        return intrusion_position(dn[:, 0], dn[:, 1]), true

    def run(self, setup: Setup, params: SpacingParams, out_dir: Path,
            show_progress: bool = False) -> ExperimentResult:
        out_dir.mkdir(parents=True, exist_ok=True)
        keys = ("avg_before_pct", "max_before_pct", "avg_after_pct", "max_after_pct")
        by_depth: dict = {str(d): {k: [] for k in keys} for d in params.depths_m}
        for spacing in progress(params.spacings_m, desc="spacings", disable=not show_progress):
            s = setup.with_(spacing_m=float(spacing))
            obs_cal, true_cal = self._observe(s, params, s.depth_m)
            cal = fit_calibration_1d(obs_cal, true_cal, {"spacing_m": float(spacing)})
            for depth in params.depths_m:
                obs, true = self._observe(s, params, depth)
                before, after = boundary_errors(s, cal, obs, true, depth)
                rows = by_depth[str(depth)]
                rows["avg_before_pct"].append(before["avg_error_pct"])
                rows["max_before_pct"].append(before["max_error_pct"])
                rows["avg_after_pct"].append(after["avg_error_pct"])
                rows["max_after_pct"].append(after["max_error_pct"])
        study = {"spacing_m": list(params.spacings_m), "depths_m": list(params.depths_m),
                 "calibration_depth_m": setup.depth_m, "positions_per_sweep": params.positions,
                 "by_depth": by_depth, "setup": setup.as_dict()}
        (out_dir / "spacing_study.json").write_text(json.dumps(study, indent=1, default=float))
        plot_spacing(study, out_dir / "spacing_study.png")
        return ExperimentResult(self.name, None, None, None, None, study)
