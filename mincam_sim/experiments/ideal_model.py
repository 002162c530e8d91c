"""Calibrate on a model, test on the physics: what the idealised dot-product model (``DotProduct``) gets wrong.

The paper's two screen calibrations, each fitted on a model's sweep and applied to the physics' sweep
(``ResponseMap``) at the same depth, errors in % of the calibrated field (50 cm at 0.5 m, scaled with depth):

* the **pair** (Sec. 4.1): the 1D intrusion pair (band ramps ``y`` and ``1 - y``, ``spacing_m`` apart), a white
  square swept along the boundary, Eq. 4 and a cubic (the spacing study's sweep and scoring:
  :func:`~mincam_sim.experiments.spacing.boundary_sweep_irradiance`, :func:`~.spacing.boundary_errors`);
* the **cross** (Sec. 4.2): the tracking cross (ramps ``x, 1 - x, y, 1 - y``, each ``spacing_m`` from the centre),
  a grid of white squares clipped to the field's disc, Eq. 7 and a bivariate cubic (the tracking experiment's
  sweep and fit: :func:`~.screen_calibration.screen_sweep_2d`, :func:`~.screen_calibration.fit_calibration_2d`).

The set-up at each depth is ``Setup(spacing_m=..., depth_m=depth, field_m=depth)``: the masks' field and the
calibrated field scale with depth, the band and the squares are 3 cm at 0.5 m scaled with it (the same angles at
every depth; only the spacing is not). Only squares every detector point of every mixel sees whole are kept, as
the screen calibration does. One code path for both layouts: :func:`calibrated_on_models`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from mincam_sim.budget import Budget
from mincam_sim.estimation.calibration import ExtrapolationWarning
from mincam_sim.estimation.estimators import intrusion_position, track_4
from mincam_sim.estimation.metrics import error_rates
from mincam_sim.experiments.layouts import mincam_on_screen, tracking_mincam
from mincam_sim.experiments.screen_calibration import fit_calibration_1d, fit_calibration_2d, screen_sweep_2d
from mincam_sim.experiments.setup import Setup
from mincam_sim.experiments.spacing import boundary_errors, boundary_sweep_irradiance
from mincam_sim.model.geometry import Pose
from mincam_sim.model.optics import seen_whole_by_every_mixel
from mincam_sim.paper import CALIBRATION_DEPTH_M, CALIBRATION_SQUARE_M
from mincam_sim.render.simulation import Simulation
from mincam_sim.scene.display import Screen, Sweep

#: The layouts compared: the intrusion pair (1D) and the tracking cross (2D).
LAYOUTS = ("pair", "cross")
#: The label of the physics calibrated on itself (the calibration's floor) in :attr:`Comparison.errors`.
PHYSICS = "physics"


@dataclass(frozen=True)
class SweepSize:
    """How finely a comparison samples.

    Attributes
    ----------
    positions : int
        Squares along the pair's boundary; the cross's grid has ``positions // 2 + 1`` squares per axis (before
        clipping to the field's disc and to the squares every mixel sees whole).
    samples_per_texel : int
        Response-map samples per screen texel for the physics.
    screen_texels : int
        Texels per side of the square test screen (1.3 times the field).
    """

    positions: int = 41
    samples_per_texel: int = 256
    screen_texels: int = 160

    @property
    def grid_per_axis(self) -> int:
        """The cross's calibration squares per axis."""
        return self.positions // 2 + 1


@dataclass(frozen=True)
class Comparison:
    """One layout at one spacing and depth, calibrated on each model and tested on the physics.

    Attributes
    ----------
    errors : dict
        Label (:data:`PHYSICS` or a model's) -> :func:`~mincam_sim.estimation.metrics.error_rates` of that
        calibration applied to the physics' sweep [% of the field].
    curves : dict
        Label -> (observed, true positions [m]): the sweep the calibration was fitted on (observed: Eq. 4's ratio,
        (n,), or Eq. 7's, (n, 2); true: (n,) along the boundary, or (n, 2)).
    """

    errors: dict
    curves: dict


def scaled_square_m(depth_m: float) -> float:
    """The band and the square [m]: 3 cm at the paper's calibration depth, scaled with depth."""
    return CALIBRATION_SQUARE_M * depth_m / CALIBRATION_DEPTH_M


def depth_setup(spacing_m: float, depth_m: float) -> Setup:
    """The set-up at ``depth_m``: the masks aimed at that depth and the calibrated field scaled with it."""
    return Setup(spacing_m=spacing_m, depth_m=depth_m, field_m=depth_m * Setup().field_m / Setup().depth_m)


def pair_sweep(setup: Setup, size: SweepSize, solver=None) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 4's ratio (n,) of the intrusion pair as the square sweeps the boundary at the set-up's depth, and the
    square's true positions (n,) [m]; ``solver`` None: the physics (response maps)."""
    square_m = scaled_square_m(setup.depth_m)
    irradiance, true_m = boundary_sweep_irradiance(setup, setup.depth_m, size.positions, size.samples_per_texel,
                                                   size.screen_texels, band_m=square_m, square_m=square_m,
                                                   solver=solver, seen_whole=True)
    return intrusion_position(*irradiance.T), true_m


def cross_sweep(setup: Setup, size: SweepSize, solver=None) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 7's ratios (n, 2) of the tracking cross over a grid of squares clipped to the field's disc at the
    set-up's depth (those every mixel sees whole), and the squares' true positions (n, 2) [m]; ``solver`` None:
    the physics (response maps)."""
    cam = mincam_on_screen(tracking_mincam(setup), setup)
    sweep = screen_sweep_2d(setup, size.grid_per_axis, scaled_square_m(setup.depth_m))
    keep = seen_whole_by_every_mixel(cam, sweep.positions_m, 0.5 * sweep.size_m, -setup.depth_m)
    sweep = Sweep(sweep.positions_m[keep], sweep.size_m, sweep.radiance)
    side = 1.3 * setup.field_m
    screen = Screen(side, side, (size.screen_texels, size.screen_texels),
                    Pose((0.0, 0.0, -setup.depth_m), (0.0, 0.0, 1.0)))
    sim = Simulation(cam, screen=screen)
    budget = Budget(samples_per_texel=size.samples_per_texel, seed=setup.seed)
    if solver is None:
        irradiance = sim.response_maps(budget).measure(sweep.frame_stack(screen)).irradiance_w_m2
    else:
        exact = not solver.budget_fields("display")  # the idealised dot product reads no budget
        irradiance = sim.measure(sweep.frame_source(screen), solver, None if exact else budget).irradiance_w_m2
    return track_4(irradiance), sweep.positions_m


def _errors(layout: str, setup: Setup, observed: np.ndarray, true_m: np.ndarray, physics: np.ndarray,
            physics_true_m: np.ndarray) -> dict:
    """The calibration fitted on (observed, true_m), applied to the physics' sweep: error rates [% of the field],
    with ``extrapolated_pct``, the share of the physics' observations outside the fitted range [%] (a model whose
    ratio changes slower than the physics' leaves the physics' ends outside it: they are scored all the same)."""
    fit = fit_calibration_1d if layout == "pair" else fit_calibration_2d
    calibration = fit(observed, true_m, {})
    with warnings.catch_warnings(action="ignore", category=ExtrapolationWarning):  # counted below instead
        if layout == "pair":
            errors = boundary_errors(setup, calibration, physics, physics_true_m, setup.depth_m)[1]
        else:
            errors = error_rates(calibration.apply(physics), physics_true_m, setup.field_m)
    return {**errors, "extrapolated_pct": 100.0 * float(np.mean(calibration.outside_range(physics)))}


def calibrated_on_models(layout: str, spacing_m: float, depth_m: float, models: dict,
                         size: SweepSize = SweepSize()) -> Comparison:
    """Calibrate ``layout`` ("pair" or "cross") on each of ``models`` (label -> display solver, e.g.
    ``DotProduct()``) and on the physics itself, and test every calibration on the physics.

    Parameters
    ----------
    layout : {"pair", "cross"}
        The intrusion pair (1D, Eq. 4) or the tracking cross (2D, Eq. 7).
    spacing_m : float
        The pair's spacing, or each cross mixel's distance from the centre [m] (0: co-located mixels).
    depth_m : float
        Calibration and test depth [m] (:func:`depth_setup`).
    models : dict
        Label -> display solver measuring the same sweep; :data:`PHYSICS` is reserved.
    size : SweepSize
        Positions, samples per texel and screen texels.

    Returns
    -------
    Comparison
        Error rates of every calibration on the physics, and the sweeps they were fitted on.
    """
    if layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {LAYOUTS}, got {layout!r}")
    if PHYSICS in models:
        raise ValueError(f"{PHYSICS!r} is the physics' own label; name the models otherwise")
    setup = depth_setup(spacing_m, depth_m)
    sweep = pair_sweep if layout == "pair" else cross_sweep
    curves = {PHYSICS: sweep(setup, size)}
    curves.update({label: sweep(setup, size, model) for label, model in models.items()})
    physics, physics_true_m = curves[PHYSICS]
    errors = {label: _errors(layout, setup, observed, true_m, physics, physics_true_m)
              for label, (observed, true_m) in curves.items()}
    return Comparison(errors, curves)
