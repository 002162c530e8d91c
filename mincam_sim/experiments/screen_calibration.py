"""Calibration on the 50" screen (paper Sec. 4.1.1, 4.2.1): white squares at known positions, rendered through
the mincam turned to the screen, read out with the sensor, and a cubic fitted from observed to true position."""

from __future__ import annotations

import numpy as np

from mincam_sim.budget import Budget
from mincam_sim.errors import ConfigError
from mincam_sim.estimation.calibration import Calibration1D, Calibration2D
from mincam_sim.experiments.layouts import mincam_on_screen
from mincam_sim.experiments.setup import Setup
from mincam_sim.model.optics import seen_whole_by_every_mixel
from mincam_sim.model.readout import read_out
from mincam_sim.render.simulation import Simulation
from mincam_sim.render.solvers import ResponseMap
from mincam_sim.scene.display import Sweep, grid_sweep, line_sweep


def screen_sweep_1d(setup: Setup, boundary_x_m: float, n: int, square_m: float) -> Sweep:
    """White squares along the boundary line ``x = boundary_x_m`` over the calibrated range (paper Fig. 4a)."""
    half = setup.field_m / 2
    return line_sweep((boundary_x_m, -half), (boundary_x_m, half), n, square_m)


def screen_sweep_2d(setup: Setup, n_per_axis: int, square_m: float) -> Sweep:
    """White squares on a grid clipped to the 50 cm diameter field (paper Sec. 4.2.1)."""
    half = setup.field_m / 2
    sweep = grid_sweep((-half, half), (-half, half), n_per_axis, n_per_axis, square_m)
    keep = np.hypot(*sweep.positions_m.T) <= half + 1e-9
    return Sweep(sweep.positions_m[keep], square_m)


def seen_by_every_mixel(mincam, setup: Setup, sweep: Sweep) -> np.ndarray:
    """Boolean mask of the sweep's squares that every mixel sees whole through its full aperture.

    ``mincam`` is the experiment's mincam (turned to the screen here). A screen point at distance ``d`` is seen
    by every point of a mixel's detector, through the mask, within ``|x - p_x| <= d tan_x`` with
    ``tan_x = (mask_width - detector_size) / (2 d_f)`` (and likewise in y); beyond that lies the penumbra, where
    the housing cuts the view until, at ``(mask_width + detector_size) / (2 d_f)``
    (:meth:`~mincam_sim.model.optics.Mixel.half_fov_tan`), nothing is seen. Eq. 4 / 7 assume every mixel sees the
    whole change: a square in one mixel's penumbra or out of its view reads a ratio folded towards the wrong
    end (with the tracking cross at 0.5 m, the square at x = -25 cm, out of the right-hand 1 - x mixel's view,
    read x_obs = 1), and such points corrupt the whole cubic fit, so the calibration leaves them out.
    """
    centres = np.asarray(sweep.positions_m, dtype=np.float64)
    return seen_whole_by_every_mixel(mincam_on_screen(mincam, setup), centres, 0.5 * sweep.size_m, -setup.depth_m)


def visible_sweep(mincam, setup: Setup, sweep: Sweep) -> tuple[Sweep, int]:
    """The squares of ``sweep`` that every mixel sees whole (:func:`seen_by_every_mixel`) and how many were
    left out; refuses a sweep left with fewer than 10 squares."""
    keep = seen_by_every_mixel(mincam, setup, sweep)
    if keep.sum() < 10:
        raise ConfigError(f"only {int(keep.sum())} of {len(keep)} calibration squares lie inside every mixel's field "
                          "of view: reduce [setup] spacing_m or field_m or the calibration square, move the screen "
                          "further away ([setup] depth_m), or bring the sweep into view (for intrusion it runs along "
                          "[intrusion] boundary_x_m, which must lie inside the field)")
    return Sweep(sweep.positions_m[keep], sweep.size_m, sweep.radiance), int((~keep).sum())


def sweep_change_dn(mincam, setup: Setup, sweep: Sweep, rng: np.random.Generator,
                    target_rel_stderr: float) -> tuple[np.ndarray, float]:
    """Read-out change [DN] of every sweep position (rows) and mixel (columns) on the set-up's screen, rendered
    with response maps to ``target_rel_stderr``; returns it with the worst relative standard error reached."""
    screen = setup.screen()
    sim = Simulation(mincam_on_screen(mincam, setup), screen=screen)
    m = sim.measure(sweep.frame_source(screen), ResponseMap(),
                    Budget(target_rel_stderr=target_rel_stderr, seed=setup.seed))
    readout = read_out(m.irradiance_w_m2, np.zeros(len(mincam)), setup.sensor(), rng, setup.exposure_fill)
    return readout.change_dn, float(m.meta["reached_rel_stderr"])


def fit_calibration_1d(observed: np.ndarray, true_m: np.ndarray, meta: dict) -> Calibration1D:
    """Cubic ``true_m = f(observed)`` over the finite observations."""
    ok = np.isfinite(observed)
    return Calibration1D.fit(observed[ok], true_m[ok], degree=3, metadata=meta)


def fit_calibration_2d(observed: np.ndarray, true_m: np.ndarray, meta: dict) -> Calibration2D:
    """Bivariate cubic ``(x_m, y_m) = f(observed)`` over the finite observations."""
    ok = np.all(np.isfinite(observed), axis=1)
    return Calibration2D.fit(observed[ok], true_m[ok], degree=3, metadata=meta)
