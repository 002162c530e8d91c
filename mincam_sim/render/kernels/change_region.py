"""Where a frame can change a mixel's measurement: bounds on its aperture (mask) plane, from scene bounds.

A frame changes the rays that meet a moving object, and the rays that land where a moving object shadows a
light. Both sets are bounded by convex point sets in the world:

* the moving objects' axis-aligned bounding boxes (their 8 corners each);
* their shadow volumes, truncated at the scene's bounding box: every segment from a light point ``l`` through an
  object point ``b`` continued to ``l + t (b - l)``, ``1 <= t <= T``; that set lies inside the convex hull of
  the corner points ``b_j`` and ``l_i + T (b_j - l_i)`` (the map is affine in ``l`` and ``b`` for fixed ``t``
  and linear in ``t``), with ``T`` the largest exit parameter of those lines from the scene's box. Lights are
  boxes (emitting shapes) or points (point and spot lights: a box of zero size); a directional light (parallel
  rays along ``d``) shadows ``b + t d``, ``t >= 0``, held by the corners ``b_j`` and ``b_j + T d``.

A ray of the fast sensor runs from a detector point ``x_d`` (local ``z = 0``) through a mask point ``x_m``
(local ``z = d_f``); it reaches a local point ``X`` when ``x_m = x_d (1 - d_f / Z) + X d_f / Z``. For a fixed
``x_d`` the rays reaching a convex set are bounded by the projections of its corners, and that projection is
affine in ``x_d``; so in the sensor's aperture-sample units ``s = x_m / w + 1/2`` (``[0, 1]^2`` covers the
mask) the region, given the detector point, is the rectangle::

    lo(x_d) = B_lo + min(a_min x_d, a_max x_d) / w,   hi(x_d) = B_hi + max(a_min x_d, a_max x_d) / w

with ``B`` the extreme corner terms ``X d_f / (Z w) + 1/2`` and ``a = 1 - d_f / Z`` over the corners (per axis,
``w`` the mask's width or height). :class:`ApertureRegions` holds these coefficients per mixel; the estimator
(:mod:`.stratified`) clips the rectangle to the aperture. The bounds need not be tight or even right: the rest
of the aperture is sampled too (indirect light, an object missed by the bounds), they only move variance.
Pure numpy; scene bounds come from the renderer.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mincam_sim.model.optics import Mincam

BoxM = tuple[np.ndarray, np.ndarray]  # (min corner (3,), max corner (3,)) of an axis-aligned box [m]
FULL = np.array([-np.inf, -np.inf, np.inf, np.inf])  # "no bound": the whole aperture


@dataclass(frozen=True)
class ApertureRegions:
    """Per-mixel rectangle bounds in aperture-sample units, affine in the detector point.

    Attributes
    ----------
    base : (n_mixels, 4) float
        ``(B_lo_x, B_lo_y, B_hi_x, B_hi_y)`` (dimensionless; ``[0, 1]`` spans the mask). ``lo > hi`` marks an
        empty region (nothing that moves is visible); ``-inf / inf`` the whole aperture.
    slope : (n_mixels, 4) float
        ``(a_min / w, a_max / w, a_min / h, a_max / h)`` [1/m]: multiply the detector point's local x (y) [m].
    detector_half_m : (n_mixels,) float
        Half the detector's side [m] (how far ``x_d`` reaches).
    """

    base: np.ndarray
    slope: np.ndarray
    detector_half_m: np.ndarray

    @classmethod
    def empty(cls, mincam: Mincam) -> ApertureRegions:
        base = np.tile(np.array([1.0, 1.0, 0.0, 0.0]), (len(mincam), 1))
        return cls(base, np.zeros((len(mincam), 4)), _detector_half(mincam))

    @classmethod
    def full(cls, mincam: Mincam) -> ApertureRegions:
        return cls(np.tile(FULL, (len(mincam), 1)), np.zeros((len(mincam), 4)), _detector_half(mincam))

    def union(self, other: ApertureRegions) -> ApertureRegions:
        """Rectangle bounds holding both (an empty side contributes nothing)."""
        a_empty, b_empty = self.is_empty(), other.is_empty()
        base = np.where(a_empty[:, None], other.base, self.base)
        slope = np.where(a_empty[:, None], other.slope, self.slope)
        both = ~a_empty & ~b_empty
        lo = np.minimum(self.base[:, :2], other.base[:, :2])
        hi = np.maximum(self.base[:, 2:], other.base[:, 2:])
        smin = np.minimum(self.slope[:, [0, 2]], other.slope[:, [0, 2]])
        smax = np.maximum(self.slope[:, [1, 3]], other.slope[:, [1, 3]])
        base[both] = np.concatenate([lo, hi], axis=1)[both]
        slope[both] = np.stack([smin[:, 0], smax[:, 0], smin[:, 1], smax[:, 1]], axis=1)[both]
        return ApertureRegions(base, slope, self.detector_half_m)

    def is_empty(self) -> np.ndarray:
        """(n_mixels,) True where the bounds lie wholly off the aperture for every detector point."""
        reach = np.abs(self.slope).max(axis=1) * self.detector_half_m
        lo, hi = self.base[:, :2] - reach[:, None], self.base[:, 2:] + reach[:, None]
        return np.any((lo > 1.0) | (hi < 0.0) | (self.base[:, :2] > self.base[:, 2:]), axis=1)

    def area_fraction(self) -> np.ndarray:
        """(n_mixels,) share of the aperture the region covers for the detector's centre point."""
        lo = np.clip(self.base[:, :2], 0.0, 1.0)
        hi = np.clip(self.base[:, 2:], 0.0, 1.0)
        return np.prod(np.clip(hi - lo, 0.0, None), axis=1)

    def packed(self) -> np.ndarray:
        """(n_mixels, 8) float64: base then slope, what the kernel gathers per lane."""
        return np.concatenate([self.base, self.slope], axis=1)


def box_corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(8, 3) corners of an axis-aligned box [m]."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    idx = np.array([[i >> 0 & 1, i >> 1 & 1, i >> 2 & 1] for i in range(8)], dtype=bool)
    return np.where(idx, hi, lo)


def change_points(objects: Sequence[BoxM], lights: Sequence[BoxM], scene_box: BoxM,
                  directions: Sequence[np.ndarray] = ()) -> np.ndarray:
    """(m, 3) points whose convex hull holds the objects and their shadow volumes inside the scene box [m].

    Parameters
    ----------
    objects : sequence of (lo, hi)
        Bounding boxes of the moving objects [m].
    lights : sequence of (lo, hi)
        Bounding boxes of the lights at a finite place [m]: emitting shapes, and point-like lights as boxes of
        zero size (environment lights have none; see :func:`mixel_regions`).
    scene_box : (lo, hi)
        Bounding box of all the scene's geometry [m]: nothing beyond it can be shadowed.
    directions : sequence of (3,) float
        Directions in which directional lights' parallel rays travel (any length; zero vectors are refused).
    """
    if not objects:
        return np.zeros((0, 3))
    obj = np.concatenate([box_corners(*b) for b in objects])
    lo, hi = (np.asarray(v, float) for v in scene_box)
    parts = [obj]
    if lights:
        light = np.concatenate([box_corners(*b) for b in lights])
        d = obj[None, :, :] - light[:, None, :]  # (L, B, 3) from light corner to object corner
        t_max = max(1.0, _largest_exit(light[:, None, :], d, lo, hi))
        parts.append((light[:, None, :] + t_max * d).reshape(-1, 3))
    for direction in directions:
        d = np.asarray(direction, float)
        if d.shape != (3,) or not np.all(np.isfinite(d)) or not np.any(d):
            raise ValueError(f"directions: a directional light needs a finite non-zero 3-vector, got {direction!r}")
        t_max = max(0.0, _largest_exit(obj, np.broadcast_to(d, obj.shape), lo, hi))
        parts.append(obj + t_max * d)
    return np.concatenate(parts)


def _largest_exit(start: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    """Largest parameter ``t`` at which the lines ``start + t d`` leave the box ``[lo, hi]`` (0 if none do)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t_lo = (lo - start) / d
        t_hi = (hi - start) / d
    t_exit = np.where(d != 0, np.maximum(t_lo, t_hi), np.inf).min(axis=-1)  # leaving the box's slab on one axis
    t_exit = t_exit[np.isfinite(t_exit)]
    return float(t_exit.max()) if t_exit.size else 0.0


def mixel_regions(mincam: Mincam, points_m: np.ndarray | None) -> ApertureRegions:
    """Aperture bounds of the rays that can reach the convex hull of ``points_m`` [m], for each mixel.

    ``None`` means "unbounded" (e.g. an environment light, whose shadows reach everywhere): the whole aperture.
    An empty point set gives empty regions.
    """
    n = len(mincam)
    if points_m is None:
        return ApertureRegions.full(mincam)
    points_m = np.asarray(points_m, float)
    if points_m.size == 0:
        return ApertureRegions.empty(mincam)
    base = np.empty((n, 4))
    slope = np.empty((n, 4))
    for k, mixel in enumerate(mincam):
        local = mixel.pose.to_local(points_m)
        z = local[:, 2]
        if np.any(z <= mixel.d_f_m * (1 + 1e-9)):  # part of the hull at or behind the mask plane: unbounded
            base[k], slope[k] = FULL, 0.0
            continue
        scale = mixel.d_f_m / z
        a = 1.0 - scale
        sx = local[:, 0] * scale / mixel.mask.width_m + 0.5
        sy = local[:, 1] * scale / mixel.mask.height_m + 0.5
        base[k] = [sx.min(), sy.min(), sx.max(), sy.max()]
        slope[k] = [a.min() / mixel.mask.width_m, a.max() / mixel.mask.width_m,
                    a.min() / mixel.mask.height_m, a.max() / mixel.mask.height_m]
    return ApertureRegions(base, slope, _detector_half(mincam))


def _detector_half(mincam: Mincam) -> np.ndarray:
    return np.array([0.5 * m.detector_size_m for m in mincam])
