"""Digital read-out of rendered mixel irradiances with the sensor model (pure numpy).

A frame's irradiances become 12-bit numbers as on the prototype: the exposure is set so that the brightest value
fills a fraction of the range, shot / read noise and quantisation are added, the background is the mean of
background-only frames and the detection threshold comes from their spread (:func:`~.estimators.noise_threshold`).
:func:`propagate_sigma` carries per-value standard deviations through an estimator to its output.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from mincam_sim.errors import InputError, is_finite_real
from mincam_sim.estimation.estimators import noise_threshold
from mincam_sim.model.sensor import SensorModel


@dataclass
class Readout:
    """Read-out (DN) of mixel irradiances: frames, averaged background, detection threshold and the sensor."""

    frames_dn: np.ndarray
    background_dn: np.ndarray
    threshold_dn: float
    sensor: SensorModel
    n_background_frames: int = 16

    @property
    def change_dn(self) -> np.ndarray:
        """Frames minus the averaged background [DN]."""
        return self.frames_dn - self.background_dn

    def ideal_change_dn(self, frame_irradiance: np.ndarray, background_irradiance: np.ndarray) -> np.ndarray:
        """The noiseless change [DN] (no shot/read noise, no quantisation) at the same exposure."""
        return self.sensor.expected(frame_irradiance) - self.sensor.expected(background_irradiance)

    def change_sigma_dn(self, frame_irradiance: np.ndarray, background_irradiance: np.ndarray,
                        mc_stderr_w_m2: np.ndarray | None = None) -> np.ndarray:
        """Standard deviation of the change [DN]: sensor noise of the frame and of the averaged background,
        plus the Monte Carlo standard error of the rendered change [W/m^2] converted to DN."""
        var = self.sensor.expected_std_dn(frame_irradiance) ** 2
        var = var + self.sensor.expected_std_dn(background_irradiance) ** 2 / self.n_background_frames
        if mc_stderr_w_m2 is not None:
            var = var + (self.sensor.dn_per_irradiance * np.asarray(mc_stderr_w_m2)) ** 2
        return np.sqrt(var)


def read_out(
    frame_irradiance_w_m2: np.ndarray,
    background_irradiance_w_m2: np.ndarray,
    sensor: SensorModel,
    rng: np.random.Generator,
    exposure_fill: float = 0.7,
    n_background_frames: int = 16,
    n_sigma: float = 5.0,
) -> Readout:
    """Expose ``sensor`` so the brightest value fills ``exposure_fill`` of its range, add noise and quantise;
    estimate the background and a ``n_sigma`` detection threshold from ``n_background_frames`` background-only
    frames.

    Parameters
    ----------
    frame_irradiance_w_m2 : (frames, mixels) array
        Rendered irradiance on each detector [W/m^2] (finite; zero frames give an empty read-out).
    background_irradiance_w_m2 : (mixels,) array
        Irradiance of the empty scene [W/m^2].
    sensor : SensorModel
        The photodetector and ADC (e.g. :meth:`~mincam_sim.model.sensor.SensorModel.paper_prototype`).
    rng : numpy.random.Generator
        Source of the sensor noise.
    """
    frames_in = np.asarray(frame_irradiance_w_m2, dtype=np.float64)
    background_in = np.asarray(background_irradiance_w_m2, dtype=np.float64)
    for name, values in (("frame_irradiance_w_m2", frames_in), ("background_irradiance_w_m2", background_in)):
        if not np.all(np.isfinite(values)):
            raise InputError(f"read_out: {name} has NaN/inf values; a read-out needs finite irradiances")
    if background_in.ndim != 1 or frames_in.shape[-1:] != background_in.shape:
        raise InputError(f"read_out: background_irradiance_w_m2 must hold one value per mixel, the last axis of "
                         f"frame_irradiance_w_m2 {frames_in.shape}; got shape {background_in.shape}")
    if (not is_finite_real(n_background_frames) or int(n_background_frames) != n_background_frames
            or n_background_frames < 2):
        raise InputError(f"read_out: n_background_frames must be an integer >= 2 (the threshold needs a spread), "
                         f"got {n_background_frames!r}")
    n_background_frames = int(n_background_frames)
    peak = float(max(np.max(frames_in, initial=0.0), np.max(background_in, initial=0.0)))
    if not peak > 0:
        raise InputError("read_out: every irradiance is 0 (or there are none), so there is no exposure to set; "
                         "the mixels see nothing lit")
    exposed = sensor.auto_exposed(peak, exposure_fill)
    shape = (n_background_frames, *np.shape(background_irradiance_w_m2))
    bg_frames = exposed.measure(np.broadcast_to(background_irradiance_w_m2, shape), rng)
    background, threshold = noise_threshold(bg_frames, n_sigma=n_sigma)
    frames = exposed.measure(frames_in, rng)
    return Readout(frames, background, float(threshold), exposed, n_background_frames)


def propagate_sigma(predict: Callable[[np.ndarray], np.ndarray], change: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Standard deviation of ``predict(change)`` (rows = frames) from independent per-value sigmas, by a
    finite-difference Jacobian (first-order propagation). Returns the shape of ``predict``'s output."""
    base = np.asarray(predict(change), dtype=float)
    var = np.zeros_like(base)
    for j in range(change.shape[1]):
        h = np.maximum(1e-3 * sigma[:, j], 1e-9)
        bumped = change.copy()
        bumped[:, j] += h
        jac = (np.asarray(predict(bumped), dtype=float) - base) / (h if base.ndim == 1 else h[:, None])
        var += (jac * (sigma[:, j] if base.ndim == 1 else sigma[:, j][:, None])) ** 2
    return np.sqrt(var)
