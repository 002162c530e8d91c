"""Spectral weighting of the wave response: a silicon quantum-efficiency model and band weights."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from mincam_sim.errors import InputError

DEFAULT_WAVELENGTHS_M = (550e-9,)  # [m] the sensor model's wavelength


# Absorption coefficient of crystalline silicon at 300 K [1/m], rounded from M. A. Green, "Self-consistent
# optical parameters of intrinsic silicon at 300 K including temperature coefficients", Solar Energy Materials
# & Solar Cells 92, 1305-1310 (2008), Table 1 (values there in 1/cm).
_SI_ALPHA_NM = np.array([400, 450, 500, 550, 600, 650, 700, 750, 800, 850, 900, 950, 1000, 1050, 1100.0])


_SI_ALPHA_PER_M = 100.0 * np.array(
    [9.52e4, 2.55e4, 1.11e4, 6.39e3, 4.14e3, 2.81e3, 1.90e3, 1.30e3, 8.50e2, 5.35e2, 3.06e2, 1.57e2, 6.40e1,
     1.63e1, 3.5]
)


QE_RANGE_M = (400e-9, 1100e-9)  # [m] the wavelengths :func:`silicon_qe` covers (the span of its absorption table)


SI_DEAD_LAYER_M = 0.2e-6  # [m] surface layer whose photocarriers recombine before collection (model)


SI_COLLECTION_DEPTH_M = 3e-6  # [m] depth down to which photocarriers are collected (front-illuminated CMOS, model)


SI_SURFACE_LOSS = 0.1  # fraction lost at the surface (reflection of an uncoated oxide stack ~ 10 %, model)


def silicon_qe(wavelength_m: float | np.ndarray) -> np.ndarray:
    """Quantum efficiency of a silicon photodiode (a model): ``(1 - R) (exp(-alpha d0) - exp(-alpha W))``.

    Parameters
    ----------
    wavelength_m : float or array_like
        Wavelength(s) [m], within 400-1100 nm.

    Returns
    -------
    ndarray
        Electrons per photon in [0, 1].

    Notes
    -----
    ``alpha`` is silicon's absorption coefficient (Green 2008, see the module source), interpolated
    log-linearly: photons absorbed between the depths ``d0`` = :data:`SI_DEAD_LAYER_M` (0.2 um, lost to
    surface recombination) and ``W`` = :data:`SI_COLLECTION_DEPTH_M` (3 um) are collected; ``R`` =
    :data:`SI_SURFACE_LOSS` (0.1). The shape (a peak near 550-600 nm, losses in the blue, a steep fall in the
    near infrared) is that of front-illuminated CMOS sensors; the response here only uses *relative* weights,
    so the scale does not matter. For a specific
    sensor pass its measured curve as ``qe`` to :func:`spectral_weights`.
    """
    bad = _outside_qe_range(wavelength_m)
    if bad:
        raise InputError(f"silicon_qe: wavelength_m must lie in the silicon QE model's range [{QE_RANGE_M[0]:g}, "
                         f"{QE_RANGE_M[1]:g}] m, got {bad} m")
    lam_nm = np.asarray(wavelength_m, dtype=np.float64) * 1e9
    alpha = np.exp(np.interp(lam_nm, _SI_ALPHA_NM, np.log(_SI_ALPHA_PER_M)))
    return (1.0 - SI_SURFACE_LOSS) * (np.exp(-alpha * SI_DEAD_LAYER_M) - np.exp(-alpha * SI_COLLECTION_DEPTH_M))


def spectral_weights(
    wavelengths_m: Sequence[float], qe: Callable[[np.ndarray], np.ndarray] | None = silicon_qe
) -> np.ndarray:
    """Weights (sum 1) of the wavelengths for a flat photon spectrum seen by a detector of quantum efficiency ``qe``.

    Parameters
    ----------
    wavelengths_m : sequence of float
        Distinct wavelengths [m], in any order.
    qe : callable or None
        Quantum efficiency [electrons per photon] at an array of wavelengths [m] (default :func:`silicon_qe`,
        which refuses wavelengths outside ``QE_RANGE_M``); ``None`` weighs the bands by their width only. It must
        return one finite value >= 0 per wavelength (or one for all); only the ratios matter.

    Returns
    -------
    ndarray
        One weight per wavelength, in the order given, summing to 1.

    Notes
    -----
    Each wavelength stands for the band between its neighbours' midpoints (trapezoid rule); a single
    wavelength gets weight 1, but it is still checked against ``qe`` (a wavelength the QE curve does not
    cover, or where it is 0, is refused whether it comes alone or with others).
    """
    lam = _check_wavelengths(wavelengths_m)
    if qe is not None and not callable(qe):
        raise InputError(f"qe must be a quantum-efficiency curve (a function of wavelength [m]) or None (band widths "
                         f"only), got {qe!r}")
    bad = _outside_qe_range(lam) if qe is silicon_qe else ""
    if bad:
        raise InputError(f"wavelengths_m {bad} m lie outside the silicon QE model's range [{QE_RANGE_M[0]:g}, "
                         f"{QE_RANGE_M[1]:g}] m: give wavelengths in that range, or pass qe=None (weights by band "
                         "width only) or your sensor's measured QE curve as qe")
    order = np.argsort(lam)
    s = lam[order]
    if len(s) == 1:
        width = np.ones(1)
    else:
        edges = np.concatenate(([s[0]], 0.5 * (s[1:] + s[:-1]), [s[-1]]))
        width = np.diff(edges)
    w_sorted = width * (np.ones_like(s) if qe is None else _qe_values(qe, s))
    w = np.empty_like(w_sorted)
    w[order] = w_sorted
    if not np.all(np.isfinite(w)) or w.sum() <= 0:
        raise InputError(f"spectral_weights: the QE curve gives no weight to wavelengths_m "
                         f"{list(map(float, lam))} m: give wavelengths where it is positive, or pass qe=None")
    return w / w.sum()


def _qe_values(qe: Callable[[np.ndarray], np.ndarray], wavelengths_m: np.ndarray) -> np.ndarray:
    """``qe(wavelengths_m)`` as one non-negative efficiency per wavelength (a scalar is broadcast; only the ratios
    matter, so a curve in percent weighs the same); anything else is refused (InputError) rather than weighting a
    band negatively."""
    try:
        values = np.broadcast_to(np.asarray(qe(wavelengths_m), dtype=np.float64), wavelengths_m.shape)
    except (TypeError, ValueError):
        values = None
    if values is None or not np.all(np.isfinite(values)) or np.any(values < 0):
        raise InputError(f"qe must return one quantum efficiency >= 0 [electrons per photon] for each of the "
                         f"wavelengths_m {list(map(float, wavelengths_m))} m; it gave "
                         f"{values.tolist() if values is not None else 'a value of another shape or type'}")
    return values


def _outside_qe_range(wavelength_m: float | np.ndarray) -> str:
    """The wavelengths [m] (listed, as text) that :func:`silicon_qe` does not cover; empty when none."""
    lam_m = np.atleast_1d(np.asarray(wavelength_m, dtype=np.float64))
    outside = ~(lam_m >= QE_RANGE_M[0]) | ~(lam_m <= QE_RANGE_M[1])  # NaN is outside too
    return ", ".join(f"{v:.4g}" for v in lam_m[outside])


def _check_wavelengths(wavelengths_m: Sequence[float]) -> np.ndarray:
    try:
        lam = np.atleast_1d(np.asarray(wavelengths_m, dtype=np.float64))
    except (TypeError, ValueError):
        lam = np.empty(0)  # not numbers: refused below
    if (isinstance(wavelengths_m, str | bytes) or lam.ndim != 1 or lam.size == 0 or not np.all(np.isfinite(lam))
            or np.any(lam <= 0)):
        raise InputError(f"wavelengths_m must be a non-empty list of positive wavelengths in metres, got "
                         f"{wavelengths_m!r}")
    if np.any(lam > 1e-4):
        raise InputError(f"wavelengths_m {wavelengths_m!r} look like nanometres; give metres (550e-9 for 550 nm)")
    values, counts = np.unique(lam, return_counts=True)
    if np.any(counts > 1):
        repeated = ", ".join(f"{v:g} m" for v in values[counts > 1])
        raise InputError(f"wavelengths_m repeats {repeated}: give each wavelength once (the spectral weights "
                         "already give each its band)")
    return lam
