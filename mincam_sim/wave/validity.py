"""How far the ray model is from the wave response for a mixel, and why (u, dot pitch, rim)."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence

import numpy as np

from mincam_sim.errors import InputError, is_finite_real
from mincam_sim.masks import Mask
from mincam_sim.masks import profiles as prof
from mincam_sim.model.optics import Mixel
from mincam_sim.wave.geometric import geometric_response
from mincam_sim.wave.response import angular_response, fresnel_number
from mincam_sim.wave.sampling import dot_pitch_m
from mincam_sim.wave.spectrum import DEFAULT_WAVELENGTHS_M, _check_wavelengths, silicon_qe

VALIDITY_TOLERANCE = 0.01  # geometric optics is flagged when it is off by more than this (relative)


def talbot_parameter(period_m: float, d_f_m: float, wavelength_m: float = DEFAULT_WAVELENGTHS_M[0]) -> float:
    """``u = lambda d_f / p^2``: the phase ``pi u`` that the first diffraction order of a period-``p`` grating
    gains against the zeroth over ``d_f`` (paraxial); geometric optics needs u << 0.1.

    Parameters
    ----------
    period_m, d_f_m, wavelength_m : float
        Period [m], mask-to-detector distance [m] and wavelength [m], each finite and > 0.

    Returns
    -------
    float
        ``u`` (dimensionless).
    """
    for name, value in (("period_m", period_m), ("d_f_m", d_f_m), ("wavelength_m", wavelength_m)):
        if not is_finite_real(value) or value <= 0:
            raise InputError(f"talbot_parameter: {name} must be a finite number > 0 [m], got {value!r}")
    return wavelength_m * d_f_m / period_m**2


def rim_onset_deg(mixel: Mixel, wavelength_m: float = DEFAULT_WAVELENGTHS_M[0],
                  tolerance: float = VALIDITY_TOLERANCE, n: int = 801) -> float:
    """Smallest incidence angle [deg] along x at which the open aperture's wave response differs from the ray
    model by more than ``tolerance`` (relative): the rim's Fresnel ringing, seen where the rim nears the
    detector's view. Beyond it, every mask of this aperture is off by about as much."""
    _check_tolerance(tolerance)
    wavelength_m = _checked_wavelength(wavelength_m)
    if not is_finite_real(n) or int(n) != n or n < 2:
        raise InputError(f"rim_onset_deg: n must be an integer >= 2 directions, got {n!r}")
    open_mixel = Mixel(_open_like(mixel.mask), mixel.d_f_m, mixel.detector_size_m)
    t = np.linspace(0.0, open_mixel.half_fov_tan()[0], int(n))
    pts = np.column_stack([t, 0 * t])
    r = angular_response(open_mixel, pts, (wavelength_m,), qe=None)  # one wavelength: no spectral weighting
    g = geometric_response(open_mixel, pts)
    bad = np.nonzero(np.abs(r - g) > tolerance * np.maximum(g, 1e-12))[0]
    return float(np.degrees(np.arctan(t[bad[0]]))) if len(bad) else float(np.degrees(np.arctan(t[-1])))


def _checked_wavelength(wavelength_m: float) -> float:
    """One wavelength [m] as a float, refused (InputError naming ``wavelength_m``) unless it is a positive number
    in metres."""
    if not is_finite_real(wavelength_m) or not 0 < wavelength_m <= 1e-4:
        raise InputError(f"wavelength_m must be a positive wavelength in metres (550e-9 for 550 nm), got "
                         f"{wavelength_m!r}")
    return float(wavelength_m)


def _check_tolerance(tolerance: float) -> None:
    """Refuse (InputError) a relative tolerance that is not a number in (0, 1)."""
    if not is_finite_real(tolerance) or not 0 < tolerance < 1:
        raise InputError(f"tolerance must be a relative difference in (0, 1), like {VALIDITY_TOLERANCE} (1 %), got "
                         f"{tolerance!r}")


def _open_like(mask: Mask) -> Mask:
    from mincam_sim.masks import constant

    return constant(1.0, 1, mask.width_m, mask.height_m)


def validity(
    mixel: Mixel,
    wavelengths_m: Sequence[float] = DEFAULT_WAVELENGTHS_M,
    n_tan: int = 9,
    tolerance: float = VALIDITY_TOLERANCE,
    warn: bool = True,
    max_cells: int | None = 2048,
    qe: Callable[[np.ndarray], np.ndarray] | None = silicon_qe,
) -> dict:
    """How far the ray model is from the wave response for this mixel, and why.

    Reports ``u`` for a periodic (sinusoid) mask, the printer dot pitch and its ``u`` for a printed film, and
    the largest relative difference ``|wave - geometric| / max(geometric)`` over ``n_tan`` directions along
    each axis inside the fully open cone (where the aperture's rim does not cut the detector's view), and
    :func:`rim_onset_deg`, the angle beyond which the rim's Fresnel ringing exceeds ``tolerance``. Warns
    (``UserWarning``) when the central difference exceeds ``tolerance``.

    Parameters
    ----------
    mixel : Mixel
        The mixel (mask, ``d_f_m``, detector size).
    wavelengths_m : sequence of float
        Wavelengths [m], weighted by :func:`~mincam_sim.wave.spectral_weights` with ``qe``; ``u`` and the rim
        are reported at the shortest.
    n_tan : int
        Directions per axis inside the fully open cone (at least 2).
    tolerance : float
        Relative difference (a fraction in (0, 1)) above which geometric optics is flagged.
    warn : bool
        Warn when the central difference exceeds ``tolerance``.
    max_cells : int, optional
        Cap on the solver's grid cells per axis.
    qe : callable or None
        Quantum efficiency [electrons per photon] at an array of wavelengths [m] for the spectral weights, as in
        :func:`~mincam_sim.wave.angular_response` (default :func:`~mincam_sim.wave.silicon_qe`, 400-1100 nm);
        ``None`` weighs the bands by their width only.

    Returns
    -------
    dict
        ``mixel``, ``wavelength_m``, ``period_m`` and ``u`` (sinusoids), ``dot_pitch_m`` and ``u_dot``
        (prints), ``max_rel_diff_central``, ``central_half_angle_deg``, ``rim_onset_deg`` [deg] and ``ok``.
    """
    _check_tolerance(tolerance)
    if not is_finite_real(n_tan) or int(n_tan) != n_tan or n_tan < 2:
        raise InputError(f"n_tan must be an integer >= 2 directions per axis, got {n_tan!r}")
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
    t = np.linspace(-0.9 * inner, 0.9 * inner, int(n_tan))
    pts = np.concatenate([np.column_stack([t, 0 * t]), np.column_stack([0 * t, t])])
    wave = angular_response(mixel, pts, wavelengths_m, "wave", qe=qe, max_cells=max_cells)
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


U_ONE_PERCENT = 0.09  # u at which a sinusoidal intensity mask loses 1 % of its fundamental (measured, README)
FRESNEL_ONE_PERCENT = 30.0  # aperture Fresnel number below which its fringes move the detector's power ~1 %


def quick_check(mixel: Mixel, wavelength_m: float = DEFAULT_WAVELENGTHS_M[0], warn: bool = True) -> list[str]:
    """Cheap per-mixel check, no wave solve: reasons why geometric optics may be off by more than 1 %.

    Flags a sinusoid whose ``u = lambda d_f / p^2`` exceeds :data:`U_ONE_PERCENT` (0.09: 1 % loss of contrast)
    and printed dots (a film's dot pitch, or the texel pitch of a ``"nearest"`` raster) with ``u`` above the
    same limit (printed films measured 2-8 % rms off at 600-2400 dpi, README). Mixels already rendered with
    ``optics = "wave"`` are never flagged. The rim's ringing (> 1 % beyond ~24 deg for the default mixel,
    :func:`rim_onset_deg`) is left to :func:`validity`.
    """
    if mixel.optics == "wave":
        return []
    lam = _checked_wavelength(wavelength_m)
    reasons = []
    n_f = fresnel_number(mixel, lam)
    if n_f < FRESNEL_ONE_PERCENT:
        reasons.append(f"its aperture's Fresnel number (s/2)^2 / (lambda d_f) = {n_f:.3g} < {FRESNEL_ONE_PERCENT:g} "
                       "(the aperture's own diffraction fringes reach the detector: about 1 % at 30, 4 % at 9)")
    p = mixel.mask.profile
    while isinstance(p, prof.Affine):
        p = p.inner
    if isinstance(p, prof.Sinusoid) and p.omega_rad_per_m > 0 and p.a1 != 0:
        period = 2 * np.pi / p.omega_rad_per_m
        u = talbot_parameter(period, mixel.d_f_m, lam)
        if u > U_ONE_PERCENT:
            reasons.append(f"its sinusoid's period {period * 1e3:.3g} mm gives u = lambda d_f / p^2 = {u:.2g} > "
                           f"{U_ONE_PERCENT} (more than 1 % contrast lost)")
    pitch = dot_pitch_m(mixel.mask)
    if pitch is None and mixel.mask.profile is None and mixel.mask.interpolation == "nearest":
        pitch = min(mixel.mask.width_m / mixel.mask.shape[1], mixel.mask.height_m / mixel.mask.shape[0])
    if pitch is not None:
        u = talbot_parameter(pitch, mixel.d_f_m, lam)
        if u > U_ONE_PERCENT and np.ptp(mixel.mask.transmission) > 0:
            reasons.append(f"its printed dots {pitch * 1e6:.3g} um apart give u = {u:.2g} > {U_ONE_PERCENT} "
                           "(printed films measured 2-8 % rms off at 600-2400 dpi)")
    if warn and reasons:
        warnings.warn(f"mixel {mixel.name!r} is rendered with geometric optics but {'; '.join(reasons)}: check it "
                      "with mincam_sim.wave.validity(mixel) or render it with optics = \"wave\"",
                      UserWarning, stacklevel=2)
    return reasons
