"""How far the ray model is from the wave response for a mixel, and why (u, dot pitch, rim)."""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np

from mincam_sim.masks import Mask
from mincam_sim.masks import profiles as prof
from mincam_sim.model.optics import Mixel
from mincam_sim.wave.geometric import geometric_response
from mincam_sim.wave.response import angular_response
from mincam_sim.wave.sampling import dot_pitch_m
from mincam_sim.wave.spectrum import DEFAULT_WAVELENGTHS_M, _check_wavelengths

VALIDITY_TOLERANCE = 0.01  # geometric optics is flagged when it is off by more than this (relative)


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
    r = angular_response(open_mixel, pts, (wavelength_m,), qe=None)  # one wavelength: no spectral weighting
    g = geometric_response(open_mixel, pts)
    bad = np.nonzero(np.abs(r - g) > tolerance * np.maximum(g, 1e-12))[0]
    return float(np.degrees(np.arctan(t[bad[0]]))) if len(bad) else float(np.degrees(np.arctan(t[-1])))


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


U_ONE_PERCENT = 0.09  # u at which a sinusoidal intensity mask loses 1 % of its fundamental (measured, README)


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
    reasons = []
    p = mixel.mask.profile
    while isinstance(p, prof.Affine):
        p = p.inner
    if isinstance(p, prof.Sinusoid) and p.omega_rad_per_m > 0 and p.a1 != 0:
        period = 2 * np.pi / p.omega_rad_per_m
        u = talbot_parameter(period, mixel.d_f_m, wavelength_m)
        if u > U_ONE_PERCENT:
            reasons.append(f"its sinusoid's period {period * 1e3:.3g} mm gives u = lambda d_f / p^2 = {u:.2g} > "
                           f"{U_ONE_PERCENT} (more than 1 % contrast lost)")
    pitch = dot_pitch_m(mixel.mask)
    if pitch is None and mixel.mask.profile is None and mixel.mask.interpolation == "nearest":
        pitch = min(mixel.mask.width_m / mixel.mask.shape[1], mixel.mask.height_m / mixel.mask.shape[0])
    if pitch is not None:
        u = talbot_parameter(pitch, mixel.d_f_m, wavelength_m)
        if u > U_ONE_PERCENT and np.ptp(mixel.mask.transmission) > 0:
            reasons.append(f"its printed dots {pitch * 1e6:.3g} um apart give u = {u:.2g} > {U_ONE_PERCENT} "
                           "(printed films measured 2-8 % rms off at 600-2400 dpi)")
    if warn and reasons:
        warnings.warn(f"mixel {mixel.name!r} is rendered with geometric optics but {'; '.join(reasons)}: check it "
                      "with mincam_sim.wave.validity(mixel) or render it with optics = \"wave\"",
                      UserWarning, stacklevel=2)
    return reasons
