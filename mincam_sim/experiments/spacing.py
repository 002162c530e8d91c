"""Spacing study: 1D intrusion error against mixel spacing and scene depth, before and after calibration.

For each spacing the two-mixel intrusion mincam (band masks y | 1 - y, paper Fig. 3a) is calibrated on the
screen at the set-up's depth, then a white square is swept along the boundary on screens at other depths (same
angular positions). "Before calibration" maps the observed relative position linearly to the mask's field
``(x_obs - 0.5) * mask_size * d / d_f`` (the ideal co-located mixel); "after" applies the cubic fitted at the
calibration depth, scaled by ``d / calibration_depth``. Errors are % of the calibrated range at each depth.
Measurements are response-map irradiances read out without noise: a sensor that is linear below saturation
scales both mixels alike, so Eq. 4 takes the irradiances' ratio (no gain, dark level or bit depth can enter
it, not even by rounding), and the study isolates geometry: field-of-view offsets, vignetting and the
detector's blur.

As a study target (``[study] experiment = "spacing"``) one point is one (spacing, calibration depth, depth,
sensor) of this same code: the calibration of ``Spacing.calibrate``, the errors of ``Spacing.score``
on the noiseless read-out, and the same errors on a noisy read-out (``noisy_`` metrics, with the sensor's
read noise ``read_noise_e``; :func:`~mincam_sim.model.readout.read_out`: the dark frame is measured with the same
sensor, its mean subtracted, and frames whose change stays within its noise carry no position).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mincam_sim.budget import Budget
from mincam_sim.estimation.calibration import Calibration1D
from mincam_sim.estimation.estimators import intrusion_position
from mincam_sim.estimation.metrics import error_rates
from mincam_sim.experiments.base import Experiment, ExperimentResult
from mincam_sim.experiments.layouts import intrusion_mincam, mincam_on_screen
from mincam_sim.experiments.screen_calibration import fit_calibration_1d, screen_sweep_1d
from mincam_sim.experiments.setup import Setup
from mincam_sim.model.geometry import Pose
from mincam_sim.model.optics import seen_whole_by_every_mixel
from mincam_sim.model.readout import read_out
from mincam_sim.paper import CALIBRATION_SQUARE_M, SPACING_M
from mincam_sim.plotting.plots import plot_spacing
from mincam_sim.progress import progress
from mincam_sim.render.simulation import Simulation
from mincam_sim.scene.display import Screen, Sweep
from mincam_sim.storage.atomic import atomic_write_text


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
    square_m: float = CALIBRATION_SQUARE_M

    def __post_init__(self) -> None:
        if min(self.spacings_m) < 0 or min(self.depths_m) <= 0:
            raise ValueError("spacings_m must be >= 0 and depths_m > 0 metres")
        if self.positions < 5 or self.samples_per_texel < 1 or self.screen_texels < 8:
            raise ValueError("need positions >= 5, samples_per_texel >= 1 and screen_texels >= 8")


def boundary_sweep_irradiance(setup: Setup, depth_m: float, positions: int, samples_per_texel: int,
                              screen_texels: int, boundary_x_m: float = 0.0, band_m: float = 0.03,
                              square_m: float = CALIBRATION_SQUARE_M, solver=None,
                              seen_whole: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Irradiance [W/m^2] (positions, 2) of the intrusion pair of ``setup`` (calibrated for its ``depth_m``) as a
    white square sweeps the boundary on a square screen at ``depth_m`` (geometry scaled with depth), and the
    square's true positions along the boundary [m]. ``solver``: None for the physics (response maps at
    ``samples_per_texel``), or another display solver (e.g. the idealised ``DotProduct``) measuring the same
    sweep. ``seen_whole``: keep only the squares that every detector point of both mixels sees whole (as the
    screen calibration does; :func:`~mincam_sim.model.optics.seen_whole_by_every_mixel`)."""
    scale = depth_m / setup.depth_m
    cam = mincam_on_screen(intrusion_mincam(setup, boundary_x_m, band_m), setup)
    scaled = setup.with_(field_m=setup.field_m * scale)
    sweep = screen_sweep_1d(scaled, boundary_x_m * scale, positions, square_m * scale)
    if seen_whole:
        keep = seen_whole_by_every_mixel(cam, sweep.positions_m, 0.5 * sweep.size_m, -depth_m)
        sweep = Sweep(sweep.positions_m[keep], sweep.size_m, sweep.radiance)
    side = 1.3 * scaled.field_m  # a square display covering the swept boundary at this depth
    screen = Screen(side, side, (screen_texels, screen_texels), Pose((0.0, 0.0, -depth_m), (0.0, 0.0, 1.0)))
    budget = Budget(samples_per_texel=samples_per_texel, seed=setup.seed)
    if solver is not None:
        measured = Simulation(cam, screen=screen).measure(sweep.frame_source(screen), solver,
                                                          budget if solver.budget_fields("display") else None)
        return measured.irradiance_w_m2, sweep.positions_m[:, 1]
    maps = Simulation(cam, screen=screen).response_maps(budget)
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
    quick_overrides = {"spacings_m": (0.0, 0.02, SPACING_M, 0.06, 0.1), "depths_m": (0.5, 1.0), "positions": 21,
                       "samples_per_texel": 16}
    #: A study point's sweep: these fields of ``Params`` in quick mode (full mode: the defaults).
    study_quick_overrides = {"positions": 15, "samples_per_texel": 16, "screen_texels": 96}
    study_metrics = tuple(f"{p}{k}" for p in ("", "noisy_") for k in ("avg_before_pct", "max_before_pct",
                                                                      "avg_after_pct", "max_after_pct", "missing_pct"))
    study_seconds = (2.0, 10.0)
    version = 2  # 2: the noiseless read-out is the irradiances' ratio (was: through the sensor's DN, same to 1e-13)

    def scene(self, setup: Setup, params: SpacingParams, rng: np.random.Generator) -> None:
        """White squares on screens, built per depth by :func:`boundary_sweep_irradiance`."""
        return None

    def sweep(self, setup: Setup, params: SpacingParams, depth_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Irradiance [W/m^2] (positions, 2) of the boundary sweep on the screen at ``depth_m`` and the square's
        true positions [m] (:func:`boundary_sweep_irradiance` with the sizes of ``params``)."""
        return boundary_sweep_irradiance(setup, depth_m, params.positions, params.samples_per_texel,
                                         params.screen_texels, params.boundary_x_m, params.band_m, params.square_m)

    def observe(self, irradiance: np.ndarray) -> np.ndarray:
        """Relative positions (Eq. 4) of the noiseless read-out (frames with nothing in view: NaN): the ratio of
        the irradiances, which a sensor linear below saturation (dark level subtracted) reads unchanged."""
        return intrusion_position(irradiance[:, 0], irradiance[:, 1])

    def observe_noisy(self, setup: Setup, irradiance: np.ndarray, read_noise_e: float,
                      rng: np.random.Generator) -> np.ndarray:
        """Relative positions read through the noisy sensor (read noise ``read_noise_e`` [e-]): the dark frame
        (the black screen) measured with the same sensor and subtracted, frames whose change stays within its
        noise without a position (NaN)."""
        sensor = dataclasses.replace(setup.sensor(), read_noise_e=float(read_noise_e))
        dark = np.zeros(irradiance.shape[1])  # the black screen: the sensor's dark level and noise only
        readout = read_out(irradiance, dark, sensor, rng, setup.exposure_fill)
        return intrusion_position(readout.change_dn[:, 0], readout.change_dn[:, 1], readout.threshold_dn)

    def _observe(self, setup: Setup, params: SpacingParams, depth_m: float) -> tuple[np.ndarray, np.ndarray]:
        irradiance, true = self.sweep(setup, params, depth_m)
        return self.observe(irradiance), true

    def calibrate(self, setup: Setup, params: SpacingParams, rng: np.random.Generator | None = None,
                  out_dir: Path | None = None) -> Calibration1D:
        """The cubic fitted on the noiseless sweep at the set-up's depth."""
        observed, true = self._observe(setup, params, setup.depth_m)
        return fit_calibration_1d(observed, true, {"spacing_m": setup.spacing_m})

    def score(self, setup: Setup, calibration: Calibration1D, observed: np.ndarray, true_m: np.ndarray,
              depth_m: float) -> dict:
        """Average and maximum error [% of the range] before and after the calibration, and the share of the
        positions without an observation (``missing_pct``; None when all have one)."""
        before, after = boundary_errors(setup, calibration, observed, true_m, depth_m)
        return {"avg_before_pct": before["avg_error_pct"], "max_before_pct": before["max_error_pct"],
                "avg_after_pct": after["avg_error_pct"], "max_after_pct": after["max_error_pct"],
                "missing_pct": after.get("missing_pct")}

    def run(self, setup: Setup, params: SpacingParams, out_dir: Path,
            show_progress: bool = False) -> ExperimentResult:
        out_dir.mkdir(parents=True, exist_ok=True)
        keys = ("avg_before_pct", "max_before_pct", "avg_after_pct", "max_after_pct")
        by_depth: dict = {str(d): {k: [] for k in keys} for d in params.depths_m}
        for spacing in progress(params.spacings_m, desc="spacings", disable=not show_progress):
            s = setup.with_(spacing_m=float(spacing))
            cal = self.calibrate(s, params)
            for depth in params.depths_m:
                scores = self.score(s, cal, *self._observe(s, params, depth), depth)
                for key in keys:
                    by_depth[str(depth)][key].append(scores[key])
        study = {"spacing_m": list(params.spacings_m), "depths_m": list(params.depths_m),
                 "calibration_depth_m": setup.depth_m, "positions_per_sweep": params.positions,
                 "by_depth": by_depth, "setup": setup.as_dict()}
        atomic_write_text(out_dir / "spacing_study.json", json.dumps(study, indent=1, default=float))
        plot_spacing(study, out_dir / "spacing_study.png")
        return ExperimentResult(self.name, None, None, None, None, study)

    # ------------------------------------------------------------------------------------- as a study target
    def study_parameters(self) -> dict:
        """One (spacing, depth) of the experiment, calibrated at ``calibration_depth_m``, with the mixel geometry
        and the sensor's bit depth and read noise (defaults: the set-up's)."""
        s = Setup()
        return {"spacing_m": s.spacing_m, "depth_m": s.depth_m, "calibration_depth_m": s.depth_m,
                "d_f_m": s.d_f_m, "detector_size_m": s.detector_size_m, "bit_depth": s.bit_depth,
                "read_noise_e": s.sensor().read_noise_e}

    def study_setup(self, params: dict, seed: int, quick: bool) -> tuple[Setup, SpacingParams]:
        """The set-up (at the calibration depth) and the sweep of the study point ``params``."""
        setup = Setup(depth_m=float(params["calibration_depth_m"]), spacing_m=float(params["spacing_m"]),
                      d_f_m=float(params["d_f_m"]), detector_size_m=float(params["detector_size_m"]),
                      bit_depth=int(params["bit_depth"]), seed=seed, quick=quick)
        sweep = SpacingParams(spacings_m=(setup.spacing_m,), depths_m=(float(params["depth_m"]),))
        if quick:
            sweep = dataclasses.replace(sweep, **self.study_quick_overrides)
        return setup, sweep

    def study_check(self, params: dict, quick: bool) -> None:
        """A point's set-up and sweep built as :meth:`study_point` builds them (their checks), nothing computed."""
        self.study_setup(params, 0, quick)

    def study_point(self, params: dict, seed: int, quick: bool) -> dict:
        """Errors before / after the calibration at ``depth_m``, noiseless (the experiment's own numbers for this
        set-up) and through the noisy sensor (``noisy_``; its noise drawn from ``seed``)."""
        setup, sweep = self.study_setup(params, seed, quick)
        depth = float(params["depth_m"])
        calibration = self.calibrate(setup, sweep)
        irradiance, true = self.sweep(setup, sweep, depth)
        noisy = self.observe_noisy(setup, irradiance, float(params["read_noise_e"]), np.random.default_rng(seed))
        out = {}
        for label, observed in (("", self.observe(irradiance)), ("noisy_", noisy)):
            out.update({f"{label}{k}": v for k, v in self.score(setup, calibration, observed, true, depth).items()})
        return {k: (np.nan if v is None else float(v)) for k, v in out.items()}

    def study_description(self) -> str:
        return ("1D intrusion error on a screen vs mincam geometry and sensor noise (calibrated at one depth, "
                "used at another): the spacing experiment, one point per set-up")
