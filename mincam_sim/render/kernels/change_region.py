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
Several moving shapes far apart would make one rectangle hold the static scene between them:
:func:`mover_regions` keeps a rectangle per shape (and per shape's background place) instead, merging only
overlapping ones (and the closest beyond :data:`MAX_REGIONS`), as a :class:`RegionSet`.
Pure numpy; scene bounds come from the renderer.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

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

    @property
    def n_regions(self) -> int:
        """Rectangles per mixel: one (the kernel samples it with nested strata)."""
        return 1


@dataclass(frozen=True)
class RegionSet:
    """Several rectangle bounds per mixel (one per moving shape and per moving shape's background place, merged
    where they overlap), each one as in :class:`ApertureRegions`; the estimator samples each with rays of its own
    and weighs every ray by all of them (multi-sample importance sampling, :mod:`.stratified`).

    Attributes
    ----------
    base : (n_mixels, n_regions, 4) float
        ``(B_lo_x, B_lo_y, B_hi_x, B_hi_y)`` of each rectangle (dimensionless; ``[0, 1]`` spans the mask).
    slope : (n_mixels, n_regions, 4) float
        ``(a_min / w, a_max / w, a_min / h, a_max / h)`` of each rectangle [1/m].
    detector_half_m : (n_mixels,) float
        Half the detector's side [m].
    distinct : (n_mixels,) int
        How many of a mixel's ``n_regions`` slots (the first ones) hold a rectangle; the others are empty and get
        no rays (:meth:`allocation`); 0: nothing that moves is in view (the kernel samples the whole aperture).
    """

    base: np.ndarray
    slope: np.ndarray
    detector_half_m: np.ndarray
    distinct: np.ndarray
    _allocations: dict = field(default_factory=dict, compare=False, repr=False)  # allocation() by its arguments

    @property
    def n_regions(self) -> int:
        """Rectangle slots per mixel (the same for every mixel)."""
        return int(self.base.shape[1])

    def region(self, k: int) -> ApertureRegions:
        """Slot ``k`` of every mixel as one :class:`ApertureRegions`."""
        return ApertureRegions(self.base[:, k], self.slope[:, k], self.detector_half_m)

    def area_fraction(self) -> np.ndarray:
        """(n_mixels,) share of the aperture the distinct rectangles cover for the detector's centre point (their
        areas summed, at most 1)."""
        lo = np.clip(self.base[:, :, :2], 0.0, 1.0)
        hi = np.clip(self.base[:, :, 2:], 0.0, 1.0)
        area = np.prod(np.clip(hi - lo, 0.0, None), axis=2)
        own = np.arange(self.n_regions)[None, :] < self.distinct[:, None]
        return np.minimum(1.0, np.where(own, area, 0.0).sum(axis=1))

    def allocation(self, counts: Sequence[int], expansions: Sequence[float]) -> np.ndarray:
        """(n_mixels, len(expansions), n_regions) int: how a mixel's ``counts[e]`` rays of expansion ``e`` split over
        its rectangles: one each, the rest in proportion to each one's area scaled by ``expansions[e]`` about its
        centre (widened by its slopes' reach over the detector, clipped to the aperture), largest remainders
        first; empty slots none. They add up to ``counts[e]`` where the mixel has a rectangle (else all 0)."""
        key = (tuple(int(c) for c in counts), tuple(float(e) for e in expansions))
        if key not in self._allocations:
            self._allocations[key] = self._allocation(*key)
        return self._allocations[key]

    def _allocation(self, counts: tuple[int, ...], expansions: tuple[float, ...]) -> np.ndarray:
        if len(counts) != len(expansions):
            raise ValueError(f"counts (rays per expansion) needs one entry per expansion: got {len(counts)} counts, "
                             f"{len(expansions)} expansions")
        n, k_max = self.base.shape[:2]
        reach = np.abs(self.slope).max(axis=2) * self.detector_half_m[:, None]  # (n, K)
        lo, hi = self.base[:, :, :2] - reach[..., None], self.base[:, :, 2:] + reach[..., None]
        own = np.arange(k_max)[None, :] < self.distinct[:, None]
        out = np.zeros((n, len(expansions), k_max), dtype=np.int64)
        for e, (count, scale) in enumerate(zip(counts, expansions, strict=True)):
            with np.errstate(invalid="ignore"):  # an unbounded rectangle: the whole aperture
                mid, half = 0.5 * (lo + hi), 0.5 * scale * (hi - lo)
                box_lo = np.where(np.isfinite(mid), np.clip(mid - half, 0.0, 1.0), 0.0)
                box_hi = np.where(np.isfinite(mid), np.clip(mid + half, 0.0, 1.0), 1.0)
            area = np.where(own, np.prod(np.clip(box_hi - box_lo, 0.0, None), axis=2), 0.0)
            for m in range(n):
                kept = int(self.distinct[m])
                if not kept:
                    continue
                base = 1 if int(count) >= kept else 0
                rest = int(count) - base * kept
                weight = area[m, :kept] + 1e-12
                share = rest * weight / weight.sum()
                alloc = np.floor(share).astype(np.int64)
                order = np.argsort(-(share - alloc), kind="stable")
                alloc[order[:rest - int(alloc.sum())]] += 1
                out[m, e, :kept] = base + alloc
        return out

    def packed(self) -> np.ndarray:
        """(n_mixels, 8 n_regions) float64: each slot's base then slope, what the kernel gathers per lane."""
        return np.concatenate([self.base, self.slope], axis=2).reshape(len(self.base), -1)


MAX_REGIONS = 8  # rectangles a mixel keeps in a RegionSet; beyond, the pair whose bounding box grows least merges


def mover_regions(parts: Sequence[ApertureRegions], max_regions: int = MAX_REGIONS) -> RegionSet:
    """The rectangles of ``parts`` (e.g. one per moving shape in the frame and one per its background place) that a
    mixel sees, per mixel: empty ones dropped, two merged into their bounding rectangle where that covers no more
    than the two apart (nested or overlapping ones), and the pair whose merge adds the least area merged while more
    than ``max_regions`` remain. An unbounded part leaves the mixel one unbounded rectangle. The slots are as many as
    the mixel that keeps the most has, rounded up to a power of two (1, 2, 4, ...: each count is a kernel of its
    own); a mixel's slots beyond its own rectangles are empty.
    """
    if not parts:
        raise ValueError("parts (the rectangle bounds to keep apart) must hold at least one ApertureRegions")
    if int(max_regions) < 1:
        raise ValueError(f"max_regions (rectangles a mixel keeps) must be >= 1, got {max_regions!r}")
    n, half = len(parts[0].base), parts[0].detector_half_m
    base = np.stack([p.base for p in parts], axis=1)  # (n, parts, 4)
    slope = np.stack([p.slope for p in parts], axis=1)
    reach = (np.abs(slope).max(axis=2) * half[:, None])[..., None]  # as ApertureRegions.is_empty, every part at once
    seen = ~np.any((base[..., :2] - reach > 1.0) | (base[..., 2:] + reach < 0.0) | (base[..., :2] > base[..., 2:]),
                   axis=2)  # (n, parts)
    unbounded = np.any(seen & ~np.all(np.isfinite(base), axis=2), axis=1)
    if seen.sum(axis=1).max() <= 1:  # one rectangle or none a mixel (one mover): nothing to merge
        apart = ~unbounded
    else:
        apart = _already_apart(base, slope, seen, half, int(max_regions)) & ~unbounded
    counts = np.where(unbounded, 1, seen.sum(axis=1))
    merged = {}
    for m in np.flatnonzero(~apart & ~unbounded):
        merged[m] = _merged([(base[m, k], slope[m, k]) for k in np.flatnonzero(seen[m])], float(half[m]),
                            int(max_regions))
        counts[m] = len(merged[m])
    most = int(counts.max())
    k_max = 1 if most <= 1 else 1 << (most - 1).bit_length()  # 2, 4, 8, ...: few launch shapes (recordings)
    out_base = np.tile(np.array([1.0, 1.0, 0.0, 0.0]), (n, k_max, 1))
    out_slope = np.zeros((n, k_max, 4))
    rows, cols = np.nonzero(seen & apart[:, None])  # apart: the seen rectangles, in order
    slots = np.cumsum(seen, axis=1)[rows, cols] - 1
    out_base[rows, slots], out_slope[rows, slots] = base[rows, cols], slope[rows, cols]
    out_base[unbounded, 0] = FULL
    for m, rects in merged.items():
        for k, (b, sl) in enumerate(rects):
            out_base[m, k], out_slope[m, k] = b, sl
    return RegionSet(out_base, out_slope, half, counts)


def _already_apart(base: np.ndarray, slope: np.ndarray, seen: np.ndarray, half_m: np.ndarray,
                   max_regions: int) -> np.ndarray:
    """(n,) bool: the mixels whose seen rectangles (``base``, ``slope``: (n, parts, 4); ``seen``: (n, parts)) are
    bounded, at most ``max_regions`` and pairwise apart (every pair's bounding rectangle covers more than the two:
    :func:`_merged` keeps them as they are), found for every mixel at once; the others go through :func:`_merged`.
    Each pair's numbers are those :func:`_merged` computes for it (the same operations, element by element)."""
    half = half_m[:, None, None]
    with np.errstate(invalid="ignore"):  # an unbounded rectangle: such a mixel is not apart
        area = _reach_areas(base, slope, half)  # (n, parts)
        joined = _joined((base[:, :, None], slope[:, :, None]), (base[:, None, :], slope[:, None, :]))
        grow = _reach_areas(*joined, half[..., None]) - area[:, :, None] - area[:, None, :]
    pairs = seen[:, :, None] & seen[:, None, :] & np.triu(np.ones(seen.shape[1:] * 2, dtype=bool), 1)
    bounded = np.all(np.isfinite(base) | ~seen[:, :, None], axis=(1, 2))
    return bounded & (seen.sum(axis=1) <= max_regions) & np.all(np.where(pairs, grow > 0.0, True), axis=(1, 2))


def _reach_areas(base: np.ndarray, slope: np.ndarray, half_m: float) -> np.ndarray:
    """Aperture share each rectangle can cover (``base``, ``slope``: (..., 4)): its base widened by its slopes'
    reach over the detector, clipped to the aperture."""
    reach = np.abs(slope).max(axis=-1, keepdims=True) * half_m
    lo = np.clip(base[..., :2] - reach, 0.0, 1.0)
    hi = np.clip(base[..., 2:] + reach, 0.0, 1.0)
    return np.prod(np.clip(hi - lo, 0.0, None), axis=-1)


def _joined(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The bounding rectangles of ``a`` and ``b`` (as :meth:`ApertureRegions.union`; (base, slope), (..., 4) each,
    broadcast)."""
    base = np.concatenate([np.minimum(a[0][..., :2], b[0][..., :2]), np.maximum(a[0][..., 2:], b[0][..., 2:])], -1)
    lo, hi = np.minimum(a[1], b[1]), np.maximum(a[1], b[1])
    return base, np.stack([lo[..., 0], hi[..., 1], lo[..., 2], hi[..., 3]], axis=-1)


def _merged(rects: list, half_m: float, max_regions: int) -> list:
    """``rects`` with overlapping pairs merged, then the cheapest pairs until at most ``max_regions`` remain."""
    rects = list(rects)
    while len(rects) >= 2:
        base = np.array([r[0] for r in rects])
        slope = np.array([r[1] for r in rects])
        area = _reach_areas(base, slope, half_m)
        joined = _joined((base[:, None], slope[:, None]), (base[None, :], slope[None, :]))
        grow = _reach_areas(*joined, half_m) - area[:, None] - area[None, :]
        grow[np.tril_indices(len(rects))] = np.inf
        i, j = np.unravel_index(int(np.argmin(grow)), grow.shape)
        if grow[i, j] > 0.0 and len(rects) <= max_regions:
            break
        rects = [r for q, r in enumerate(rects) if q not in (i, j)] + [(joined[0][i, j], joined[1][i, j])]
    return rects


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
    return mixel_regions_each(mincam, [points_m])[0]


def mixel_regions_each(mincam: Mincam, point_sets: Sequence[np.ndarray | None]) -> list[ApertureRegions]:
    """:func:`mixel_regions` of each point set, every mixel's pose applied once to all of them together (the
    same numbers as a call per set: each point is mapped on its own, and the bounds are per set minima and
    maxima)."""
    n = len(mincam)
    sets = [None if p is None else np.asarray(p, float).reshape(-1, 3) for p in point_sets]
    bounded = [k for k, p in enumerate(sets) if p is not None and len(p)]
    out: list = [None] * len(sets)
    if bounded:
        points = sets[bounded[0]] if len(bounded) == 1 else np.concatenate([sets[k] for k in bounded])
        starts = np.cumsum([0] + [len(sets[k]) for k in bounded[:-1]])
        base = np.empty((n, 4, len(bounded)))
        slope = np.empty((n, 4, len(bounded)))
        for m, mixel in enumerate(mincam):
            local = mixel.pose.to_local(points)
            z = local[:, 2]
            near = z <= mixel.d_f_m * (1 + 1e-9)  # at or behind the mask plane: that point's set is unbounded
            scale = mixel.d_f_m / np.where(near, 1.0, z)
            a = 1.0 - scale
            sx = local[:, 0] * scale / mixel.mask.width_m + 0.5
            sy = local[:, 1] * scale / mixel.mask.height_m + 0.5
            for j, (values, reduce) in enumerate(((sx, np.minimum), (sy, np.minimum), (sx, np.maximum),
                                                  (sy, np.maximum))):
                base[m, j] = reduce.reduceat(values, starts)
            a_lo, a_hi = np.minimum.reduceat(a, starts), np.maximum.reduceat(a, starts)
            slope[m] = [a_lo / mixel.mask.width_m, a_hi / mixel.mask.width_m,
                        a_lo / mixel.mask.height_m, a_hi / mixel.mask.height_m]
            behind = np.logical_or.reduceat(near, starts)
            base[m, :, behind], slope[m, :, behind] = FULL, 0.0
        half = _detector_half(mincam)
        for j, k in enumerate(bounded):
            out[k] = ApertureRegions(base[:, :, j], slope[:, :, j], half)
    return [ApertureRegions.full(mincam) if p is None else ApertureRegions.empty(mincam) if r is None else r
            for p, r in zip(sets, out, strict=True)]


def _detector_half(mincam: Mincam) -> np.ndarray:
    return np.array([0.5 * m.detector_size_m for m in mincam])
