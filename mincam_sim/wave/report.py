"""Numbers of the README's wave-optics section (pure numpy): the default sinusoid's contrast, the Talbot curve,
the aperture rim, printed films against their geometric model.

``python -m mincam_sim.wave.report`` prints them (JSON); ``mincam-sim figures --wave`` draws the figure
(:func:`mincam_sim.plotting.figures.make_wave_figure`).
"""

from __future__ import annotations

import json
import math

import numpy as np

from mincam_sim import masks, paper, wave
from mincam_sim.model.optics import Mixel

DEFAULT_PERIOD_M = 0.2e-3  # [m] the README's default sinusoid
CENTRAL_TAN = math.tan(math.radians(17.0))  # the central field used for contrast numbers


def _fundamental(values: np.ndarray, tan: np.ndarray, cycles_per_tan: float) -> complex:
    """Complex amplitude of the component exp(i 2 pi c t) by least squares (with a constant and 2nd harmonic)."""
    w = 2 * np.pi * cycles_per_tan * tan
    a = np.column_stack([np.ones_like(tan), np.cos(w), np.sin(w), np.cos(2 * w), np.sin(2 * w)])
    c = np.linalg.lstsq(a, values, rcond=None)[0]
    return complex(c[1], -c[2])


def sinusoid_contrast(period_m: float = DEFAULT_PERIOD_M, mixel: Mixel | None = None, n: int = 241) -> dict:
    """Wave vs geometric response of a sinusoid mixel over the central +-17 deg (along x).

    Returns the contrast ratio of the fundamental (wave / geometric), the relative change of its frequency
    (free fit) and the largest relative difference ``|R - G| / max G``.
    """
    from scipy.optimize import curve_fit

    mixel = mixel or Mixel(masks.sinusoid(2 * np.pi / period_m))
    t = np.linspace(-CENTRAL_TAN, CENTRAL_TAN, n)
    pts = np.column_stack([t, 0 * t])
    r = wave.angular_response(mixel, pts)
    g = wave.geometric_response(mixel, pts)
    c = mixel.d_f_m / period_m
    fw, fg = _fundamental(r, t, c), _fundamental(g, t, c)

    def model(tt, a0, a1, ph, cyc):
        return a0 + a1 * np.cos(2 * np.pi * cyc * tt + ph)

    p_w = curve_fit(model, t, r, p0=[r.mean(), abs(fw), -np.angle(fw), c])[0]
    p_g = curve_fit(model, t, g, p0=[g.mean(), abs(fg), -np.angle(fg), c])[0]
    return {"period_m": period_m, "u": wave.talbot_parameter(period_m, mixel.d_f_m),
            "contrast_ratio": abs(fw) / abs(fg), "frequency_change": p_w[3] / p_g[3] - 1,
            "max_rel_diff": float(np.max(np.abs(r - g)) / np.max(g))}


def talbot_curve(u_values: np.ndarray, d_f_m: float = paper.D_F_M, a0: float = 0.5, a1: float = 0.5) -> np.ndarray:
    """Signed fundamental ratio (wave / geometric) of a sinusoidal intensity mask against u = lambda d_f / p^2.

    Each point: a 2 mm sinusoid of period ``p = sqrt(lambda d_f / u)`` seen by a detector of p / 4, the
    fundamental taken over one walk-off period (32 directions, DFT bin 1).
    """
    out = []
    lam = wave.DEFAULT_WAVELENGTHS_M[0]
    for u in np.atleast_1d(u_values):
        p = math.sqrt(lam * d_f_m / u)
        mixel = Mixel(masks.sinusoid(2 * np.pi / p, a0, a1), d_f_m, p / 4)
        t = (np.arange(32) - 16) / 32 * p / d_f_m
        pts = np.column_stack([t, 0 * t])
        fw = np.fft.fft(wave.angular_response(mixel, pts))[1]
        fg = np.fft.fft(wave.geometric_response(mixel, pts))[1]
        out.append(float(np.real(fw / fg)))
    return np.array(out)


def rim_profile(mixel: Mixel | None = None, n: int = 801) -> dict:
    """Open-aperture response along x: wave, geometric, and their relative difference, out to the field's edge."""
    mixel = mixel or Mixel(masks.constant(1.0))
    edge = mixel.half_fov_tan()[0]
    t = np.linspace(0.0, edge, n)
    pts = np.column_stack([t, 0 * t])
    r = wave.angular_response(mixel, pts)
    g = wave.geometric_response(mixel, pts)
    return {"tan": t, "wave": r, "geometric": g}


def print_deviation(dpi: float, n: int = 13, max_cells: int = 4096, halftone: str | None = "ordered",
                    period_m: float = DEFAULT_PERIOD_M) -> dict:
    """A printed default sinusoid: wave (2D solver) against its geometric model at ``n`` central directions."""
    film = masks.PrintedFilm(dpi=dpi, halftone=halftone)
    mixel = Mixel(film.print(masks.sinusoid(2 * np.pi / period_m)))
    t = np.linspace(-CENTRAL_TAN, CENTRAL_TAN, n)
    pts = np.column_stack([t, 0.37 * t[::-1]])
    r, info = wave.angular_response(mixel, pts, method="2d", max_cells=max_cells, return_info=True)
    g = wave.geometric_response(mixel, pts)
    rel = (r - g) / g
    return {"dpi": dpi, "halftone": halftone, "rms_rel_diff": float(np.sqrt(np.mean(rel**2))),
            "max_rel_diff": float(np.max(np.abs(rel))), "band_covered_min": info.band_covered_min,
            "dx_m": info.dx_m[0], "tan": t.tolist(), "wave": r.tolist(), "geometric": g.tolist()}


def report() -> dict:
    """All the numbers of the README section."""
    out: dict = {"default_sinusoid": sinusoid_contrast()}
    u = np.array([0.02, 0.05, 0.09, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0])
    out["talbot"] = dict(zip(map(float, u), talbot_curve(u).tolist(), strict=True))
    rim = rim_profile()
    ok = rim["geometric"] > 0.02
    rel = np.where(ok, rim["wave"] / np.where(ok, rim["geometric"], 1) - 1, 0)
    deg = np.degrees(np.arctan(rim["tan"]))
    out["rim"] = {f"{lo}-{hi} deg": float(np.max(np.abs(rel[(deg >= lo) & (deg < hi)])))
                  for lo, hi in ((0, 10), (10, 17), (17, 20), (20, 22), (22, 24), (24, 26), (26, 28))}
    out["rim"]["at_field_edge_min"] = float(np.min(rel[ok]))
    out["prints"] = [{k: v for k, v in print_deviation(dpi, 13, halftone=h).items()
                      if k not in ("tan", "wave", "geometric")}
                     for dpi, h in ((600, "ordered"), (1200, "ordered"), (2400, "ordered"), (600, None))]
    return out


if __name__ == "__main__":  # pragma: no cover
    print(json.dumps(report(), indent=1))
