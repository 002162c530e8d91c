"""The computational grid of the wave solver and the mask's amplitude on it (one-axis masks, print dots)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import fft as sfft

from mincam_sim.masks import Mask
from mincam_sim.masks import profiles as prof

BAND_MARGIN = 1.5  # keep directions up to this times the geometric reach (a hard cut right at it loses light)


DOMAIN_FACTOR = 1.6  # periodic domain / (aperture + detector): what the kept band needs not to wrap (> 1.25)


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
        from mincam_sim.masks import resample

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
    cell (a :class:`~mincam_sim.masks.profiles.Band`) lands at its true position to ``dx / (2 supersample)``.
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


def dot_pitch_m(mask: Mask) -> float | None:
    """Printer dot pitch [m] of a printed film (``meta["film"]["dpi"]``), else None."""
    film = mask.meta.get("film") if isinstance(mask.meta, dict) else None
    if isinstance(film, dict) and film.get("dpi"):
        return 0.0254 / float(film["dpi"])
    return None


def _align(mask: Mask, axis: int) -> int:
    """Texels across the aperture along ``axis`` (0: x) for a ``"nearest"`` raster (dot edges), else 1."""
    if mask.profile is None and mask.interpolation == "nearest":
        return int(mask.shape[1] if axis == 0 else mask.shape[0])
    return 1
