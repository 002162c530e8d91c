"""The mask-design problem as plain arrays: the linear forward model, the film, the sensor noise and the task's
targets, and the optimiser's result (pure NumPy; :mod:`.optimiser` runs Adam on it through Dr.Jit)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass
class DesignProblem:
    """Everything the optimiser needs, as plain arrays (built by :func:`mincam_sim.design.optimise.build_problem`).

    Attributes
    ----------
    matrices : list of (n_frames, D) ndarray
        Per mixel, the linear model ``E = A @ T`` on the printer-dot grid [W/m^2].
    upsample_index, upsample_weight : (D, 4) ndarray
        Bilinear interpolation of the (G, G) parameter grid onto the D printer dots (indices into G*G).
    targets : (n_frames, n_outputs) ndarray
        What the decoder predicts per frame: true positions (normalised field coordinates,
        :mod:`mincam_sim.design.tracking`), a count, a log depth ... (one column per decoder output).
    features : callable
        ``features(dn, xp)`` -> tuple of decoder inputs from the (n_mixels,) list of DN arrays, written with
        the array namespace ``xp`` (``drjit`` inside the optimiser, ``numpy`` at inference).
    n_params : int
        G * G logits per mask.
    t_min, t_max, gamma, levels : film tone mapping (:class:`mincam_sim.masks.PrintedFilm`).
    dn_per_w_m2 : float
        Sensor gain for the exposure [DN per W/m^2].
    noise_dn : callable
        ``noise_dn(irradiance (n_mixels, n_frames) ndarray) -> sigma [DN]`` of the background-subtracted change,
        or, with ``background_rows``, ``noise_dn(change, background)`` (both (n_mixels, n_frames) [W/m^2]).
    background_rows : list of (n_rows, D) ndarray, optional
        Per mixel, linear models of the backgrounds behind the frames (e.g. a uniform plane of unit radiance
        per depth) [W/m^2 per unit transmission].
    background_weights : (n_frames, n_rows) ndarray, optional
        Each frame's background as a combination of those rows: its irradiance is ``W @ (R_k @ T_k)``.
    fit_noiseless : bool
        Fit the decoder of each step on the noiseless read-out (as a calibration is fitted), and score it on
        the noisy one; default: fit and score on the same noisy batch.
    error_cap : float, optional
        Robust loss: a frame's squared error counts at most ``error_cap**2`` (a lost frame, e.g. a change that
        noise cancels, weighs as one error of ``error_cap`` and carries no gradient) [fraction of the field].
    model : {"physical", "ideal"}
        What built the linear model: the traced physics, or the idealised dot-product model.
    degree : int
        Total degree of the decoder's polynomial of the features (3: the tracking cubic).
    """

    matrices: list
    upsample_index: np.ndarray
    upsample_weight: np.ndarray
    targets: np.ndarray
    features: Callable
    n_params: int
    t_min: float
    t_max: float
    gamma: float
    levels: int | None
    dn_per_w_m2: float
    noise_dn: Callable
    background_rows: list | None = None
    background_weights: np.ndarray | None = None
    fit_noiseless: bool = False
    error_cap: float | None = None
    model: str = "physical"
    degree: int = 3

    def background_irradiance(self, transmissions: list) -> np.ndarray | None:
        """Irradiance (n_mixels, n_frames) [W/m^2] of each frame's background through the masks ``T_k``."""
        if self.background_rows is None:
            return None
        return np.array([self.background_weights @ (r @ np.asarray(t, dtype=np.float64))
                         for r, t in zip(self.background_rows, transmissions, strict=True)])

    def sigma_dn(self, irradiance: np.ndarray, transmissions: list) -> np.ndarray:
        """Noise [DN] of each frame's change for masks ``T_k`` (see ``noise_dn``)."""
        if self.background_rows is None:
            return self.noise_dn(irradiance)
        return self.noise_dn(irradiance, self.background_irradiance(transmissions))


@dataclass
class DesignResult:
    """Output of :func:`mincam_sim.design.optimiser.optimise_masks` (NumPy arrays)."""

    logits: list  # per mixel (G*G,) ndarray
    transmission: list  # per mixel (D,) ndarray: the printed transmission on the dot grid
    loss_history: np.ndarray  # (iterations,) training RMS error [target units, tracking: fraction of the field]
    coefficients: np.ndarray  # (n_outputs, n_terms) decoder polynomial at the end


__all__ = ["DesignProblem", "DesignResult"]
