"""Estimators turning mixel measurements into intrusion positions, 2D positions, speeds and paths. Pure numpy.

They work on any array of measurements, simulated or recorded from hardware. Equation numbers refer to the
paper (Sec. 4). Mask coordinates are the normalised ``x``, ``y`` in [0, 1] of :mod:`mincam_sim.masks`.

* 1D intrusion (Eq. 2-4): masks ``x`` and ``1 - x``; ``x_obs = dP1 / (dP1 + dP2)`` is the centroid of the
  change D caused by the intruder, :func:`intrusion_position`.
* 2D tracking (Eq. 5-8): masks ``(x, 1 - x, y, 1 - y)`` (:func:`track_4`) or ``(x, y, 1)`` (:func:`track_3`).
* Speed (Eq. 9-14): a mask ``A0 + A1 cos(omega_df x + phi)`` at ``d_f`` from the detector is seen at depth
  ``d`` with angular frequency ``omega_d = omega_df d_f / d`` [rad/m]; moving at speed ``v`` the mixel signal
  is a sinusoid of angular frequency ``omega_p = omega_d v`` [rad/s], so ``v = omega_p / omega_d``.
* Two speed mixels on both sides of a vehicle give its planar path (differential-drive kinematics),
  :func:`trajectory_from_speeds`.

Here ``dP`` always means the change of a measurement from its background (measurement - background).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from mincam_sim.errors import InputError, is_finite_real

ChangeNorm = Literal["sum", "l1", "l2", "max"]
WindowName = Literal["hann", "hamming", "blackman", "rect"]

_CANCELLATION_EPS = 64 * np.finfo(np.float64).eps
MAX_FFT_SAMPLES = 1 << 26  # zero-padded FFT length (1 GiB of complex128): beyond it the peak search is refused


def _number(name: str, value: float, low: float = -np.inf, *, low_open: bool = False, unit: str = "") -> float:
    """``value`` as a float when it is a finite real number ``>= low`` (``> low`` with ``low_open``); otherwise one
    :class:`~mincam_sim.errors.InputError` naming ``name``, the rule and what was given."""
    if not is_finite_real(value) or (value <= low if low_open else value < low):
        rule = "a finite number" + ("" if low == -np.inf else f" {'>' if low_open else '>='} {low:g}")
        raise InputError(f"{name} must be {rule}{unit}, got {value!r}")
    return float(value)


def _count(name: str, value: int, low: int) -> int:
    """``value`` as an int when it is a whole number ``>= low`` (a float such as 16.0 too); else InputError."""
    if not is_finite_real(value) or int(value) != value or value < low:
        raise InputError(f"{name} must be an integer >= {low}, got {value!r}")
    return int(value)


# -------------------------------------------------------------------------------------------- change / ratios
def change_statistic(measurements: ArrayLike, background: ArrayLike, norm: ChangeNorm = "sum") -> np.ndarray:
    """Size of the change of each frame from the background, in the units of the measurements.

    Parameters
    ----------
    measurements : array_like, shape (n_frames, n_mixels) or (n_frames,)
        Mixel values per frame (e.g. DN).
    background : array_like, shape (n_mixels,) or scalar
        Background value of each mixel (e.g. the mean of frames without intruder).
    norm : {"sum", "l1", "l2", "max"}
        ``"sum"``: ``|sum_i dP_i|``, the paper's total change: with complementary masks (x, 1 - x) it is
        ``|integral of D|``; it can cancel when an intruder brightens some parts of the view and darkens
        others. ``"l1"``: ``sum_i |dP_i|`` (no cancellation between mixels); ``"l2"``: Euclidean norm;
        ``"max"``: largest ``|dP_i|``.

    Returns
    -------
    numpy.ndarray, shape (n_frames,)
    """
    m, b = np.asarray(measurements, dtype=np.float64), np.asarray(background, dtype=np.float64)
    if m.ndim == 2 and b.ndim > 0 and b.shape[-1:] not in ((1,), m.shape[-1:]):
        raise InputError(f"background must hold one value per mixel ({m.shape[-1]}) or one for all, got shape "
                         f"{b.shape} for measurements of shape {m.shape}")
    delta = m - b
    if delta.ndim == 1:
        delta = delta[:, np.newaxis]
    if delta.ndim != 2:
        raise ValueError(f"measurements need shape (n_frames, n_mixels) or (n_frames,), got {delta.shape}")
    if norm == "sum":
        return np.abs(delta.sum(axis=1))
    if norm == "l1":
        return np.abs(delta).sum(axis=1)
    if norm == "l2":
        return np.sqrt((delta**2).sum(axis=1))
    if norm == "max":
        return np.abs(delta).max(axis=1)
    raise ValueError(f"norm must be one of 'sum', 'l1', 'l2', 'max', got {norm!r}")


def detect_change(
    measurements: ArrayLike, background: ArrayLike, threshold: float, norm: ChangeNorm = "sum"
) -> np.ndarray:
    """Frames whose change from the background exceeds ``threshold`` (boolean, shape (n_frames,)).

    The change is :func:`change_statistic` (default: the paper's total change ``|dP1 + dP2 + ...|``);
    ``threshold`` is in the same units. :func:`noise_threshold` derives one from background-only frames.
    """
    _number("threshold", threshold, 0.0, unit=" (the units of the measurements)")
    return change_statistic(measurements, background, norm) > threshold


def noise_threshold(
    background_frames: ArrayLike, n_sigma: float = 5.0, norm: ChangeNorm = "sum"
) -> tuple[np.ndarray, float]:
    """Background and detection threshold estimated from frames known to contain no intruder.

    Returns ``(background, threshold)`` with ``background`` the per-mixel mean and ``threshold`` the mean plus
    ``n_sigma`` standard deviations of :func:`change_statistic` over those frames. Needs at least 2 frames.
    """
    frames = np.asarray(background_frames, dtype=np.float64)
    if frames.ndim == 1:
        frames = frames[:, np.newaxis]
    if frames.ndim != 2 or frames.shape[0] < 2:
        raise InputError(f"background_frames must have shape (n_frames >= 2, n_mixels), got {frames.shape}")
    if not np.all(np.isfinite(frames)):
        raise InputError(f"background_frames hold {int(np.sum(~np.isfinite(frames)))} NaN or infinite value(s): "
                         "drop those frames first")
    _number("n_sigma", n_sigma, 0.0, unit=" standard deviations")
    background = frames.mean(axis=0)
    stat = change_statistic(frames, background, norm)
    return background, float(stat.mean() + n_sigma * stat.std(ddof=1))


def _safe_ratio(numerator: np.ndarray, denominator: np.ndarray, scale: np.ndarray, min_abs: float) -> np.ndarray:
    """numerator / denominator, NaN where |denominator| is ~0 (below ``min_abs`` or lost to cancellation)."""
    tiny = np.maximum(min_abs, _CANCELLATION_EPS * scale)
    ok = np.isfinite(denominator) & (np.abs(denominator) > tiny)
    out = np.full(np.broadcast_shapes(numerator.shape, denominator.shape), np.nan)
    np.divide(numerator, denominator, out=out, where=ok)
    return out


def intrusion_position(dP_x: ArrayLike, dP_1mx: ArrayLike, min_total: float = 0.0) -> np.ndarray:
    """Relative intrusion position ``x_obs = dP_x / (dP_x + dP_1mx)`` (paper Eq. 4), vectorised over frames.

    Parameters
    ----------
    dP_x, dP_1mx : array_like
        Changes of the mixels with masks ``x`` and ``1 - x`` (broadcast together).
    min_total : float
        Frames with ``|dP_x + dP_1mx| <= min_total`` (no intruder) give NaN; NaN is also returned where the
        denominator is zero up to floating-point cancellation.

    Returns
    -------
    numpy.ndarray
        ``x_obs``: the centroid of the change, in [0, 1] for a one-signed change with ideal masks; noise or a
        change of mixed sign can put it outside [0, 1] (it is not clipped).
    """
    a = np.asarray(dP_x, dtype=np.float64)
    b = np.asarray(dP_1mx, dtype=np.float64)
    return _safe_ratio(a, a + b, np.abs(a) + np.abs(b), _number("min_total", min_total, 0.0))


def _as_frames(dP: ArrayLike, n_mixels: int, name: str) -> np.ndarray:
    d = np.asarray(dP, dtype=np.float64)
    if d.shape[-1:] != (n_mixels,):
        raise ValueError(f"{name} needs dP of shape (n_frames, {n_mixels}) (last axis: mixels), got {d.shape}")
    return d


def track_4(dP: ArrayLike, min_total: float = 0.0) -> np.ndarray:
    """2D relative position from four mixels with masks ``(x, 1 - x, y, 1 - y)`` (paper Eq. 7).

    Parameters
    ----------
    dP : array_like, shape (n_frames, 4) (or (..., 4))
        Changes of the four mixels, in that mask order.
    min_total : float
        Threshold on each denominator below which the coordinate is NaN (see :func:`intrusion_position`).

    Returns
    -------
    numpy.ndarray, shape (n_frames, 2)
        ``(x, y)`` relative positions (centroid of the change in normalised mask coordinates).
    """
    d = _as_frames(dP, 4, "track_4")
    x = intrusion_position(d[..., 0], d[..., 1], min_total)
    y = intrusion_position(d[..., 2], d[..., 3], min_total)
    return np.stack([x, y], axis=-1)


def track_3(dP: ArrayLike, min_total: float = 0.0) -> np.ndarray:
    """2D relative position from three mixels with masks ``(x, y, 1)`` (paper Eq. 8): ``(dP1/dP3, dP2/dP3)``.

    Same shapes and NaN rule as :func:`track_4`. Unlike :func:`track_4`, a gain mismatch between mixels biases
    the result, since the denominator comes from a different mixel than each numerator.
    """
    d = _as_frames(dP, 3, "track_3")
    min_total = _number("min_total", min_total, 0.0)
    total = d[..., 2]
    x = _safe_ratio(d[..., 0], total, np.abs(total), min_total)
    y = _safe_ratio(d[..., 1], total, np.abs(total), min_total)
    return np.stack([x, y], axis=-1)


def centroid(
    disturbance: ArrayLike, coords: ArrayLike | Sequence[ArrayLike], cell_weights: ArrayLike | None = None
) -> np.ndarray:
    """Ideal centroid ``integral(x D) / integral(D)`` of a disturbance sampled on a grid.

    Parameters
    ----------
    disturbance : array_like, shape ``(*batch, *grid)``
        Change D of the scene, one grid per frame.
    coords : array_like of shape grid, or tuple/list of such arrays
        Coordinate(s) of the grid samples (e.g. ``x`` for 1D, ``(X, Y)`` from ``np.meshgrid`` for 2D); each
        must broadcast to ``grid``, which is taken as the trailing ``ndim`` axes of ``disturbance``.
    cell_weights : array_like of shape grid, optional
        Quadrature weights (cell sizes); uniform by default (they cancel on a uniform grid).

    Returns
    -------
    numpy.ndarray
        Shape ``batch`` for a single coordinate array, ``(*batch, k)`` for a tuple/list of k arrays; NaN where
        ``integral(D) == 0``.
    """
    d = np.asarray(disturbance, dtype=np.float64)
    # a list or tuple of arrays is several coordinates; a list of numbers is one coordinate array
    multi = isinstance(coords, tuple | list) and len(coords) > 0 and not all(np.ndim(c) == 0 for c in coords)
    coord_arrays = [np.asarray(c, dtype=np.float64) for c in (coords if multi else [coords])]
    grid_ndim = max(c.ndim for c in coord_arrays)
    if grid_ndim == 0 or grid_ndim > d.ndim:
        raise ValueError(
            f"coords must be arrays over the grid (the trailing axes of disturbance {d.shape}); "
            f"got shapes {[c.shape for c in coord_arrays]}"
        )
    grid_shape = d.shape[d.ndim - grid_ndim :]
    weights = np.ones(grid_shape) if cell_weights is None else np.broadcast_to(cell_weights, grid_shape)
    axes = tuple(range(d.ndim - grid_ndim, d.ndim))
    weighted = d * weights
    total = weighted.sum(axis=axes)
    results = []
    for c in coord_arrays:
        moment = (weighted * np.broadcast_to(c, grid_shape)).sum(axis=axes)
        results.append(_safe_ratio(moment, np.asarray(total), np.abs(weighted).sum(axis=axes), 0.0))
    return np.stack(results, axis=-1) if multi else results[0]


# ------------------------------------------------------------------------------------------------ speed
@dataclass(frozen=True)
class Spectrum:
    """Windowed, zero-padded amplitude spectrum of a mixel signal and its refined peak.

    Attributes
    ----------
    freqs_hz : numpy.ndarray
        Frequencies of the zero-padded FFT bins [Hz], 0 to Nyquist.
    magnitude : numpy.ndarray
        ``|FFT|`` of the mean-removed, windowed signal, normalised so that a sinusoid of amplitude A lying on
        a bin reads A.
    peak_hz : float
        Refined frequency of the strongest non-DC peak [Hz].
    peak_omega_rad_s : float
        The same as an angular frequency, ``omega_p = 2 pi peak_hz`` [rad/s].
    peak_magnitude : float
        Magnitude at the refined peak (same normalisation as ``magnitude``).
    """

    freqs_hz: np.ndarray
    magnitude: np.ndarray
    peak_hz: float
    peak_omega_rad_s: float
    peak_magnitude: float


def window_weights(window: WindowName, n_samples: int) -> np.ndarray:
    """Taper of ``n_samples`` weights: ``"hann"``, ``"hamming"``, ``"blackman"`` or ``"rect"`` (no taper)."""
    makers = {"hann": np.hanning, "hamming": np.hamming, "blackman": np.blackman, "rect": np.ones}
    if window not in makers:
        raise ValueError(f"window must be one of {sorted(makers)}, got {window!r}")
    return np.asarray(makers[window](n_samples), dtype=np.float64)


def _dtft_derivatives(weighted: np.ndarray, n_centred: np.ndarray, omega: float) -> tuple[complex, ...]:
    """Y(w) = sum x_n w_n e^{-i w n} and its first two derivatives in w (w in rad/sample)."""
    phasor = weighted * np.exp(-1j * omega * n_centred)
    return phasor.sum(), (-1j * n_centred * phasor).sum(), (-(n_centred**2) * phasor).sum()


def spectrum(
    signal: ArrayLike,
    sample_rate_hz: float,
    window: WindowName = "hann",
    zero_pad_factor: int = 8,
    min_frequency_hz: float | None = None,
    max_frequency_hz: float | None = None,
) -> Spectrum:
    """Spectrum of a uniformly sampled signal and the refined frequency of its strongest non-DC peak.

    The (window-weighted) mean is removed, the signal is windowed and zero-padded to ``zero_pad_factor`` x its
    length; the largest local maximum of ``|FFT|`` within ``[min_frequency_hz, max_frequency_hz]`` is then
    refined by Newton's method on the continuous windowed DTFT, so the result is the maximiser of the windowed
    periodogram (for ``window="rect"`` the maximum-likelihood estimator of a single sinusoid in white noise).

    Accuracy (see :func:`frequency_error_std`): at high SNR the estimate is unbiased up to the leakage of the
    sinusoid's negative-frequency image (negligible a few bins away from DC and Nyquist) and its standard
    deviation is ``sqrt(2 sigma^2 sum(n^2 w_n^2) / (A^2 (sum n^2 w_n)^2))`` rad/sample, n centred; for the
    rectangular window that is the Cramer-Rao bound ``sqrt(12 / (SNR N^3))`` with ``SNR = A^2 / (2 sigma^2)``,
    and the Hann window costs a factor of about 1.5 in standard deviation.

    Parameters
    ----------
    signal : array_like, shape (n_samples,)
        Mixel values over time, n_samples >= 8, finite.
    sample_rate_hz : float
        Sampling rate [Hz].
    window : {"hann", "hamming", "blackman", "rect"}
        Taper applied before the FFT.
    zero_pad_factor : int
        FFT length / signal length (>= 1); finer bins make the coarse search robust, not the refinement exact.
    min_frequency_hz : float, optional
        Lowest accepted peak [Hz]; default ``2 sample_rate_hz / n_samples`` (two bins, outside the DC main
        lobe: a record must hold at least ~2 cycles).
    max_frequency_hz : float, optional
        Highest accepted peak [Hz]; default Nyquist.
    """
    x = np.asarray(signal, dtype=np.float64)
    if x.ndim != 1 or x.size < 8:
        raise ValueError(f"signal must be 1D with at least 8 samples, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("signal has NaN or inf values; interpolate them first (sampling must stay uniform)")
    _number("sample_rate_hz", sample_rate_hz, 0.0, low_open=True, unit=" Hz")
    zero_pad_factor = _count("zero_pad_factor", zero_pad_factor, 1)
    if zero_pad_factor * x.size > MAX_FFT_SAMPLES:
        raise InputError(f"zero_pad_factor {zero_pad_factor} x {x.size} samples exceeds {MAX_FFT_SAMPLES} FFT "
                         f"points: give zero_pad_factor <= {max(1, MAX_FFT_SAMPLES // x.size)}")
    for name, limit in (("min_frequency_hz", min_frequency_hz), ("max_frequency_hz", max_frequency_hz)):
        if limit is not None:
            _number(name, limit, 0.0, unit=" Hz (or None)")
    if min_frequency_hz is not None and max_frequency_hz is not None and min_frequency_hz > max_frequency_hz:
        raise InputError(f"min_frequency_hz {min_frequency_hz:g} must not exceed max_frequency_hz "
                         f"{max_frequency_hz:g}")
    n = x.size
    w = window_weights(window, n)
    weighted = (x - np.sum(w * x) / np.sum(w)) * w
    n_fft = int(zero_pad_factor) * n
    fft = np.fft.rfft(weighted, n_fft)
    magnitude = 2.0 * np.abs(fft) / np.sum(w)
    freqs = np.fft.rfftfreq(n_fft, d=1.0 / sample_rate_hz)

    f_lo = 2.0 * sample_rate_hz / n if min_frequency_hz is None else float(min_frequency_hz)
    f_hi = sample_rate_hz / 2.0 if max_frequency_hz is None else float(max_frequency_hz)
    is_local_max = np.zeros(freqs.size, dtype=bool)
    is_local_max[1:-1] = (magnitude[1:-1] >= magnitude[:-2]) & (magnitude[1:-1] >= magnitude[2:])
    candidates = np.flatnonzero(is_local_max & (freqs >= f_lo) & (freqs <= f_hi))
    if candidates.size == 0 or magnitude[candidates].max() == 0:
        raise NoSpectralPeakError(
            f"no spectral peak between {f_lo:.6g} Hz and {f_hi:.6g} Hz; the signal may be constant or too "
            "short (it needs a few cycles of the sinusoid), or the frequency limits exclude the peak"
        )
    k = int(candidates[np.argmax(magnitude[candidates])])

    # Coarse: parabola through log-magnitudes of the three padded bins; fine: Newton on d|Y|^2/dw = 0.
    lm = np.log(magnitude[k - 1 : k + 2] + 1e-300)
    curvature = lm[0] - 2 * lm[1] + lm[2]
    offset = 0.5 * (lm[0] - lm[2]) / curvature if curvature < 0 else 0.0
    bin_rad = 2 * np.pi / n_fft  # padded bin width [rad/sample]
    omega = (k + float(np.clip(offset, -0.5, 0.5))) * bin_rad
    n_centred = np.arange(n) - (n - 1) / 2.0
    lo, hi = (k - 1) * bin_rad, (k + 1) * bin_rad
    for _ in range(20):
        y0, y1, y2 = _dtft_derivatives(weighted, n_centred, omega)
        slope = 2 * (np.conj(y0) * y1).real
        curv = 2 * ((np.conj(y0) * y2).real + abs(y1) ** 2)
        if curv >= 0:
            break
        step = -slope / curv
        omega = float(np.clip(omega + step, lo, hi))
        if abs(step) < 1e-13 * max(omega, bin_rad):
            break
    peak_magnitude = 2.0 * abs(_dtft_derivatives(weighted, n_centred, omega)[0]) / np.sum(w)
    peak_hz = omega * sample_rate_hz / (2 * np.pi)
    return Spectrum(freqs, magnitude, float(peak_hz), float(2 * np.pi * peak_hz), float(peak_magnitude))


def dominant_frequency(signal: ArrayLike, sample_rate_hz: float, window: WindowName = "hann", **kwargs) -> float:
    """Angular frequency ``omega_p`` [rad/s] of the strongest non-DC peak (kwargs: see :func:`spectrum`)."""
    return spectrum(signal, sample_rate_hz, window, **kwargs).peak_omega_rad_s


def frequency_error_std(
    amplitude: float, noise_std: float, n_samples: int, sample_rate_hz: float, window: WindowName = "hann"
) -> float:
    """High-SNR standard deviation [rad/s] of :func:`dominant_frequency` for ``A cos(w t + phi)`` + noise.

    Small-error linearisation of the windowed-periodogram maximiser (n centred on the record):
    ``var(w) = 2 sigma^2 sum(n^2 w_n^2) / (A^2 (sum n^2 w_n)^2)`` [rad/sample]^2, scaled by
    ``sample_rate_hz``. With ``window="rect"`` it equals the Cramer-Rao bound ``12 / (SNR N (N^2 - 1))``,
    SNR = A^2 / (2 sigma^2), for white Gaussian noise of standard deviation sigma.
    """
    _number("amplitude", amplitude, 0.0, low_open=True)
    _number("noise_std", noise_std, 0.0)
    n_samples = _count("n_samples", n_samples, 2)
    _number("sample_rate_hz", sample_rate_hz, 0.0, low_open=True, unit=" Hz")
    w = window_weights(window, n_samples)
    n = np.arange(n_samples) - (n_samples - 1) / 2.0
    var = 2 * noise_std**2 * np.sum(n**2 * w**2) / (amplitude**2 * np.sum(n**2 * w) ** 2)
    return float(np.sqrt(var) * sample_rate_hz)


def scene_frequency(omega_df_rad_per_m: float, d_f_m: float, depth_m: ArrayLike) -> np.ndarray | float:
    """Angular frequency of the mask as seen on the scene plane (paper Eq. 10): ``omega_df d_f / d`` [rad/m].

    ``omega_df_rad_per_m`` is the mask's own angular spatial frequency [rad/m], ``d_f_m`` the mask-to-detector
    distance [m] and ``depth_m`` the detector-to-scene distance [m] (> 0).
    """
    _number("omega_df_rad_per_m", omega_df_rad_per_m, 0.0, unit=" rad/m")
    _number("d_f_m", d_f_m, 0.0, low_open=True, unit=" m")
    depth = np.asarray(depth_m, dtype=np.float64)
    if np.any(~np.isfinite(depth) | (depth <= 0)):
        raise InputError(f"depth_m must be finite and > 0 [m], got depth_m={depth_m!r}")
    result = omega_df_rad_per_m * d_f_m / depth
    return float(result) if result.ndim == 0 else result


class NoSpectralPeakError(ValueError):
    """A signal's spectrum holds no peak in the frequency band searched (a constant signal, or one too short to
    hold a period of the sinusoid)."""


class AliasingError(ValueError):
    """A speed lies at or above the Nyquist limit of the sampled sinusoid signal (see :func:`nyquist_speed`)."""


def nyquist_speed(sample_rate_hz: float, omega_d_rad_per_m: float) -> float:
    """Highest speed [m/s] a sinusoid mixel sampled at ``sample_rate_hz`` can measure: ``pi f_s / omega_d``.

    At that speed the signal's angular frequency ``omega_d v`` (Eq. 13) reaches the Nyquist frequency
    ``pi f_s`` [rad/s]; a faster scene gives a signal that is indistinguishable from a slower one
    (:func:`aliased_speed`), so no estimator working on the samples alone can tell them apart.

    Parameters
    ----------
    sample_rate_hz : float
        Mixel sampling rate [Hz] (> 0).
    omega_d_rad_per_m : float
        Angular frequency of the mask on the scene plane [rad/m] (Eq. 10, :func:`scene_frequency`), in the
        same length unit as the speed (rad/px for a speed in px/s).
    """
    if not np.isfinite(sample_rate_hz) or sample_rate_hz <= 0:
        raise ValueError(f"sample_rate_hz must be a finite number > 0, got {sample_rate_hz!r}")
    if not np.isfinite(omega_d_rad_per_m) or omega_d_rad_per_m <= 0:
        raise ValueError(f"omega_d_rad_per_m must be finite and > 0, got {omega_d_rad_per_m!r}")
    return float(np.pi * sample_rate_hz / omega_d_rad_per_m)


def aliased_speed(speed_m_s: ArrayLike, sample_rate_hz: float, omega_d_rad_per_m: float) -> np.ndarray | float:
    """The speed [m/s] whose sampled signal is identical to that of ``|speed_m_s|``: the true one below the
    Nyquist limit ``v_N`` (:func:`nyquist_speed`), folded into ``[0, v_N]`` above it (``2 v_N - v`` for
    ``v_N < v < 2 v_N``, and so on). This is what the FFT peak of the samples reports."""
    v_n = nyquist_speed(sample_rate_hz, omega_d_rad_per_m)
    folded = np.mod(np.abs(np.asarray(speed_m_s, dtype=np.float64)), 2 * v_n)
    folded = np.where(folded > v_n, 2 * v_n - folded, folded)
    return float(folded) if folded.ndim == 0 else folded


def check_below_nyquist(speed_m_s: ArrayLike, sample_rate_hz: float, omega_d_rad_per_m: float,
                        what: str = "speed") -> None:
    """Raise :class:`AliasingError` if any ``|speed_m_s|`` is at or above :func:`nyquist_speed`.

    The message names the limit, the speed the samples would show instead and the two ways out (a higher
    sample rate, or a coarser mask / larger depth, i.e. a lower ``omega_d``).
    """
    v = np.abs(np.atleast_1d(np.asarray(speed_m_s, dtype=np.float64)))
    v_n = nyquist_speed(sample_rate_hz, omega_d_rad_per_m)
    if np.any(~np.isfinite(v)):
        raise ValueError(f"{what} must be finite, got {speed_m_s!r}")
    bad = v[v >= v_n]
    if bad.size:
        shown = aliased_speed(bad[0], sample_rate_hz, omega_d_rad_per_m)
        raise AliasingError(
            f"{what} {bad[0]:.6g} is at or above the Nyquist limit pi f_s / omega_d = {v_n:.6g} "
            f"(f_s = {sample_rate_hz:.6g} Hz, omega_d = {omega_d_rad_per_m:.6g} rad per length unit): its samples "
            f"look like a speed of {shown:.6g}; sample faster than {bad.max() * omega_d_rad_per_m / np.pi:.6g} Hz "
            "or use a coarser mask period"
        )


def speed_from_frequency(omega_p_rad_s: ArrayLike, omega_d_rad_per_m: float) -> np.ndarray | float:
    """Speed ``v = omega_p / omega_d`` [m/s] (paper Eq. 14)."""
    if not np.isfinite(omega_d_rad_per_m) or omega_d_rad_per_m <= 0:
        raise ValueError(f"omega_d_rad_per_m must be finite and > 0, got {omega_d_rad_per_m!r}")
    v = np.asarray(omega_p_rad_s, dtype=np.float64) / omega_d_rad_per_m
    return float(v) if v.ndim == 0 else v


def speed_from_signal(
    signal: ArrayLike,
    sample_rate_hz: float,
    omega_d_rad_per_m: float,
    window: WindowName = "hann",
    max_speed_m_s: float | None = None,
    **kwargs,
) -> float:
    """Speed [m/s] of a mixel with a sinusoidal mask from its signal: ``dominant_frequency / omega_d``.

    The sign of the motion is not observable from one sinusoid (the result is a speed, >= 0). The Nyquist
    limit gives the highest measurable speed, :func:`nyquist_speed` ``= pi sample_rate_hz / omega_d``: a
    faster scene aliases to :func:`aliased_speed`, which the samples cannot reveal. The result is therefore
    always below that limit; pass ``max_speed_m_s`` (the fastest speed the set-up must measure) to have
    :class:`AliasingError` raised when it is not measurable, instead of a wrong speed. The mask's constant term
    A0 passes the scene's slow brightness variations, which can outweigh the sinusoid on real textures: pass
    ``min_frequency_hz = omega_d v_min / (2 pi)`` for the lowest speed ``v_min`` of interest.
    """
    if max_speed_m_s is not None:
        check_below_nyquist(max_speed_m_s, sample_rate_hz, omega_d_rad_per_m, "max_speed_m_s")
    omega_p = dominant_frequency(signal, sample_rate_hz, window, **kwargs)
    return float(speed_from_frequency(omega_p, omega_d_rad_per_m))


def speed_track(
    signal: ArrayLike,
    sample_rate_hz: float,
    omega_d_rad_per_m: float,
    window_samples: int,
    hop_samples: int | None = None,
    window: WindowName = "hann",
    **kwargs,
) -> tuple[np.ndarray, np.ndarray]:
    """Speed over time from sliding windows: returns ``(times_s, speeds_m_s)``, times at window centres.

    ``hop_samples`` defaults to ``window_samples // 2``. Each window must hold a few cycles of the signal.
    """
    x = np.asarray(signal, dtype=np.float64)
    window_samples = _count("window_samples", window_samples, 8)
    hop = window_samples // 2 if hop_samples is None else _count("hop_samples", hop_samples, 1)
    if window_samples < 8 or hop < 1 or window_samples > x.size:
        raise ValueError(
            f"need 8 <= window_samples <= len(signal) ({x.size}) and hop_samples >= 1, "
            f"got window_samples={window_samples}, hop_samples={hop}"
        )
    starts = np.arange(0, x.size - window_samples + 1, hop)
    speeds = np.array(
        [
            speed_from_signal(x[s : s + window_samples], sample_rate_hz, omega_d_rad_per_m, window, **kwargs)
            for s in starts
        ]
    )
    times = (starts + (window_samples - 1) / 2.0) / sample_rate_hz
    return times, speeds


# ------------------------------------------------------------------------------------------------ trajectory
@dataclass(frozen=True)
class Trajectory:
    """Planar path integrated from left/right speeds (see :func:`trajectory_from_speeds` for conventions).

    Attributes
    ----------
    x_m, y_m, heading_rad : numpy.ndarray, shape (n_steps + 1,)
        Poses at the start and after each step: position [m] and heading [rad, counter-clockwise from +x].
    heading_change_rad : numpy.ndarray, shape (n_steps,)
        Heading change of each step [rad], ``(v_right - v_left) dt / W``; positive = turning left.
    turn_radius_m : numpy.ndarray, shape (n_steps,)
        Signed radius of the path of the midpoint [m], ``W/2 (v_r + v_l) / (v_r - v_l)``; positive = centre of
        the turn on the left; ``+inf`` when ``v_left == v_right`` (straight).
    """

    x_m: np.ndarray
    y_m: np.ndarray
    heading_rad: np.ndarray
    heading_change_rad: np.ndarray
    turn_radius_m: np.ndarray


def trajectory_from_speeds(
    v_left: ArrayLike,
    v_right: ArrayLike,
    width_m: float,
    dt_s: float | ArrayLike,
    initial_pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> Trajectory:
    """Path of a rigid vehicle from the forward speeds of its left and right sides (differential drive).

    Conventions: world frame x, y [m], heading counter-clockwise from +x [rad]; vehicle frame +x forward, +y
    to the left. ``v_left`` / ``v_right`` are the forward speeds [m/s] measured by the mixels on the left /
    right side during each step (held constant over the step), ``width_m`` the lateral distance between the
    two mixels. The midpoint moves at ``v = (v_l + v_r) / 2`` and turns at ``omega = (v_r - v_l) / W``; each
    step is integrated exactly as a circular arc (straight line when ``omega = 0``). A speed mixel measures
    ``|v|``, so reversing has to be signalled to this function by negative speeds.

    Parameters
    ----------
    v_left, v_right : array_like, shape (n_steps,)
        Forward speeds [m/s].
    width_m : float
        Lateral separation of the two mixels [m] (> 0).
    dt_s : float or array_like of shape (n_steps,)
        Step duration(s) [s] (> 0).
    initial_pose : (x_m, y_m, heading_rad)
        Starting pose.
    """
    vl = np.atleast_1d(np.asarray(v_left, dtype=np.float64))
    vr = np.atleast_1d(np.asarray(v_right, dtype=np.float64))
    if vl.shape != vr.shape or vl.ndim != 1:
        raise ValueError(f"v_left and v_right must be 1D arrays of one length, got {vl.shape} and {vr.shape}")
    if not np.all(np.isfinite(vl)) or not np.all(np.isfinite(vr)):
        raise ValueError("v_left / v_right contain NaN or inf; fill gaps (interpolate) before integrating")
    _number("width_m", width_m, 0.0, low_open=True, unit=" (mixel separation in metres)")
    if len(initial_pose) != 3 or not all(is_finite_real(v) for v in initial_pose):
        raise InputError(f"initial_pose must be three finite numbers (x_m, y_m, heading_rad), got {initial_pose!r}")
    dt = np.broadcast_to(np.asarray(dt_s, dtype=np.float64), vl.shape)
    if np.any(~np.isfinite(dt) | (dt <= 0)):
        raise ValueError("dt_s must be finite and > 0 (seconds per step)")
    v = 0.5 * (vl + vr)
    dheading = (vr - vl) * dt / width_m
    with np.errstate(divide="ignore", invalid="ignore"):
        radius = np.where(vr == vl, np.inf, 0.5 * width_m * (vr + vl) / (vr - vl))
    x0, y0, h0 = initial_pose
    heading = h0 + np.concatenate([[0.0], np.cumsum(dheading)])
    # Chord of an arc of length s turning by a: length s sinc(a/2), direction heading + a/2.
    chord = v * dt * np.sinc(dheading / (2 * np.pi))
    mid_heading = heading[:-1] + 0.5 * dheading
    x = x0 + np.concatenate([[0.0], np.cumsum(chord * np.cos(mid_heading))])
    y = y0 + np.concatenate([[0.0], np.cumsum(chord * np.sin(mid_heading))])
    return Trajectory(x, y, heading, dheading, radius)
