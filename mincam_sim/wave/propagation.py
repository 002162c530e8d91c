"""Band-limited angular-spectrum propagation of tilted plane waves through the aperture to the detector."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy import fft as sfft

from mincam_sim.wave.sampling import Sampling, _cell_centres


def _kz_minus(f2: np.ndarray, f02: float, inv_lam2: float) -> np.ndarray:
    """``sqrt(1/lambda^2 - f2) - sqrt(1/lambda^2 - f02)`` without cancellation (NaN where evaporating)."""
    a = np.sqrt(np.maximum(inv_lam2 - f2, 0.0))
    b = math.sqrt(inv_lam2 - f02)
    return (f02 - f2) / (a + b)


def _axis_freqs(s: Sampling, f0: float, wavelength_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Absolute frequencies on the grid and the per-axis band-limit mask."""
    f = sfft.fftfreq(s.n_domain, s.dx_m) + f0
    # per-axis reach: the direction tangent of the component (its own axis, other axis at zero) must reach
    lam_f = wavelength_m * f
    keep = np.abs(lam_f) < 1.0
    tan = np.where(keep, lam_f / np.sqrt(np.maximum(1.0 - lam_f**2, 1e-300)), np.inf)
    return f, keep & (np.abs(tan) <= s.reach_tan * 1.0001)


def _detector_weights(s: Sampling, detector_m: float, centre_m: float = 0.0) -> tuple[slice, np.ndarray]:
    """Cells overlapping the detector ``[centre - a, centre + a]`` and their overlap fractions (sum 1)."""
    x = _cell_centres(s.n_domain, s.dx_m)
    lo, hi = centre_m - detector_m / 2, centre_m + detector_m / 2
    overlap = np.clip(np.minimum(x + s.dx_m / 2, hi) - np.maximum(x - s.dx_m / 2, lo), 0.0, None)
    idx = np.nonzero(overlap > 0)[0]
    sl = slice(int(idx[0]), int(idx[-1]) + 1)
    w = overlap[sl] / detector_m
    return sl, w


def _pad(amp: np.ndarray, n_dom: Sequence[int]) -> np.ndarray:
    out = np.zeros(tuple(n_dom), dtype=amp.dtype)
    idx = tuple(slice((nd - na) // 2, (nd - na) // 2 + na) for nd, na in zip(n_dom, amp.shape, strict=True))
    out[idx] = amp
    return out


def _response_1d(amp_ap: np.ndarray, s: Sampling, d_f_m: float, detector_m: float, wavelength_m: np.ndarray,
                 tan: np.ndarray) -> np.ndarray:
    """1D detector-averaged intensity for each (wavelength, incidence tangent) pair (uniform along the other axis)."""
    spec = sfft.fft(_pad(amp_ap.astype(np.complex128), [s.n_domain]))
    sl, w = _detector_weights(s, detector_m)
    lam_all = np.broadcast_to(np.asarray(wavelength_m, dtype=np.float64), tan.shape)
    out = np.empty(len(tan))
    f_rel = sfft.fftfreq(s.n_domain, s.dx_m)
    chunk = max(1, (1 << 21) // s.n_domain)
    for lo in range(0, len(tan), chunk):
        lam = lam_all[lo : lo + chunk, None]
        f0 = -np.sin(np.arctan(tan[lo : lo + chunk, None])) / lam
        f = f_rel[None, :] + f0
        lam_f = lam * f
        inside = np.abs(lam_f) < 1.0
        tan_f = np.where(inside, lam_f / np.sqrt(np.maximum(1.0 - lam_f**2, 1e-300)), np.inf)
        keep = inside & (np.abs(tan_f) <= s.reach_tan * 1.0001)
        a = np.sqrt(np.maximum(1.0 / lam**2 - f**2, 0.0))
        b = np.sqrt(1.0 / lam**2 - f0**2)
        phase = 2 * np.pi * d_f_m * (f0**2 - f**2) / (a + b)
        h = np.where(keep, np.exp(1j * phase), 0.0)
        u = sfft.ifft(spec[None, :] * h, axis=1)[:, sl]
        out[lo : lo + chunk] = np.abs(u) ** 2 @ w
    return out


def axis_wavelength(wavelength_m: float, tan_axis: np.ndarray, tan_other: np.ndarray) -> np.ndarray:
    """Wavelength [m] of the 1D problem along one axis for a wave tilted along both.

    With the other axis' transverse frequency ``f_o`` held at the incident one, ``kz = sqrt(1/lambda^2 - f_o^2
    - f^2)`` is a 1D propagator of wavelength ``1 / sqrt(1/lambda^2 - f_o^2) = lambda sqrt((1 + t^2 + t_o^2) /
    (1 + t^2))``, in which the incidence tangent along the axis stays ``t``.
    """
    t, o = np.asarray(tan_axis, dtype=float), np.asarray(tan_other, dtype=float)
    return wavelength_m * np.sqrt((1 + t * t + o * o) / (1 + t * t))


def _response_2d(amp_ap: np.ndarray, sx: Sampling, sy: Sampling, d_f_m: float, detector_m: float,
                 wavelength_m: float, tan: np.ndarray, workers: int) -> np.ndarray:
    """2D detector-averaged intensity for each incidence (tan_x, tan_y); ``amp_ap`` is (ny, nx), row 0 bottom."""
    spec = sfft.fft2(_pad(amp_ap.astype(np.complex64), [sy.n_domain, sx.n_domain]), workers=workers)
    inv_lam2 = 1.0 / wavelength_m**2
    slx, wx = _detector_weights(sx, detector_m)
    sly, wy = _detector_weights(sy, detector_m)
    out = np.empty(len(tan))
    for i, (tx, ty) in enumerate(tan):
        norm = math.sqrt(1.0 + tx * tx + ty * ty)
        f0x, f0y = -tx / norm / wavelength_m, -ty / norm / wavelength_m
        fx, kx = _axis_freqs(sx, f0x, wavelength_m)
        fy, ky = _axis_freqs(sy, f0y, wavelength_m)
        f2 = fy[:, None] ** 2 + fx[None, :] ** 2
        phase = 2 * np.pi * d_f_m * _kz_minus(f2, f0x**2 + f0y**2, inv_lam2)
        keep = ky[:, None] & kx[None, :] & (f2 * wavelength_m**2 < 1.0)
        h = np.where(keep, np.exp(1j * phase.astype(np.float32)), np.complex64(0)).astype(np.complex64)
        g = sfft.ifft(spec * h, axis=0, workers=workers)[sly]  # only the detector's rows
        u = sfft.ifft(g, axis=1, workers=workers)[:, slx]
        out[i] = float(wy @ (np.abs(u) ** 2) @ wx)
    return out
