"""The detector-averaged power behind the mask for plane waves from given directions (the public entry)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from mincam_sim.errors import InputError
from mincam_sim.masks import Mask
from mincam_sim.masks import profiles as prof
from mincam_sim.model.optics import Mixel
from mincam_sim.wave.geometric import _check_tan, geometric_response
from mincam_sim.wave.propagation import _response_1d, _response_2d, axis_wavelength
from mincam_sim.wave.sampling import (
    _align,
    _axis_profile_1d,
    choose_sampling,
    dot_pitch_m,
    separable_axis,
    transmission_on_cells,
)
from mincam_sim.wave.spectrum import DEFAULT_WAVELENGTHS_M, _check_wavelengths, silicon_qe, spectral_weights

OPTICS = ("geometric", "wave")


MAX_CELLS_2D = 4096  # default cap on 2D grid cells per axis (memory ~ 0.3 GB per complex64 array at 4096^2)
MIN_CELLS = 64  # the fewest grid cells per axis a caller may ask for (64 read a ramp 0.2 % off, 14 cells 3 %)


def _check_optics(optics: str) -> str:
    if optics not in OPTICS:
        raise InputError(f"optics must be 'geometric' or 'wave', got {optics!r}")
    return optics


def _check_solver_sizes(max_cells: int | None, workers: int) -> None:
    """Refuse a ``max_cells`` (grid cells per axis) or ``workers`` (FFT threads) the solvers cannot use."""
    if max_cells is not None and (isinstance(max_cells, bool) or not isinstance(max_cells, int | np.integer)
                                  or max_cells < MIN_CELLS):
        raise InputError(f"max_cells must be None (the default) or an integer >= {MIN_CELLS} grid cells per axis "
                         f"(14 cells read a ramp 3 % off), got {max_cells!r}")
    if isinstance(workers, bool) or not isinstance(workers, int | np.integer) or workers < 1:
        raise InputError(f"workers must be an integer >= 1 (threads for the 2D FFTs), got {workers!r}")


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


MIN_FRESNEL_NUMBER = 10.0  # the solver's band and periodic domain follow the rays; below it they miss diffraction


def fresnel_number(mixel: Mixel, wavelength_m: float) -> float:
    """The aperture's Fresnel number ``(s / 2)**2 / (wavelength d_f)``, ``s`` the mask's shorter side [m].

    Large (909 for the default 2 mm mask at 2 mm and 550 nm): the field behind the aperture is its geometric
    shadow with Fresnel fringes at the rim. Near 1 and below the aperture diffracts as a whole (far field).
    """
    side_m = min(mixel.mask.width_m, mixel.mask.height_m)
    return (side_m / 2) ** 2 / (wavelength_m * mixel.d_f_m)


def check_fresnel_number(mixel: Mixel, wavelengths_m: np.ndarray) -> None:
    """Refuse (InputError) a mixel whose aperture Fresnel number (:func:`fresnel_number`, at the longest
    wavelength) is below :data:`MIN_FRESNEL_NUMBER`.

    The solver keeps directions up to :data:`~mincam_sim.wave.sampling.BAND_MARGIN` times the rays' reach and a
    periodic domain sized from the rays, which holds while diffraction spreads the field by much less than the
    aperture. Against the closed-form Fresnel diffraction of an open square aperture at normal incidence, its
    answer is off by 0.1-0.5 % at Fresnel numbers 10-40, 2.4 % at 8, 55 % at 3 and 14 % at 1.8 (a 2 mm aperture
    1 m from the detector).
    """
    n_f = fresnel_number(mixel, float(np.max(wavelengths_m)))
    if n_f < MIN_FRESNEL_NUMBER:
        side_m = min(mixel.mask.width_m, mixel.mask.height_m)
        max_d_f = (side_m / 2) ** 2 / (float(np.max(wavelengths_m)) * MIN_FRESNEL_NUMBER)
        raise InputError(
            f"mixel {mixel.name!r}: its aperture's Fresnel number (s/2)^2 / (lambda d_f) is {n_f:.3g} (mask side "
            f"{side_m * 1e3:.3g} mm, d_f {mixel.d_f_m * 1e3:.3g} mm, {np.max(wavelengths_m) * 1e9:.4g} nm), below "
            f"{MIN_FRESNEL_NUMBER:g}: the aperture diffracts as a whole and the wave solver, whose band and domain "
            f"follow the rays, is not accurate there (14 % off at 1.8); give d_f_m <= {max_d_f:.3g} m or a larger "
            "mask")


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
    _check_solver_sizes(max_cells, workers)
    if _check_optics(optics) == "geometric":
        g = geometric_response(mixel, tan)
        info = WaveInfo("geometric", [], [])
        return (g, info) if return_info else g
    lam = _check_wavelengths(wavelengths_m)
    check_fresnel_number(mixel, lam)
    weights = spectral_weights(lam, qe)
    axis = separable_axis(mixel.mask)
    if method == "auto":
        method = "separable" if axis is not None else "2d"
    if method not in ("separable", "2d"):
        raise InputError(f"method must be 'auto', 'separable' or '2d', got {method!r}")
    if method == "separable" and axis is None:
        raise InputError(f"mask {mixel.mask.name!r} varies along both axes: use method='2d' (or 'auto')")
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
