"""The ray model's answer for the same mixel: detector averages of T(x_d + d_f t), exact quadrature."""

from __future__ import annotations

import numpy as np

from mincam_sim.errors import InputError
from mincam_sim.masks import Mask
from mincam_sim.masks import profiles as prof
from mincam_sim.model.optics import Mixel
from mincam_sim.wave.sampling import separable_axis

QUADRATURE_CHUNK_POINTS = 8192  # directions per block of the one-axis quadrature (~13 MB per array)


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
        integral = np.empty(len(tan))
        for start in range(0, len(tan), QUADRATURE_CHUNK_POINTS):  # blocks: ~200 nodes per point held at once
            block = slice(start, start + QUADRATURE_CHUNK_POINTS)
            pos = lo[block, None] + (hi[block] - lo[block])[:, None] * nodes[None, :]
            zero = np.zeros_like(pos)
            xy = (pos, zero) if axis in ("x", "xy") else (zero, pos)
            t = np.broadcast_to(np.asarray(mask.profile.evaluate(*xy, prof.NUMPY_OPS), dtype=np.float64),
                                pos.shape)
            integral[block] = (t @ wts) * (hi[block] - lo[block])
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


def _check_tan(tan_theta) -> np.ndarray:
    tan = np.asarray(tan_theta, dtype=np.float64)
    if tan.ndim == 1 and tan.shape == (2,):
        tan = tan[None]
    if tan.ndim != 2 or tan.shape[1] != 2 or not len(tan) or not np.all(np.isfinite(tan)):
        raise InputError(f"tan_theta must be finite direction tangents of shape (n, 2), n >= 1, got shape "
                         f"{tan.shape}")
    return tan
