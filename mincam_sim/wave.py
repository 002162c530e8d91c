"""Scalar wave optics of a mixel: the detector-averaged power behind a mask, as a function of incidence.

A plane wave arrives from the direction a ray of the geometric model would leave in, with direction tangents
``t = (tan_x, tan_y)`` in physical mask coordinates (+x right, +y up, seen from the detector looking out: the
ray model's mask point is ``x_d + d_f t``). The mask multiplies the field by its amplitude transmission
``sqrt(T)`` (a real, thin, phase-free absorber: printed film, grey ink), the housing blocks everything outside
the aperture, and the field is propagated over ``d_f`` to the detector plane by the band-limited angular
spectrum method. :func:`angular_response` returns the detector average of ``|U|^2`` relative to the incident
intensity: 1 for an infinite open aperture, and in the limit lambda -> 0 the ray model's answer
(``optics="geometric"``: the detector average of ``T(x_d + d_f t)``, zero outside the aperture).

Numerical method (:class:`Sampling`):

* the mask plane is sampled on cells of ``dx`` aligned with the aperture's edges; the amplitude of a raster
  mask with ``"nearest"`` interpolation (printer dots) is area-averaged over each cell;
* the carrier of the tilted wave is never sampled: propagating ``A(x) exp(i 2 pi f0 x)`` is
  ``exp(i 2 pi f0 x) IFFT[ FFT[A](f) H(f + f0) ]`` with ``H(f) = exp(i 2 pi d_f sqrt(1/lambda^2 - |f|^2))``
  (the phase is taken relative to ``H(f0)``, in a cancellation-free form);
* band limit: directions that cannot reach the detector from the aperture, ``|tan| > (w/2 + a)/d_f`` per axis
  (rays), are dropped beyond a margin (:data:`BAND_MARGIN` = 1.5 times that: a hard cut right at the ray limit
  loses up to 1.5 % at the rim, because a plane-wave component is not a ray), and so are evanescent ones; the
  periodic domain (:data:`DOMAIN_FACTOR` x (w + 2 a)) is wide enough that nothing kept wraps onto the
  detector (checked by convergence in domain and cell size: 2e-5 at the rim);
* the detector average weighs each output cell by its overlap with the detector.

Masks whose transmission varies along one axis only (ramps, axis-aligned sinusoids, constants, 1D rasters) are
computed as a product of two exact 1D problems (``method="separable"``): the field factorises, up to the
fourth-order cross term ``lambda^3 d_f f_x^2 f_y^2`` of the propagation phase, which is < 1e-3 rad for every
mask feature and the aperture rim here (checked against the 2D solver in the tests). Other masks (printed
films, halftones, circular ramps) are solved in 2D.

The silicon quantum-efficiency curve for spectral weighting is a model, documented in :func:`silicon_qe`.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import fft as sfft

from . import mask_profiles as prof
from .masks import Mask
from .optics import Mixel

DEFAULT_WAVELENGTHS_M = (550e-9,)  # [m] the sensor model's wavelength
OPTICS = ("geometric", "wave")
MAX_CELLS_2D = 4096  # default cap on 2D grid cells per axis (memory ~ 0.3 GB per complex64 array at 4096^2)
BAND_MARGIN = 1.5  # keep directions up to this times the geometric reach (a hard cut right at it loses light)
DOMAIN_FACTOR = 1.6  # periodic domain / (aperture + detector): what the kept band needs not to wrap (> 1.25)
VALIDITY_TOLERANCE = 0.01  # geometric optics is flagged when it is off by more than this (relative)

# --------------------------------------------------------------------------------------------- silicon QE
# Absorption coefficient of crystalline silicon at 300 K [1/m], rounded from M. A. Green, "Self-consistent
# optical parameters of intrinsic silicon at 300 K including temperature coefficients", Solar Energy Materials
# & Solar Cells 92, 1305-1310 (2008), Table 1 (values there in 1/cm).
_SI_ALPHA_NM = np.array([400, 450, 500, 550, 600, 650, 700, 750, 800, 850, 900, 950, 1000, 1050, 1100.0])
_SI_ALPHA_PER_M = 100.0 * np.array(
    [9.52e4, 2.55e4, 1.11e4, 6.39e3, 4.14e3, 2.81e3, 1.90e3, 1.30e3, 8.50e2, 5.35e2, 3.06e2, 1.57e2, 6.40e1,
     1.63e1, 3.5]
)
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
    lam_nm = np.asarray(wavelength_m, dtype=np.float64) * 1e9
    if np.any(~np.isfinite(lam_nm)) or np.any(lam_nm < _SI_ALPHA_NM[0]) or np.any(lam_nm > _SI_ALPHA_NM[-1]):
        raise ValueError(f"silicon_qe: wavelength_m must lie in [400e-9, 1100e-9] m, got {wavelength_m!r}")
    alpha = np.exp(np.interp(lam_nm, _SI_ALPHA_NM, np.log(_SI_ALPHA_PER_M)))
    return (1.0 - SI_SURFACE_LOSS) * (np.exp(-alpha * SI_DEAD_LAYER_M) - np.exp(-alpha * SI_COLLECTION_DEPTH_M))


def spectral_weights(
    wavelengths_m: Sequence[float], qe: Callable[[np.ndarray], np.ndarray] | None = silicon_qe
) -> np.ndarray:
    """Weights (sum 1) of the wavelengths for a flat photon spectrum seen by a detector of quantum efficiency ``qe``.

    Each wavelength stands for the band between its neighbours' midpoints (trapezoid rule); a single
    wavelength gets weight 1. ``qe=None`` weighs the bands by their width only.
    """
    lam = _check_wavelengths(wavelengths_m)
    if len(lam) == 1:
        return np.ones(1)
    order = np.argsort(lam)
    s = lam[order]
    edges = np.concatenate(([s[0]], 0.5 * (s[1:] + s[:-1]), [s[-1]]))
    width = np.diff(edges)
    w_sorted = width * (np.ones_like(s) if qe is None else np.asarray(qe(s), dtype=np.float64))
    w = np.empty_like(w_sorted)
    w[order] = w_sorted
    if not np.all(np.isfinite(w)) or w.sum() <= 0:
        raise ValueError("spectral_weights: the QE curve gives no weight to these wavelengths")
    return w / w.sum()


def _check_wavelengths(wavelengths_m: Sequence[float]) -> np.ndarray:
    lam = np.atleast_1d(np.asarray(wavelengths_m, dtype=np.float64))
    if lam.ndim != 1 or lam.size == 0 or not np.all(np.isfinite(lam)) or np.any(lam <= 0):
        raise ValueError(f"wavelengths_m must be a non-empty list of positive wavelengths in metres, got "
                         f"{wavelengths_m!r}")
    if np.any(lam > 1e-4):
        raise ValueError(f"wavelengths_m {wavelengths_m!r} look like nanometres; give metres (550e-9 for 550 nm)")
    return lam


# --------------------------------------------------------------------------------------------- mask sampling
def separable_axis(mask: Mask) -> str | None:
    """``"x"`` or ``"y"`` if the transmission varies along that axis only, ``"xy"`` if constant, else None."""
    p = mask.profile
    if p is not None:
        axis = _profile_axis(p)
        if axis is not None or type(p) in _KNOWN_2D:
            return axis
    t = mask.transmission  # a raster, or a profile of unknown kind: judged by its texel picture
    if np.ptp(t) == 0:
        return "xy"
    if np.all(t == t[:1, :]):
        return "x"
    if np.all(t == t[:, :1]):
        return "y"
    return None


_KNOWN_2D = (prof.CircularArc,)


def _profile_axis(p: prof.MaskProfile) -> str | None:
    if isinstance(p, prof.Constant):
        return "xy"
    if isinstance(p, prof.Ramp):
        return "x" if p.kind in ("x", "1-x") else "y"
    if isinstance(p, prof.Sinusoid):
        if p.omega_rad_per_m == 0 or p.a1 == 0:
            return "xy"
        d = p.direction_deg % 180.0
        return "x" if d == 0.0 else ("y" if d == 90.0 else None)
    if isinstance(p, prof.Affine):
        return _profile_axis(p.inner)
    if isinstance(p, prof.Band):
        inner = _profile_axis(p.inner)
        return "x" if inner in ("x", "xy") else None
    return None


def _cell_centres(n: int, d: float) -> np.ndarray:
    return (np.arange(n) - (n - 1) / 2.0) * d


def transmission_on_cells(mask: Mask, nx: int, ny: int) -> np.ndarray:
    """Amplitude transmission ``sqrt(T)`` on an (ny, nx) grid of cells covering the aperture, row 0 at the *bottom*.

    Profiles and bilinear rasters are evaluated at the cell centres; ``"nearest"`` rasters (printer dots) are
    area-averaged over each cell, which keeps dot edges at their true positions to within a cell.
    """
    w, h = mask.width_m, mask.height_m
    if mask.profile is not None:
        x = _cell_centres(nx, w / nx)
        y = _cell_centres(ny, h / ny)
        gx, gy = np.meshgrid(x, y)
        t = np.broadcast_to(np.asarray(mask.profile.evaluate(gx, gy, prof.NUMPY_OPS), dtype=np.float64), gx.shape)
        return np.sqrt(np.clip(t, 0.0, 1.0))
    if mask.interpolation == "nearest":
        from .masks import resample

        amp = Mask(np.sqrt(mask.transmission), w, h, name=f"sqrt({mask.name})", interpolation="nearest")
        return resample(amp, (ny, nx))[::-1].copy()
    from scipy.ndimage import map_coordinates

    rows, cols = mask.shape
    u = (np.arange(nx) + 0.5) / nx * cols - 0.5
    v = (1.0 - (np.arange(ny) + 0.5) / ny) * rows - 0.5  # row index (top = 0) of each cell centre (bottom first)
    gv, gu = np.meshgrid(v, u, indexing="ij")
    t = map_coordinates(mask.transmission, [gv, gu], order=1, mode="nearest")
    return np.sqrt(np.clip(t, 0.0, 1.0))


def _axis_profile_1d(mask: Mask, axis: str, n: int, supersample: int = 16) -> np.ndarray:
    """Amplitude of a one-axis mask on ``n`` cells along ``axis`` (the other axis is uniform).

    A profile's amplitude is averaged over ``supersample`` points per cell, so that a sharp edge inside a
    cell (a :class:`~mincam_sim.mask_profiles.Band`) lands at its true position to ``dx / (2 supersample)``.
    """
    if mask.profile is not None:
        size = mask.width_m if axis == "x" else mask.height_m
        c = _cell_centres(n * supersample, size / (n * supersample))
        zero = np.zeros_like(c)
        x, y = (c, zero) if axis == "x" else (zero, c)
        t = np.broadcast_to(np.asarray(mask.profile.evaluate(x, y, prof.NUMPY_OPS), dtype=np.float64), c.shape)
        return np.sqrt(np.clip(t, 0.0, 1.0)).reshape(n, supersample).mean(axis=1)
    if axis == "x":
        return transmission_on_cells(mask, n, 1)[0] if mask.profile is not None else \
            transmission_on_cells(mask, n, mask.shape[0])[0]
    col = transmission_on_cells(mask, 1, n)[:, 0] if mask.profile is not None else \
        transmission_on_cells(mask, mask.shape[1], n)[:, 0]
    return col


# --------------------------------------------------------------------------------------------- sampling
@dataclass(frozen=True)
class Sampling:
    """One axis of the computational grid.

    Attributes
    ----------
    dx_m : float
        Cell size [m]; the aperture spans exactly ``n_aperture`` cells.
    n_aperture, n_domain : int
        Cells across the aperture and across the periodic domain (``n_domain - n_aperture`` even).
    reach_tan : float
        Largest direction tangent kept: :data:`BAND_MARGIN` times the ray limit ``(w / 2 + a) / d_f`` (a:
        detector half-size); components beyond it are dropped (band limit).
    """

    dx_m: float
    n_aperture: int
    n_domain: int
    reach_tan: float

    @property
    def domain_m(self) -> float:
        return self.dx_m * self.n_domain

    def band_covered(self, wavelength_m: float, tan_in: float) -> float:
        """Fraction of the reachable band ``|f| <= sin(atan(reach_tan)) / lambda`` held at incidence ``tan_in``."""
        f_reach = math.sin(math.atan(self.reach_tan)) / wavelength_m
        f0 = -math.sin(math.atan(tan_in)) / wavelength_m
        nyq = 0.5 / self.dx_m
        lo, hi = max(-f_reach, f0 - nyq), min(f_reach, f0 + nyq)
        return max(0.0, hi - lo) / (2 * f_reach)


def choose_sampling(
    aperture_m: float,
    detector_m: float,
    d_f_m: float,
    wavelength_m: float,
    max_tan: float,
    max_cells: int,
    feature_m: float | None = None,
    shift_m: float = 0.0,
    align: int = 1,
) -> Sampling:
    """Grid for one axis: fine enough for every direction that reaches the detector, capped at ``max_cells``.

    The ideal cell holds the whole reachable band at the steepest incidence ``max_tan``:
    ``dx <= 1 / (2 (f_reach + |f0|))``; it is also at most ``feature_m / 8`` (printer dot pitch) when given.
    When ``max_cells`` forbids it the grid is coarser and :meth:`Sampling.band_covered` says how much of the
    band it holds (reported by :func:`angular_response` in ``info``). The domain is
    :data:`DOMAIN_FACTOR` ``(aperture + detector + 2 shift)`` so that no kept component wraps onto the
    detector. ``align``:
    the cells across the aperture are a multiple of it (a raster's texel count, so printer dots start and end
    on cell edges) whenever the cap allows.
    """
    reach = BAND_MARGIN * (aperture_m / 2 + detector_m / 2) / d_f_m
    f_reach = math.sin(math.atan(reach)) / wavelength_m
    f0 = math.sin(math.atan(max_tan)) / wavelength_m
    dx_ideal = 1.0 / (2.0 * (f_reach + f0))
    if feature_m is not None:
        dx_ideal = min(dx_ideal, feature_m / 8.0)
    domain = DOMAIN_FACTOR * (aperture_m + detector_m + 2 * abs(shift_m)) + 8 * dx_ideal
    n_ap = max(8, math.ceil(aperture_m / dx_ideal))
    n_ap = math.ceil(n_ap / align) * align
    n_dom = math.ceil(domain / aperture_m * n_ap)
    if n_dom > max_cells:
        n_ap = max(8, math.floor(max_cells * aperture_m / domain))
        if n_ap >= align:
            n_ap = n_ap // align * align
        n_dom = math.ceil(domain / aperture_m * n_ap)
    n_dom = sfft.next_fast_len(n_dom)
    while (n_dom - n_ap) % 2:
        n_dom = sfft.next_fast_len(n_dom + 1)
    return Sampling(aperture_m / n_ap, n_ap, n_dom, reach)


# --------------------------------------------------------------------------------------------- propagation
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


# --------------------------------------------------------------------------------------------- geometric
def _clip_interval(lo: np.ndarray, hi: np.ndarray, a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
    return np.maximum(lo, a), np.minimum(hi, b)


def geometric_response(mixel: Mixel, tan_theta: np.ndarray, n_gauss: int = 24) -> np.ndarray:
    """The ray model: detector average of ``T(x_d + d_f t)``, zero outside the aperture (exact quadrature).

    The detector square shifted by ``d_f t`` is clipped to the aperture; on the clipped rectangle, profiles
    and bilinear rasters are integrated by composite Gauss-Legendre (``n_gauss`` nodes per axis on each of
    8 sub-intervals), ``"nearest"`` rasters exactly (texel overlaps).
    """
    tan = _check_tan(tan_theta)
    mask, a, z = mixel.mask, mixel.detector_size_m / 2, mixel.d_f_m
    w, h = mask.width_m, mask.height_m
    cx, cy = z * tan[:, 0], z * tan[:, 1]
    x0, x1 = _clip_interval(cx - a, cx + a, -w / 2, w / 2)
    y0, y1 = _clip_interval(cy - a, cy + a, -h / 2, h / 2)
    area = (2 * a) ** 2
    out = np.zeros(len(tan))
    ok = (x1 > x0) & (y1 > y0)
    if mask.profile is None and mask.interpolation == "nearest":
        rows, cols = mask.shape
        ex = (np.arange(cols + 1) / cols - 0.5) * w
        ey = (0.5 - np.arange(rows + 1) / rows) * h  # top edge first
        for i in np.nonzero(ok)[0]:
            ox = np.clip(np.minimum(ex[1:], x1[i]) - np.maximum(ex[:-1], x0[i]), 0, None)
            oy = np.clip(np.minimum(ey[:-1], y1[i]) - np.maximum(ey[1:], y0[i]), 0, None)
            out[i] = oy @ mask.transmission @ ox / area
        return out
    g, gw = np.polynomial.legendre.leggauss(n_gauss)
    sub = 8
    k = np.arange(sub)
    axis = separable_axis(mask) if mask.profile is not None else None
    if axis is not None:  # one-axis profile: 1D quadrature along its axis, clipped lengths along the other
        nodes = ((k[:, None] + (g[None, :] + 1) / 2) / sub).ravel()
        wts = np.tile(gw / 2 / sub, sub)
        lo, hi = (x0, x1) if axis in ("x", "xy") else (y0, y1)
        pos = lo[:, None] + (hi - lo)[:, None] * nodes[None, :]
        zero = np.zeros_like(pos)
        xy = (pos, zero) if axis in ("x", "xy") else (zero, pos)
        t = np.broadcast_to(np.asarray(mask.profile.evaluate(*xy, prof.NUMPY_OPS), dtype=np.float64), pos.shape)
        integral = (t @ wts) * (hi - lo)
        other = (y1 - y0) if axis in ("x", "xy") else (x1 - x0)
        return np.where(ok, integral * other / area, 0.0)
    for i in np.nonzero(ok)[0]:
        xs = x0[i] + (x1[i] - x0[i]) * ((k[:, None] + (g[None, :] + 1) / 2) / sub).ravel()
        ys = y0[i] + (y1[i] - y0[i]) * ((k[:, None] + (g[None, :] + 1) / 2) / sub).ravel()
        wxs = np.tile(gw / 2 / sub, sub) * (x1[i] - x0[i])
        wys = np.tile(gw / 2 / sub, sub) * (y1[i] - y0[i])
        gx, gy = np.meshgrid(xs, ys)
        out[i] = wys @ _evaluate_mask(mask, gx, gy) @ wxs / area
    return out


def _evaluate_mask(mask: Mask, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
    """Transmission at physical points inside the aperture, as the renderer reads it."""
    if mask.profile is not None:
        return np.broadcast_to(np.asarray(mask.profile.evaluate(x_m, y_m, prof.NUMPY_OPS), dtype=np.float64),
                               x_m.shape)
    from scipy.ndimage import map_coordinates

    rows, cols = mask.shape
    u = (x_m / mask.width_m + 0.5) * cols - 0.5
    v = (0.5 - y_m / mask.height_m) * rows - 0.5
    order = 0 if mask.interpolation == "nearest" else 1
    if order == 0:
        u, v = np.floor(u + 0.5), np.floor(v + 0.5)
    return map_coordinates(mask.transmission, [v, u], order=order, mode="nearest")


def open_fraction(mixel: Mixel, tan_theta: np.ndarray) -> np.ndarray:
    """Geometric response of the open aperture: the fraction of the detector that sees through it at ``t``."""
    tan = _check_tan(tan_theta)
    a, z = mixel.detector_size_m / 2, mixel.d_f_m
    fx = np.clip((mixel.mask.width_m / 2 + a - np.abs(z * tan[:, 0])) / (2 * a), 0.0, 1.0)
    fy = np.clip((mixel.mask.height_m / 2 + a - np.abs(z * tan[:, 1])) / (2 * a), 0.0, 1.0)
    return fx * fy


# --------------------------------------------------------------------------------------------- public API
def _check_tan(tan_theta) -> np.ndarray:
    tan = np.asarray(tan_theta, dtype=np.float64)
    if tan.ndim == 1 and tan.shape == (2,):
        tan = tan[None]
    if tan.ndim != 2 or tan.shape[1] != 2 or not np.all(np.isfinite(tan)):
        raise ValueError(f"tan_theta must be finite direction tangents of shape (n, 2), got shape {tan.shape}")
    return tan


def _check_optics(optics: str) -> str:
    if optics not in OPTICS:
        raise ValueError(f"optics must be 'geometric' or 'wave', got {optics!r}")
    return optics


def dot_pitch_m(mask: Mask) -> float | None:
    """Printer dot pitch [m] of a printed film (``meta["film"]["dpi"]``), else None."""
    film = mask.meta.get("film") if isinstance(mask.meta, dict) else None
    if isinstance(film, dict) and film.get("dpi"):
        return 0.0254 / float(film["dpi"])
    return None


@dataclass
class WaveInfo:
    """How a wave response was computed (per wavelength: grid and the fraction of the reachable band held)."""

    method: str
    wavelengths_m: list[float]
    weights: list[float]
    dx_m: list[tuple[float, float]] = field(default_factory=list)
    cells: list[tuple[int, int]] = field(default_factory=list)
    band_covered_min: float = 1.0

    def as_dict(self) -> dict:
        return dict(vars(self))


def angular_response(
    mixel: Mixel,
    tan_theta: np.ndarray,
    wavelengths_m: Sequence[float] = DEFAULT_WAVELENGTHS_M,
    optics: str = "wave",
    qe: Callable[[np.ndarray], np.ndarray] | None = silicon_qe,
    method: str = "auto",
    max_cells: int | None = None,
    workers: int = 2,
    return_info: bool = False,
):
    """Detector-averaged power behind the mask for plane waves from directions ``tan_theta``.

    Parameters
    ----------
    mixel : Mixel
        Detector size, mask (with its physical size) and ``d_f_m``; its pose does not matter.
    tan_theta : (n, 2) array_like
        Direction tangents (tan_x, tan_y) in physical mask coordinates: the ray model's mask point for detector
        point ``x_d`` is ``x_d + d_f_m * tan_theta`` (+x right, +y up, seen from the detector looking out).
    wavelengths_m : sequence of float
        Wavelengths [m]; several are combined with :func:`spectral_weights` (QE ``qe``, flat photon spectrum).
    optics : {"wave", "geometric"}
        ``"geometric"``: the ray model's answer (:func:`geometric_response`), independent of wavelength.
    method : {"auto", "separable", "2d"}
        ``"auto"``: separable for one-axis masks (:func:`separable_axis`), else 2D.
    max_cells : int, optional
        Cap on grid cells per axis (default: 2**16 for 1D problems, :data:`MAX_CELLS_2D` for 2D).
    workers : int
        Threads for the 2D FFTs.
    return_info : bool
        Also return a :class:`WaveInfo` (grid, band coverage).

    Returns
    -------
    (n,) ndarray
        Power relative to the unobstructed detector (an infinite open aperture gives 1), or
        ``(response, info)``.
    """
    tan = _check_tan(tan_theta)
    if _check_optics(optics) == "geometric":
        g = geometric_response(mixel, tan)
        info = WaveInfo("geometric", [], [])
        return (g, info) if return_info else g
    lam = _check_wavelengths(wavelengths_m)
    weights = spectral_weights(lam, qe)
    axis = separable_axis(mixel.mask)
    if method == "auto":
        method = "separable" if axis is not None else "2d"
    if method not in ("separable", "2d"):
        raise ValueError(f"method must be 'auto', 'separable' or '2d', got {method!r}")
    if method == "separable" and axis is None:
        raise ValueError(f"mask {mixel.mask.name!r} varies along both axes: use method='2d' (or 'auto')")
    info = WaveInfo(method, lam.tolist(), weights.tolist())
    out = np.zeros(len(tan))
    for lam_i, w_i in zip(lam, weights, strict=True):
        if method == "separable":
            r, dx, cells, cov = _separable(mixel, axis, tan, float(lam_i), max_cells or (1 << 16))
        else:
            r, dx, cells, cov = _two_d(mixel, tan, float(lam_i), max_cells or MAX_CELLS_2D, workers)
        out += w_i * r
        info.dx_m.append(dx)
        info.cells.append(cells)
        info.band_covered_min = min(info.band_covered_min, cov)
    return (out, info) if return_info else out


def _axis_setup(mixel: Mixel, axis: str, k: int, lam: float, max_tan: float, max_cells: int):
    """Sampling and aperture amplitude of the 1D problem along axis ``k`` (0: x) of a one-axis mask."""
    mask, det, z = mixel.mask, mixel.detector_size_m, mixel.d_f_m
    size, ax = ((mask.width_m, "x"), (mask.height_m, "y"))[k]
    s = choose_sampling(size, det, z, lam, max_tan, max_cells, dot_pitch_m(mask), align=_align(mask, k))
    amp = _axis_profile_1d(mask, ax, s.n_aperture) if axis == ax else np.ones(s.n_aperture)
    return s, amp


def _uniform_value(mask: Mask, axis: str) -> float:
    """T of a uniform mask (its amplitude is left out of both 1D problems), 1 otherwise."""
    if axis != "xy":
        return 1.0
    if mask.profile is None:
        return float(mask.transmission.flat[0])
    return float(np.asarray(mask.profile.evaluate(np.zeros(1), np.zeros(1), prof.NUMPY_OPS)).ravel()[0])


def _separable(mixel: Mixel, axis: str, tan: np.ndarray, lam: float, max_cells: int):
    res, dxs, cells, cov = [], [], [], 1.0
    for k in (0, 1):
        t, other = tan[:, k], tan[:, 1 - k]
        s, amp = _axis_setup(mixel, axis, k, lam, float(np.max(np.abs(t))), max_cells)
        lam_k = axis_wavelength(lam, t, other)
        pairs, inv = np.unique(np.column_stack([lam_k, t]), axis=0, return_inverse=True)
        res.append(_response_1d(amp, s, mixel.d_f_m, mixel.detector_size_m, pairs[:, 0], pairs[:, 1])[inv.ravel()])
        dxs.append(s.dx_m)
        cells.append(s.n_domain)
        cov = min(cov, min(s.band_covered(lam, float(v)) for v in (t.min(), t.max())))
    return res[0] * res[1] * _uniform_value(mixel.mask, axis), tuple(dxs), tuple(cells), cov


def _align(mask: Mask, axis: int) -> int:
    """Texels across the aperture along ``axis`` (0: x) for a ``"nearest"`` raster (dot edges), else 1."""
    if mask.profile is None and mask.interpolation == "nearest":
        return int(mask.shape[1] if axis == 0 else mask.shape[0])
    return 1


def _two_d(mixel: Mixel, tan: np.ndarray, lam: float, max_cells: int, workers: int):
    mask, det, z = mixel.mask, mixel.detector_size_m, mixel.d_f_m
    feature = dot_pitch_m(mask)
    sx = choose_sampling(mask.width_m, det, z, lam, float(np.max(np.abs(tan[:, 0]))), max_cells, feature,
                         align=_align(mask, 0))
    sy = choose_sampling(mask.height_m, det, z, lam, float(np.max(np.abs(tan[:, 1]))), max_cells, feature,
                         align=_align(mask, 1))
    amp = transmission_on_cells(mask, sx.n_aperture, sy.n_aperture)
    r = _response_2d(amp, sx, sy, z, det, lam, tan, workers)
    cov = min(s.band_covered(lam, float(v)) for s, col in ((sx, 0), (sy, 1))
              for v in (tan[:, col].min(), tan[:, col].max()))
    return r, (sx.dx_m, sy.dx_m), (sx.n_domain, sy.n_domain), cov


# --------------------------------------------------------------------------------------------- tables
@dataclass(frozen=True, eq=False)
class ResponseTable:
    """A mixel's response tabulated on a (tan_x, tan_y) grid, for rendering.

    Attributes
    ----------
    tan_x, tan_y : (nx,), (ny,) ndarray
        Ascending grid of direction tangents (physical mask coordinates).
    wave, geometric, open : (ny, nx) ndarray
        Wave response (spectrally weighted), the ray model's response, and the open-aperture fraction.
    meta : dict
        How it was computed.
    """

    tan_x: np.ndarray
    tan_y: np.ndarray
    wave: np.ndarray
    geometric: np.ndarray
    open: np.ndarray
    meta: dict = field(default_factory=dict)

    def directional_weight(self, min_open: float = 1e-3) -> np.ndarray:
        """``wave / open`` where the aperture is open (>= ``min_open``), else 0.

        A ray through the aperture with direction ``t`` carries this weight instead of ``T(x_m)``: averaged
        over the detector points it is multiplied by ``open(t)``, which gives back ``wave(t)``.
        """
        return np.where(self.open >= min_open, self.wave / np.maximum(self.open, min_open), 0.0)

    def fingerprint_parts(self) -> dict:
        from .identity import array_digest

        return {"tan_x": array_digest(self.tan_x), "tan_y": array_digest(self.tan_y),
                "wave": array_digest(self.wave), "meta": self.meta}


def response_table(
    mixel: Mixel,
    wavelengths_m: Sequence[float] = DEFAULT_WAVELENGTHS_M,
    n_tan: int | None = None,
    qe: Callable[[np.ndarray], np.ndarray] | None = silicon_qe,
    max_cells: int | None = None,
    workers: int = 2,
) -> ResponseTable:
    """Tabulate the mixel's wave response over its whole field of view (``|tan| <= half_fov_tan``).

    ``n_tan`` points per axis (default: 513 for one-axis masks, whose 1D factors are solved on 129 points and
    interpolated, see :func:`_table_separable`; 33 for 2D masks, whose cost is one 2D propagation per point).
    The renderer reads the table bilinearly: its spacing must resolve the response's angular detail (about
    ``min(detector, period) / d_f``); a 2D table is therefore only as good as its ``n_tan`` allows.
    """
    axis = separable_axis(mixel.mask)
    if n_tan is None:
        n_tan = 513 if axis is not None else 33
    if int(n_tan) != n_tan or n_tan < 3:
        raise ValueError(f"n_tan must be an integer >= 3 points per axis, got {n_tan!r}")
    hx, hy = mixel.half_fov_tan()
    tx = np.linspace(-hx, hx, int(n_tan))
    ty = np.linspace(-hy, hy, int(n_tan))
    gx, gy = np.meshgrid(tx, ty)
    pts = np.column_stack([gx.ravel(), gy.ravel()])
    if axis is not None:  # one-axis masks: each axis on a few wavelength levels, interpolated
        wave, info = _table_separable(mixel, axis, tx, ty, wavelengths_m, qe, max_cells or (1 << 16))
    else:
        wave, info = angular_response(mixel, pts, wavelengths_m, "wave", qe, "2d", max_cells, workers,
                                      return_info=True)
        wave = wave.reshape(gy.shape)
    geometric = geometric_response(mixel, pts).reshape(gy.shape)
    opened = open_fraction(mixel, pts).reshape(gy.shape)
    meta = {"n_tan": int(n_tan), "wavelengths_m": list(map(float, _check_wavelengths(wavelengths_m))),
            "qe": getattr(qe, "__name__", "custom") if qe is not None else None, **info.as_dict()}
    return ResponseTable(tx, ty, wave, geometric, opened, meta)


def _lagrange_basis(nodes: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Lagrange basis polynomials of ``nodes`` at ``x``: (len(nodes), len(x))."""
    out = np.ones((len(nodes), len(x)))
    for j, nj in enumerate(nodes):
        for m, nm in enumerate(nodes):
            if m != j:
                out[j] *= (x - nm) / (nj - nm)
    return out


def _table_separable(mixel, axis, tx, ty, wavelengths_m, qe, max_cells, n_solve: int = 129, levels: int = 5):
    """Product table of a one-axis mask from 1D factors solved on ``n_solve`` tangents x ``levels`` wavelengths.

    The factor along x needs the wavelength :func:`axis_wavelength` ``lambda sqrt(s)``, ``s = (1 + tx^2 + ty^2)
    / (1 + tx^2)`` in [1, 1 + max ty^2]; it is solved at ``levels`` Chebyshev points of s, interpolated in s by
    the polynomial through them and in t by a cubic spline. The smooth part of the response (the mask, its
    Talbot contrast) interpolates to < 1e-5; the coherent ripple of the far rim oscillates with wavelength
    (its phase ~ pi rho^2 / (lambda d_f) moves by 2 pi for a 0.2 % change of lambda at rho = 1 mm) and is
    smoothed by the interpolation in s: table and direct solves differ by up to ~1e-3 (tested).
    """
    from scipy.interpolate import CubicSpline

    lam = _check_wavelengths(wavelengths_m)
    weights = spectral_weights(lam, qe)
    gx, gy = np.meshgrid(tx, ty)
    total = np.zeros(gx.shape)
    info = WaveInfo("separable", lam.tolist(), weights.tolist())
    for lam_i, w_i in zip(lam, weights, strict=True):
        factors = []
        for k, (grid, other) in enumerate(((tx, ty), (ty, tx))):
            solve = np.linspace(grid[0], grid[-1], min(n_solve, len(grid)))
            s_max = 1.0 + float(np.max(other**2))
            nodes = 1.0 + (s_max - 1.0) * 0.5 * (1 - np.cos(np.pi * (np.arange(levels) + 0.5) / levels))
            sampling, amp = _axis_setup(mixel, axis, k, float(lam_i), float(np.max(np.abs(grid))), max_cells)
            tt = np.tile(solve, levels)
            ll = np.repeat(float(lam_i) * np.sqrt(nodes), len(solve))
            r = _response_1d(amp, sampling, mixel.d_f_m, mixel.detector_size_m, ll, tt).reshape(levels, len(solve))
            r_grid = CubicSpline(solve, r, axis=1)(grid) if len(solve) < len(grid) else r  # (levels, len(grid))
            t_axis, t_other = (gx, gy) if k == 0 else (gy, gx)
            s_needed = (1 + t_axis**2 + t_other**2) / (1 + t_axis**2)
            col = np.searchsorted(grid, t_axis)  # t_axis values are grid values exactly
            basis = _lagrange_basis(nodes, s_needed.ravel())  # (levels, points)
            factors.append(np.sum(basis * r_grid[:, col.ravel()], axis=0).reshape(gx.shape))
            info.dx_m.append(sampling.dx_m)
            info.cells.append(sampling.n_domain)
        total += w_i * factors[0] * factors[1]
    return total * _uniform_value(mixel.mask, axis), info


# --------------------------------------------------------------------------------------------- validity
def talbot_parameter(period_m: float, d_f_m: float, wavelength_m: float = DEFAULT_WAVELENGTHS_M[0]) -> float:
    """``u = lambda d_f / p^2``: the phase ``pi u`` that the first diffraction order of a period-``p`` grating
    gains against the zeroth over ``d_f`` (paraxial); geometric optics needs u << 0.1."""
    return wavelength_m * d_f_m / period_m**2


def rim_onset_deg(mixel: Mixel, wavelength_m: float = DEFAULT_WAVELENGTHS_M[0],
                  tolerance: float = VALIDITY_TOLERANCE, n: int = 801) -> float:
    """Smallest incidence angle [deg] along x at which the open aperture's wave response differs from the ray
    model by more than ``tolerance`` (relative): the rim's Fresnel ringing, seen where the rim nears the
    detector's view. Beyond it, every mask of this aperture is off by about as much."""
    open_mixel = Mixel(_open_like(mixel.mask), mixel.d_f_m, mixel.detector_size_m)
    t = np.linspace(0.0, open_mixel.half_fov_tan()[0], n)
    pts = np.column_stack([t, 0 * t])
    r = angular_response(open_mixel, pts, (wavelength_m,))
    g = geometric_response(open_mixel, pts)
    bad = np.nonzero(np.abs(r - g) > tolerance * np.maximum(g, 1e-12))[0]
    return float(np.degrees(np.arctan(t[bad[0]]))) if len(bad) else float(np.degrees(np.arctan(t[-1])))


def _open_like(mask: Mask) -> Mask:
    from .masks import constant

    return constant(1.0, 1, mask.width_m, mask.height_m)


def validity(
    mixel: Mixel,
    wavelengths_m: Sequence[float] = DEFAULT_WAVELENGTHS_M,
    n_tan: int = 9,
    tolerance: float = VALIDITY_TOLERANCE,
    warn: bool = True,
    max_cells: int | None = 2048,
) -> dict:
    """How far the ray model is from the wave response for this mixel, and why.

    Reports ``u`` for a periodic (sinusoid) mask, the printer dot pitch and its ``u`` for a printed film, and
    the largest relative difference ``|wave - geometric| / max(geometric)`` over ``n_tan`` directions along
    each axis inside the fully open cone (where the aperture's rim does not cut the detector's view), and
    :func:`rim_onset_deg`, the angle beyond which the rim's Fresnel ringing exceeds ``tolerance``. Warns
    (``UserWarning``) when the central difference exceeds ``tolerance``.
    """
    mask, z, det = mixel.mask, mixel.d_f_m, mixel.detector_size_m
    lam = float(np.min(_check_wavelengths(wavelengths_m)))
    out: dict = {"mixel": mixel.name, "wavelength_m": lam}
    p = mask.profile
    while isinstance(p, prof.Affine):
        p = p.inner
    if isinstance(p, prof.Sinusoid) and p.omega_rad_per_m > 0:
        period = 2 * np.pi / p.omega_rad_per_m
        out["period_m"] = period
        out["u"] = talbot_parameter(period, z, lam)
    pitch = dot_pitch_m(mask)
    if pitch is not None:
        out["dot_pitch_m"] = pitch
        out["u_dot"] = talbot_parameter(pitch, z, lam)
    inner = (min(mask.width_m, mask.height_m) / 2 - det / 2) / z  # fully open cone
    t = np.linspace(-0.9 * inner, 0.9 * inner, n_tan)
    pts = np.concatenate([np.column_stack([t, 0 * t]), np.column_stack([0 * t, t])])
    wave = angular_response(mixel, pts, wavelengths_m, "wave", max_cells=max_cells)
    geo = geometric_response(mixel, pts)
    scale = max(float(np.max(geo)), 1e-12)
    out["max_rel_diff_central"] = float(np.max(np.abs(wave - geo)) / scale)
    out["central_half_angle_deg"] = float(np.degrees(np.arctan(0.9 * inner)))
    out["rim_onset_deg"] = rim_onset_deg(mixel, lam, tolerance)
    out["ok"] = out["max_rel_diff_central"] <= tolerance
    if warn and not out["ok"]:
        why = []
        if "u" in out:
            why.append(f"sinusoid period {out['period_m'] * 1e3:.3g} mm gives u = lambda d_f / p^2 = {out['u']:.3g}")
        if pitch is not None:
            why.append(f"printer dots {pitch * 1e6:.3g} um apart (u = {out['u_dot']:.3g})")
        warnings.warn(
            f"mixel {mixel.name!r}: geometric optics is off by {100 * out['max_rel_diff_central']:.2g} % "
            f"(> {100 * tolerance:g} %) within +-{out['central_half_angle_deg']:.0f} deg"
            + (f" ({'; '.join(why)})" if why else "")
            + "; render it with optics = \"wave\" (Mixel(optics='wave') or [mincam] optics = \"wave\")",
            UserWarning, stacklevel=2,
        )
    return out
