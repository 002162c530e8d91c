"""Closed-form radiometry used to validate the renderer (pure numpy).

View factors follow Howell's catalogue ("A Catalog of Radiation Heat Transfer Configuration Factors",
case B-3: differential planar element to a parallel rectangle with a corner above the element).
"""

from __future__ import annotations

import numpy as np


def _corner_view_factor(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """View factor from a point to the parallel rectangle [0, x] x [0, y] at unit height (signed, odd in x, y)."""
    ax = np.sqrt(1.0 + x * x)
    ay = np.sqrt(1.0 + y * y)
    return (x / ax * np.arctan(y / ax) + y / ay * np.arctan(x / ay)) / (2.0 * np.pi)


def point_to_parallel_rect(x0, x1, y0, y1, height_m) -> np.ndarray:
    """View factor from a differential element (normal towards the rectangle) to a parallel rectangle.

    The rectangle [x0, x1] x [y0, y1] [m] lies in the plane at distance ``height_m`` [m], in coordinates
    centred on the element. Returns 0 for empty rectangles.
    """
    x0, x1, y0, y1 = (np.asarray(v, dtype=float) / height_m for v in (x0, x1, y0, y1))
    f = (
        _corner_view_factor(x1, y1)
        - _corner_view_factor(x0, y1)
        - _corner_view_factor(x1, y0)
        + _corner_view_factor(x0, y0)
    )
    return np.where((x1 > x0) & (y1 > y0), f, 0.0)


def open_aperture_irradiance(
    radiance: float,
    detector_size_m: float,
    aperture_w_m: float,
    aperture_h_m: float,
    d_f_m: float,
    screen_rect_m: tuple[float, float, float, float],
    distance_m: float,
    offset_m: tuple[float, float] = (0.0, 0.0),
    order: int = 48,
) -> float:
    """Mean irradiance [W/m^2] on a square detector behind an open rectangular aperture, facing a parallel
    uniform Lambertian emitter of radiance ``radiance`` [W m^-2 sr^-1].

    ``E = pi L F``, with F the view factor from each detector point to the part of the emitter seen through the
    aperture (the aperture projected from that point onto the emitter plane, clipped to the emitter),
    averaged over the detector by Gauss-Legendre quadrature of ``order`` x ``order`` points.

    Parameters
    ----------
    screen_rect_m : (x0, x1, y0, y1)
        Emitter extent in the detector's frame (x, y parallel to the detector axes) [m].
    distance_m : float
        Distance from the detector plane to the emitter plane [m].
    offset_m : (dx, dy)
        Position of the detector centre relative to the aperture axis [m] (0 for a mixel).
    """
    nodes, w = np.polynomial.legendre.leggauss(order)
    px = offset_m[0] + nodes * detector_size_m / 2
    py = offset_m[1] + nodes * detector_size_m / 2
    gx, gy = np.meshgrid(px, py)
    scale = distance_m / d_f_m
    sx0, sx1, sy0, sy1 = screen_rect_m
    ax0 = gx + (-aperture_w_m / 2 - gx) * scale
    ax1 = gx + (aperture_w_m / 2 - gx) * scale
    ay0 = gy + (-aperture_h_m / 2 - gy) * scale
    ay1 = gy + (aperture_h_m / 2 - gy) * scale
    x0, x1 = np.maximum(ax0, sx0) - gx, np.minimum(ax1, sx1) - gx
    y0, y1 = np.maximum(ay0, sy0) - gy, np.minimum(ay1, sy1) - gy
    f = point_to_parallel_rect(x0, x1, y0, y1, distance_m)
    weights = np.outer(w, w) / 4.0
    return float(np.pi * radiance * np.sum(weights * f))
