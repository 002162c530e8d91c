"""Calibration on the 50" screen (paper Sec. 4.1.1, 4.2.1): white squares at known positions, rendered through
the mincam turned to the screen, read out with the sensor, and a cubic fitted from observed to true position."""

from __future__ import annotations

import numpy as np

from ..calibration import Calibration1D, Calibration2D
from ..readout import read_out
from ..render.screen_engine import render_frames
from ..scene.display import Sweep, grid_sweep, line_sweep
from .layouts import mincam_on_screen
from .setup import Setup


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


def sweep_change_dn(mincam, setup: Setup, sweep: Sweep, rng: np.random.Generator,
                    target_rel_stderr: float) -> tuple[np.ndarray, float]:
    """Read-out change [DN] of every sweep position (rows) and mixel (columns) on the set-up's screen, rendered
    with response maps to ``target_rel_stderr``; returns it with the worst relative standard error reached."""
    screen = setup.screen()
    m, _ = render_frames(mincam_on_screen(mincam, setup), screen, sweep.frame_source(screen), "response_map",
                         target_rel_stderr=target_rel_stderr, seed=setup.seed)
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
