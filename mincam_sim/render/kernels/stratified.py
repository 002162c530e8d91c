"""Stratified estimates of the fast sensor: most rays where a frame can change things, a few everywhere else.

For every ray the detector point ``x_d`` is drawn uniformly (as in :mod:`.mixel_sensor`); given ``x_d``, the
aperture ``[0, 1]^2`` (aperture-sample units, the whole mask) is split into the *region* rectangle ``R(x_d)``
(:mod:`.change_region`, clipped to the aperture) and its *rest* ``C(x_d)`` (up to four rectangles). A region ray
draws its aperture point uniformly in ``R`` and is weighted by ``|R|``; a rest ray draws uniformly in ``C``
(a rectangle picked in proportion to its area, then a uniform point in it) and is weighted by ``|C|``. For every
``x_d`` both are exact stratum measures, so::

    E = mean over region rays of |R| w L  +  mean over rest rays of |C| w L

is unbiased for the sensor's irradiance whatever the region (a region that misses the change only costs
variance; an empty region leaves the rest stratum the whole aperture). Each (mixel, replicate) group holds
``n_region + n_rest`` lanes; the lane layout depends only on the counts, so two passes with the same seed, counts
and regions (a frame and its background) draw the same random numbers lane by lane, and their difference cancels
everywhere the scenes agree. Values are summed in float64 in a fixed order (as :mod:`.tracing`).

Each ray's detector point, aperture point (in its stratum's own coordinates) and ring pick are one point of an
Owen-scrambled Sobol sequence (:mod:`.qmc`, randomised quasi-Monte Carlo): one scramble per (replicate, mixel,
stratum) drawn from the seed, point ``i`` for the stratum's ``i``-th ray. Every point is uniform (unbiased), the
points of a stratum are balanced over the joint (detector, aperture) domain (less variance from where the
object's edges cut the region; no fixed pairing of strata across the two factors), and replicates are
independent, so their spread stays an honest standard error. The bounces and light samples after them come from
the per-lane sampler. With ``sobol=False`` the points are independent and the region's aperture points sit on a
jittered grid in the region's coordinates (the whole-aperture background value still draws them so).

Several rectangles (a :class:`.change_region.RegionSet`: one per moving shape and per moving shape's background
place, where a mixel sees two or more apart) replace the one region by multi-sample importance sampling with the
balance heuristic (:func:`_mis_sample`): each stratum but the last is split over the rectangles (its rays in
proportion to their areas, one at least each), whose nested strata (region, rings) are laid out as below; the last
samples the whole aperture, and every ray is weighted by ``n_own / sum_s n_s q_s(x)`` over all of them. Unbiased
for any rectangles (the whole aperture always has rays); each (stratum, rectangle) has its own scramble and point
indices, so each rectangle gets a Sobol sequence of its own, and the lane layout still depends only on the counts
(frame and background pair lane by lane). A single rectangle keeps the nested strata without MIS weights (same
numbers as before several rectangles existed).

Where a stratum is empty for a detector point (a ring beyond the aperture's edge; a region that is empty, off the
aperture, or unbounded and so the whole aperture) its rays pool with the outermost non-empty stratum's, weighted
by their share of that stratum's rays: again unbiased, and no ray is spent on nothing. Rays are traced by the scene's
integrator, or by :mod:`.guided_path` when a guide is given (inter-reflection bounces drawn partly toward the
moving shapes; same expectation).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from mincam_sim.model.optics import Mincam
from mincam_sim.render import backend
from mincam_sim.render.kernels import frozen, guided_path, qmc, tracing
from mincam_sim.render.kernels.change_region import ApertureRegions, RegionSet
from mincam_sim.render.kernels.tracing import LaneSampler, launch_seed

DETECTOR_SHRINK = 1 - 2e-6  # as mixel_sensor.mixel_position_sample: keeps x strictly inside the mixel's film cell


def check_strata(counts: Sequence[int], expansions: Sequence[float]) -> None:
    """Raise a ``ValueError`` naming the field unless every stratum has >= 1 ray and the expansions grow."""
    if len(counts) != len(expansions) + 1:
        raise ValueError(f"counts (rays per replicate and mixel in each stratum) needs one entry per expansion "
                         f"plus one for the rest of the aperture: got {len(counts)} counts, {len(expansions)} "
                         "expansions")
    for j, value in enumerate(counts):
        if isinstance(value, bool) or int(value) != value or value < 1:
            raise ValueError(f"counts[{j}] (rays per replicate and mixel in stratum {j}) must be an integer >= 1, "
                             f"got {value!r}; every stratum needs rays, or the estimate is biased")
    if not expansions or expansions[0] != 1.0 or any(b <= a for a, b in zip(expansions, expansions[1:], strict=False)):
        raise ValueError(f"expansions (region scale factors of the nested strata) must start at 1 and grow, "
                         f"got {list(expansions)!r}")


def stratified_estimates(scene, sensor, mincam: Mincam, regions: ApertureRegions | RegionSet, replicates: int,
                         counts: Sequence[int], seed: int, expansions: Sequence[float] = (1.0,),
                         by_stratum: bool = False, jitter: bool = True, guide=None,
                         max_depth: int | None = None, freeze: tuple | None = None, sobol: bool = True) -> np.ndarray:
    """(replicates, n_mixels) independent stratified estimates of each mixel's irradiance [W/m^2].

    Parameters
    ----------
    scene, sensor
        The fast scene and its mixel-array sensor (:class:`.mincam_scene.MincamScene`).
    regions : ApertureRegions or RegionSet
        Per-mixel region bounds (aperture-sample units, affine in the detector point): one rectangle (nested
        strata) or several (:class:`.change_region.RegionSet`: each one's nested strata, combined by multi-sample
        importance sampling).
    replicates : int
        Independent groups per mixel (their spread gives the standard error).
    counts : sequence of int
        Rays per (mixel, replicate) in each stratum: the region, each ring, the rest of the aperture.
    expansions : sequence of float
        Scale factors (about the region's centre) of the nested rectangles: ``(1.0,)`` = region and rest;
        ``(1.0, 3.0)`` adds the ring between the region and the region scaled 3 times (indirect light near it).
    seed : int
        Seed of the launch; same seed, counts and regions give the same random numbers lane by lane.
    by_stratum : bool
        Return (replicates, n_mixels, n_strata): each stratum's part; their sum is the estimate.
    jitter : bool
        Region rays on a jittered grid (one per cell of the largest square grid that fits, the remainder
        uniform): still unbiased (every cell equally often, a uniform point in it), less variance from
        where in the region the object's edges lie. Used only without ``sobol``.
    guide : (centre (3,) [m], radius [m]), optional
        Sphere toward which inter-reflection bounces are guided (:mod:`.guided_path`; the same for both passes of
        a pair). Needs ``max_depth`` (the scene integrator's); without a guide, or at a depth the guided path does
        not reproduce, the scene's own integrator traces the rays.
    freeze : tuple, optional
        Replay each launch from a recording (``dr.freeze``: no Python tracing per call) made with this key,
        :func:`buffers_key` of every object whose parameters changed since the scene was loaded (None:
        trace every launch). Same numbers bit for bit either way.
    sobol : bool
        Each ray's detector point, aperture point and ring pick from an Owen-scrambled Sobol sequence
        (:mod:`.qmc`), one scramble per (replicate, mixel, stratum), point ``i`` for the stratum's ``i``-th ray
        (randomised quasi-Monte Carlo: unbiased, replicates independent); False: independent numbers (and
        ``jitter``).
    """
    return stratified_lanes(scene, sensor, mincam, regions, replicates, counts, seed, expansions, jitter, guide,
                            max_depth, freeze, sobol=sobol).estimates(by_stratum)


class LaneValues:
    """Every lane's ``scale x weight x L`` of one stratified pass (per launch, float64) and, where the pass
    watched boxes, which lanes' paths met one (an ``mi.Bool`` per launch: a segment, shadow rays included,
    crossing a box); ``traced`` lanes were traced (the others were taken from the pass it was paired with).
    Where only some (replicate, mixel) groups were traced (``groups``), the others' lanes hold NaN."""

    def __init__(self, n_mixels: int, replicates: int, counts: list[int], values: list[np.ndarray],
                 touched: list | None, traced: int, groups: np.ndarray | None = None) -> None:
        self.n_mixels, self.replicates, self.counts = n_mixels, replicates, counts
        self.values, self.touched, self.traced, self.groups = values, touched, traced, groups

    def estimates(self, by_stratum: bool = False) -> np.ndarray:
        """(replicates, n_mixels) estimates [W/m^2], or (replicates, n_mixels, n_strata) their parts; lanes
        summed in float64 in a fixed order; NaN for a group that was not traced (see ``groups``)."""
        per = sum(self.counts)
        rows = []
        for value in self.values:
            value = value.reshape(-1, per)
            start, part = 0, []
            for count in self.counts:
                part.append(value[:, start:start + count].sum(axis=1) / count)
                start += count
            rows.append(np.stack(part, axis=1))
        parts = np.concatenate(rows).reshape(self.n_mixels, self.replicates, len(self.counts)).transpose(1, 0, 2)
        return parts if by_stratum else parts.sum(axis=2)


def stratified_lanes(scene, sensor, mincam: Mincam, regions: ApertureRegions | RegionSet, replicates: int,
                     counts: Sequence[int], seed: int, expansions: Sequence[float] = (1.0,), jitter: bool = True,
                     guide=None, max_depth: int | None = None, freeze: tuple | None = None,
                     watch: Sequence[tuple[np.ndarray, np.ndarray]] | None = None,
                     pair: LaneValues | None = None, sobol: bool = True,
                     groups: np.ndarray | None = None) -> LaneValues:
    """The lanes of :func:`stratified_estimates` (same parameters), with two more for a frame and its
    background traced as a pair.

    Parameters
    ----------
    watch : sequence of (lo (3,), hi (3,)) [m], optional
        Boxes (scene coordinates) holding every shape that differs between the two passes, in both places:
        the pass records which lanes' paths cross one. Needs the guided path (a guide and a depth it covers).
    pair : LaneValues, optional
        The other pass of the pair, traced with the same seed, counts, regions and guide, with ``watch``: only
        its lanes that met a box are traced here, and every other lane takes its value. A path that crosses
        none of the boxes meets the same surfaces, draws the same random numbers and casts the same shadow
        rays in both scenes, so its value is the same: the result equals a full pass bit for bit.
    groups : (replicates, n_mixels) bool array, optional
        Trace only the lanes of these (replicate, mixel) groups (None: all), the launches laid out as for all
        ``replicates``: every traced lane draws what it draws in a full pass (the guided path's lane sampler),
        so two calls on complementary groups give a full pass's values. The other groups' lanes hold NaN (or,
        with ``pair``, the pair's values, NaN where the pair did not trace them). Needs the guided path; a
        ``pair`` must have been traced on the same groups (or a superset).
    """
    counts = [int(c) for c in counts]
    check_strata(counts, expansions)
    n_regions = regions.n_regions
    mi = backend.mitsuba()
    import drjit as dr

    n = len(mincam)
    per = sum(counts)
    n_groups = n * int(replicates)
    packed = np.concatenate([regions.packed(), 2.0 * regions.detector_half_m[:, None]], axis=1)  # (n, 9)
    if n_regions > 1:  # then 3 unused, the rays of each stratum but the last per rectangle, in packets of 4
        packed = np.concatenate([packed, np.zeros((n, 3)),
                                 regions.allocation(counts[:-1], expansions).reshape(n, -1)], axis=1)
        packed = np.pad(packed, ((0, 0), (0, _mis_stride(n_regions, len(expansions)) - packed.shape[1])))
    coeffs = mi.Float(np.ascontiguousarray(packed.ravel(), dtype=np.float32))
    guided = guide is not None and max_depth is not None and guided_path.supports(max_depth)
    if (watch is not None or pair is not None or groups is not None) and not guided:
        raise ValueError("watch, pair and groups need the guided path: a guide and a max_depth of 1 .. 5")
    group_on = None
    if groups is not None:
        groups = np.asarray(groups, dtype=bool)
        if groups.shape != (int(replicates), n):
            raise ValueError(f"groups (which replicate of which mixel to trace) must have shape (replicates, "
                             f"n_mixels) = ({int(replicates)}, {n}), got {groups.shape}")
        group_on = groups.T.ravel()  # group g = mixel k * replicates + replicate r
    spheres = guided_path.opaque_spheres(guide) if guided else []
    boxes = [tuple(mi.Point3f(*(dr.opaque(mi.Float, float(x)) for x in corner)) for corner in box)
             for box in (watch or [])]
    groups_per_launch = max(1, tracing.MAX_LANES // per)
    trace = _launch if freeze is None else frozen.frozen(scene, _launch)
    values, touched, traced = [], ([] if watch is not None else None), 0
    for launch, g0 in enumerate(range(0, n_groups, groups_per_launch)):
        ng = min(groups_per_launch, n_groups - g0)
        value = None if pair is None else pair.values[launch].copy()
        if value is None and group_on is not None:
            value = np.full(ng * per, np.nan)
        # lane indices made by Dr.Jit, not mapped from numpy (whose alignment would make a frozen launch record)
        if pair is None or pair.touched is None:
            lanes = dr.arange(mi.UInt32, ng * per)
        else:
            lanes = dr.compress(pair.touched[launch])
        if group_on is not None and not group_on[g0:g0 + ng].all() and dr.width(lanes):
            keep = dr.gather(mi.Bool, mi.Bool(np.ascontiguousarray(group_on[g0:g0 + ng])), lanes // per)
            lanes = dr.gather(mi.UInt32, lanes, dr.compress(keep))  # the lanes of the groups traced
        dr.make_opaque(lanes)
        shape = _LaunchShape(0 if guided else ng * per, tuple(counts), int(replicates), n,
                             tuple(float(e) for e in expansions), bool(jitter), int(max_depth) if guided else 0,
                             getattr(sensor, "version", 0), bool(sobol), n_regions)
        met = mi.Bool(False)
        if dr.width(lanes):
            with frozen.no_cyclic_gc():
                out, met = trace(scene, sensor, coeffs, dr.opaque(mi.UInt32, launch_seed(seed, launch)),
                                 dr.opaque(mi.UInt32, g0), lanes, spheres, boxes, shape, freeze)
            out = np.asarray(out, dtype=np.float64).reshape(-1)
            traced += dr.width(lanes)
            if value is None:
                value = out
            else:
                value[np.asarray(lanes, dtype=np.int64)] = out
        if touched is not None:
            if dr.width(lanes) == ng * per:
                met = dr.zeros(mi.Bool, ng * per) | met  # no box (nothing differs): no lane met one
            else:  # a subset of the groups: the others' lanes met nothing (and are not traced by the pair)
                full = dr.zeros(mi.Bool, ng * per)
                if dr.width(lanes):
                    dr.scatter(full, met, lanes)
                met = full
            dr.eval(met)
            touched.append(met)
        values.append(value)
    return LaneValues(n, int(replicates), counts, values, touched, traced, groups)


class _LaunchShape(NamedTuple):
    """What fixes a launch's kernel code (plain Python values: a frozen launch records again when one
    changes): lanes (0 on the guided path, whose lanes come as an array), rays per stratum, replicates,
    mixels, expansions, jitter, guided depth (0 = the scene's integrator), the sensor's configuration version,
    Sobol points (:mod:`.qmc`) or independent ones, rectangles per mixel (1: nested strata about one region;
    more: :func:`_mis_sample`)."""

    lanes: int
    counts: tuple[int, ...]
    replicates: int
    n_mixels: int
    expansions: tuple[float, ...]
    jitter: bool
    guided_depth: int
    sensor_version: int
    sobol: bool
    n_regions: int = 1


def _launch(scene, sensor, coeffs, seed, g0, lanes, spheres, boxes, shape: _LaunchShape,
            buffers: tuple | None = None):
    """``scale x weight x L`` of the given lanes of one launch (an ``mi.Float``) and whether each one's path
    crossed one of ``boxes`` (an ``mi.Bool``; False without boxes): lane ``l`` is ray ``l % per`` of group
    ``g0 + l // per``. Everything that varies from frame to frame comes in as a Dr.Jit value (``seed``,
    ``g0``, ``lanes``, the region coefficients, the guide spheres, the boxes), so that a frozen launch replays
    it; ``buffers`` only keys the recording (:func:`buffers_key`)."""
    mi = backend.mitsuba()
    import drjit as dr

    counts = shape.counts
    per = sum(counts)
    if shape.guided_depth:
        sampler = LaneSampler.for_launch(seed, lanes)  # any subset of lanes draws what a full launch draws there
    else:
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(seed, shape.lanes)
    per_o = dr.opaque(mi.UInt32, per)
    group = lanes // per_o + g0
    j = lanes % per_o
    stratum = mi.UInt32(0)
    for edge in np.cumsum(counts)[:-1]:
        stratum += mi.UInt32(j >= dr.opaque(mi.UInt32, int(edge)))
    k = group // dr.opaque(mi.UInt32, shape.replicates)
    n_rect, n_exp = shape.n_regions, len(shape.expansions)
    sub = rank = alloc = None
    if n_rect > 1:  # packets of 4 (one load each): the rectangles, the detector's side, the rays per rectangle
        stride = _mis_stride(n_rect, n_exp)
        c = []
        for q in range(stride // 4):
            packet = dr.gather(mi.Array4f, coeffs, k * (stride // 4) + q)
            c += [packet[i] for i in range(4)]
        alloc = [c[8 * n_rect + 4 + e * n_rect:8 * n_rect + 4 + (e + 1) * n_rect] for e in range(n_exp)]
        sub, rank = _mis_technique(dr, mi, alloc, j, stratum, counts)
    else:  # the rectangle's base and slope, the detector's side
        c = [dr.gather(mi.Float, coeffs, k * 9 + i) for i in range(9)]
    if shape.sobol:
        u, v, pick = _sobol_samples(dr, mi, seed, group, j, stratum, counts, sub, rank, n_rect)
    else:
        u = sampler.next_2d()
        v = sampler.next_2d()
        if shape.jitter:
            v = _jittered_region(dr, mi, v, j, counts[0])
        pick = sampler.next_1d()
    wavelength = sampler.next_1d()
    position = mi.Point2f((mi.Float(k) + 0.5 + (u.x - 0.5) * DETECTOR_SHRINK) / shape.n_mixels, u.y)
    x_d = (u.x - 0.5) * DETECTOR_SHRINK * c[8 * n_rect]
    y_d = (u.y - 0.5) * c[8 * n_rect]
    rays = [dr.opaque(mi.Float, float(count)) for count in counts]
    if n_rect > 1:
        aperture, scale = _mis_sample(dr, mi, [c[8 * r:8 * r + 8] for r in range(n_rect)], alloc, x_d, y_d, v,
                                      pick, stratum, sub, list(shape.expansions), rays)
    else:
        aperture, scale = _stratum_sample(dr, mi, c, x_d, y_d, v, pick, stratum, list(shape.expansions), rays)
    ray, weight = sensor.sample_ray_differential(0.0, wavelength, position, aperture)
    if shape.guided_depth:
        radiance, met = guided_path.guided_radiance_watched(scene, sampler, ray, shape.guided_depth, spheres,
                                                            boxes)
    else:
        radiance, _, _ = scene.integrator().sample(scene, sampler, ray, None, True)
        met = mi.Bool(False)
    return scale * weight * radiance, met


def buffers_key(objects, traversals: dict | None = None) -> tuple:
    """Where the parameters of Mitsuba ``objects`` (the shapes a run moves, or the whole scene) live now: the
    address and width of every evaluated array (vertex positions and normals, textures, ...) and the value of
    every scalar. A frozen launch replays only with the key it was recorded with.

    Dr.Jit 1.5 / Mitsuba 3.9 replay a recording with the *addresses* its kernel read the shapes' arrays from
    when it was recorded (the shapes are reached through virtual calls, not through the frozen function's
    inputs). After a vertex update Dr.Jit's allocator hands out one of two addresses in turn, so a replay
    keyed on the launch alone read the previous frame's vertices every other frame. Keyed on the addresses
    as well, a moving mesh makes a recording per address, each replayed only while its address holds the
    current values.

    ``traversals``, a dict the caller keeps (with the objects' lifetime), holds each object's ``mi.traverse``
    between calls; every parameter is still read as it is now."""
    import drjit as dr

    mi = backend.mitsuba()
    parts = []
    for obj in objects:
        params = _traversal(mi, obj, traversals)
        for key in params.keys():
            value = params[key]
            if dr.is_tensor_v(value) and dr.is_jit_v(value):
                value = value.array  # a texture: the address of its flat array (a restored copy lands elsewhere)
            if dr.is_jit_v(value) and dr.depth_v(value) == 1 and dr.width(value) > 1:
                dr.eval(value)
                parts.append((key, int(np.from_dlpack(value).__array_interface__["data"][0]), dr.width(value)))
            elif dr.is_jit_v(value):
                parts.append((key, np.asarray(value).tobytes()))
            else:
                parts.append((key, repr(value)))
    return tuple(parts)


def _traversal(mi, obj, kept: dict | None):
    """``mi.traverse(obj)``, kept in ``kept`` (the caller's, so that it lives no longer than the objects do)
    when given: an object's keys are fixed once it exists, and reading a key reads the object's current value
    (Mitsuba's ``SceneParameters`` looks it up on every read), so a kept traversal gives the addresses and values
    of now, never those of when it was made. The object is held with it, so its ``id`` is not reused while the
    entry lives."""
    if kept is None:
        return mi.traverse(obj)
    entry = kept.get(id(obj))
    if entry is None or entry[0] is not obj:
        entry = kept[id(obj)] = (obj, mi.traverse(obj))
    return entry[1]


def frozen_recordings(scene) -> int:
    """How many times this scene's frozen launch has been recorded (0 if it never ran frozen)."""
    return frozen.recordings(scene, _launch)


def _sobol_samples(dr, mi, seed, group, j, stratum, counts, sub=None, rank=None, n_sub: int = 1):
    """Detector sample ``u``, aperture sample ``v`` and ring pick of each lane from the Owen-scrambled Sobol
    sequence (:mod:`.qmc`): the scramble is drawn from the launch seed, the lane's group and its stratum, the
    point index is the lane's rank among its stratum's rays. ``v`` (which the region's edges cut) takes the
    sequence's first two dimensions, whose projection is a (0, m, 2)-net. With several rectangles (``n_sub``),
    each (stratum, rectangle ``sub`` of ``n_sub``, or ``n_sub`` for none) has a scramble of its own and the
    index is the lane's ``rank`` among that technique's rays (:func:`_mis_technique`)."""
    if sub is None:
        start = mi.UInt32(0)
        for edge in np.cumsum(counts)[:-1]:
            start = dr.select(j >= dr.opaque(mi.UInt32, int(edge)), dr.opaque(mi.UInt32, int(edge)), start)
        # keys with the top bit set: never a lane index (< MAX_LANES), so no scramble is a lane sampler's seed
        key = (group * dr.opaque(mi.UInt32, len(counts)) + stratum) | dr.opaque(mi.UInt32, 0x80000000)
        index = j - start
    else:
        key = ((group * dr.opaque(mi.UInt32, len(counts)) + stratum) * dr.opaque(mi.UInt32, n_sub + 1) + sub
               ) | dr.opaque(mi.UInt32, 0x80000000)
        index = rank
    scramble, _ = mi.sample_tea_32(seed, key)
    p = qmc.owen_sobol(index, scramble, 5)
    return mi.Point2f(p[2], p[3]), mi.Point2f(p[0], p[1]), p[4]


def _mis_stride(n_regions: int, n_expansions: int) -> int:
    """Floats per mixel of the coefficients with several rectangles: 8 per rectangle, the detector's side and 3
    unused, the rays per (expansion, rectangle), padded to packets of 4."""
    return -(-(8 * n_regions + 4 + n_expansions * n_regions) // 4) * 4


def _mis_technique(dr, mi, alloc, j, stratum, counts):
    """Rectangle (``sub``) and rank among that rectangle's rays of each lane of a stratum that several rectangles
    share: stratum ``e``'s lanes go to rectangle 0 for its first ``alloc[e][0]`` ranks, then rectangle 1, ...;
    ``sub`` = the number of rectangles where none takes the lane (the last stratum, rays left over): the whole
    aperture."""
    start = mi.UInt32(0)
    for edge in np.cumsum(counts)[:-1]:
        start = dr.select(j >= dr.opaque(mi.UInt32, int(edge)), dr.opaque(mi.UInt32, int(edge)), start)
    r = j - start
    rank_f = mi.Float(r)  # ranks < 2^24: exact
    sub, before, cum = mi.UInt32(0), mi.Float(0.0), mi.Float(0.0)
    for k in range(len(alloc[0])):
        rays = mi.Float(0.0)
        for e, row in enumerate(alloc):
            rays = dr.select(stratum == e, row[k], rays)
        cum = cum + rays
        past = rank_f >= cum
        sub += mi.UInt32(past)
        before = dr.select(past, cum, before)
    return sub, r - mi.UInt32(before)


def _jittered_region(dr, mi, v, j, n_region: int):
    """Aperture samples of the region lanes ``j < n_region`` on a jittered ``side x side`` grid (normalised
    region coordinates), for the largest complete set of cells; the other lanes keep ``v``."""
    side = math.isqrt(int(n_region))
    if side < 2:
        return v
    cells = side * side
    on_grid = j < dr.opaque(mi.UInt32, (int(n_region) // cells) * cells)
    cell = j % dr.opaque(mi.UInt32, cells)
    side_u, side_f = dr.opaque(mi.UInt32, side), dr.opaque(mi.Float, float(side))
    gx = (mi.Float(cell % side_u) + v.x) / side_f
    gy = (mi.Float(cell // side_u) + v.y) / side_f
    return mi.Point2f(dr.select(on_grid, gx, v.x), dr.select(on_grid, gy, v.y))


def _stratum_sample(dr, mi, c, x_d, y_d, v, pick, stratum, expansions, rays):
    """Aperture sample in [0, 1]^2 and its weight: stratum s is the ring between nested rectangle s - 1 (a
    point for s = 0) and rectangle s (the whole aperture for the last), clipped to the aperture, weighted by
    its measure.

    For a detector point where a stratum is empty (a ring beyond the aperture's edge, a region off the
    aperture or empty; an unbounded region is the whole aperture and leaves every ring empty) its rays
    sample the outermost non-empty stratum instead, and every ray that samples a stratum ``e`` is weighted
    by ``|e| n_own / M_e`` (``n_own`` the rays of its own stratum, ``M_e`` those of all strata that sample
    ``e``): the strata's parts still sum to the aperture's integral for every detector point (unbiased), and
    no ray is spent on nothing. ``rays`` holds each stratum's ray count per group."""
    lo_x = c[0] + dr.minimum(c[4] * x_d, c[5] * x_d)
    lo_y = c[1] + dr.minimum(c[6] * y_d, c[7] * y_d)
    hi_x = c[2] + dr.maximum(c[4] * x_d, c[5] * x_d)
    hi_y = c[3] + dr.maximum(c[6] * y_d, c[7] * y_d)
    empty = ~((hi_x > lo_x) & (hi_y > lo_y) & dr.isfinite(hi_x - lo_x) & dr.isfinite(hi_y - lo_y))
    full = ~(dr.isfinite(lo_x) & dr.isfinite(lo_y) & dr.isfinite(hi_x) & dr.isfinite(hi_y))
    mid_x, mid_y = 0.5 * (lo_x + hi_x), 0.5 * (lo_y + hi_y)
    half_x, half_y = 0.5 * (hi_x - lo_x), 0.5 * (hi_y - lo_y)

    def rect(scale):
        if scale is None:  # the whole aperture
            return (mi.Float(0.0), mi.Float(0.0), mi.Float(1.0), mi.Float(1.0))
        box = [mid_x - scale * half_x, mid_y - scale * half_y, mid_x + scale * half_x, mid_y + scale * half_y]
        box = [dr.select(full, b, dr.clip(x, 0.0, 1.0)) for b, x in zip((0.0, 0.0, 1.0, 1.0), box, strict=True)]
        return [dr.select(empty & ~full, 0.0, x) for x in box]

    rects = [rect(e) for e in expansions] + [rect(None)]
    n_strata = len(rects)

    def bounds(s):
        """(inner, outer) rectangles of stratum s; stratum 0 is a ring around a point at its corner."""
        outer = list(rects[s])
        inner = [outer[0], outer[1], outer[0], outer[1]] if s == 0 else list(rects[s - 1])
        return inner, outer

    areas = [sum(_ring_strips(*bounds(s))) for s in range(n_strata)]
    outermost = mi.UInt32(0)
    for s in range(n_strata):
        outermost = dr.select(areas[s] > 0.0, s, outermost)
    # the stratum each stratum's rays sample here: their own, or the outermost non-empty one
    target = [dr.select(areas[s] > 0.0, mi.UInt32(s), outermost) for s in range(n_strata)]
    own_target = mi.UInt32(0)
    own_rays = mi.Float(0.0)
    for s in range(n_strata):
        own_target = dr.select(stratum == s, target[s], own_target)
        own_rays = dr.select(stratum == s, rays[s], own_rays)
    sharing = mi.Float(0.0)  # rays of every stratum that samples the same stratum as this ray
    for s in range(n_strata):
        sharing += dr.select(target[s] == own_target, rays[s], 0.0)

    inner, outer = bounds(0)
    for s in range(1, n_strata):
        sel = own_target == s
        b_inner, b_outer = bounds(s)
        inner = [dr.select(sel, a, b) for a, b in zip(b_inner, inner, strict=True)]
        outer = [dr.select(sel, a, b) for a, b in zip(b_outer, outer, strict=True)]
    a0, a1, a2, a3 = _ring_strips(inner, outer)
    area = a0 + a1 + a2 + a3
    x0, y0, x1, y1 = _picked_strip(dr, inner, outer, (a0, a1, a2, a3), pick * area)
    aperture = mi.Point2f(x0 + (x1 - x0) * v.x, y0 + (y1 - y0) * v.y)
    return aperture, area * own_rays / sharing


def _ring_strips(inner, outer):
    """Areas of the bottom, top, left and right strips of the ring between ``inner`` and ``outer`` (rectangles
    ``(x0, y0, x1, y1)``, ``inner`` within ``outer``)."""
    ix0, iy0, ix1, iy1 = inner
    ox0, oy0, ox1, oy1 = outer
    return ((ox1 - ox0) * (iy0 - oy0), (ox1 - ox0) * (oy1 - iy1), (ix0 - ox0) * (iy1 - iy0),
            (ox1 - ix1) * (iy1 - iy0))


def _picked_strip(dr, inner, outer, strip_areas, t):
    """``(x0, y0, x1, y1)`` of the strip of the ring between ``inner`` and ``outer`` (bottom, top, left, right
    of the inner rectangle, with areas ``strip_areas``) in which ``t`` (in [0, ring area)) falls."""
    ox0, oy0, ox1, oy1 = outer
    ix0, iy0, ix1, iy1 = inner
    a0, a1, a2, _ = strip_areas
    first, second, third = t < a0, t < a0 + a1, t < a0 + a1 + a2
    x0 = dr.select(first | second | third, ox0, ix1)
    x1 = dr.select(first | second, ox1, dr.select(third, ix0, ox1))
    y0 = dr.select(first, oy0, dr.select(second, iy1, iy0))
    y1 = dr.select(first, iy0, dr.select(second, oy1, iy1))
    return x0, y0, x1, y1


def _mis_sample(dr, mi, regions, alloc, x_d, y_d, v, pick, stratum, sub, expansions, rays):
    """Aperture sample in [0, 1]^2 and its weight for several rectangles per mixel: the nested strata of each
    rectangle, combined by multi-sample importance sampling with the balance heuristic.

    Technique ``(e, k)`` (stratum ``e < len(expansions)``, its lanes given to rectangle ``k`` by
    :func:`_mis_technique`, ``n_ek = alloc[e][k]`` rays) draws its aperture point uniformly in stratum ``e`` of
    rectangle ``k`` as :func:`_stratum_sample` lays them out (the rectangle for ``e = 0``, else the ring between it
    scaled by ``expansions[e - 1]`` and by ``expansions[e]`` about its centre, clipped to the aperture; the ring's
    strip picked by ``pick`` in proportion to its area), or over the whole aperture where that is empty (beyond the
    aperture's edge, an empty or unbounded rectangle); the last stratum's rays, and any a stratum gives no
    rectangle, draw over the whole aperture. Given the detector point, a ray at aperture point ``x`` is weighted by
    ``n_own / sum_s n_s q_s(x)`` over every technique ``s`` (``q_s = 1 / |S_s|`` inside its stratum ``S_s``, 0
    outside, 1 for the whole aperture; ``n_own`` the rays of the ray's stratum, ``rays``): each stratum's lanes
    summed and divided by its rays, the strata added, give ``sum_i f(x_i) / sum_s n_s q_s(x_i)``, unbiased for any
    rectangles since the whole aperture always has rays. A rectangle that overlaps no other is sampled as the nested
    strata sample one region. ``regions`` holds each rectangle's 8 coefficients (as
    :class:`.change_region.RegionSet` packs them)."""
    zero, one = mi.Float(0.0), mi.Float(1.0)

    def bounds(c):
        """Rectangle ``c`` at this detector point: (lo_x, lo_y, hi_x, hi_y) and whether it is finite and not
        empty."""
        lo_x = c[0] + dr.minimum(c[4] * x_d, c[5] * x_d)
        lo_y = c[1] + dr.minimum(c[6] * y_d, c[7] * y_d)
        hi_x = c[2] + dr.maximum(c[4] * x_d, c[5] * x_d)
        hi_y = c[3] + dr.maximum(c[6] * y_d, c[7] * y_d)
        ok = (dr.isfinite(lo_x) & dr.isfinite(lo_y) & dr.isfinite(hi_x) & dr.isfinite(hi_y)
              & (hi_x > lo_x) & (hi_y > lo_y))
        return (lo_x, lo_y, hi_x, hi_y), ok

    def scaled(rect, scale):
        """``rect`` scaled about its centre, clipped to the aperture."""
        lo_x, lo_y, hi_x, hi_y = rect
        mid_x, mid_y = 0.5 * (lo_x + hi_x), 0.5 * (lo_y + hi_y)
        half_x, half_y = 0.5 * (hi_x - lo_x), 0.5 * (hi_y - lo_y)
        return [dr.clip(x, 0.0, 1.0) for x in (mid_x - scale * half_x, mid_y - scale * half_y,
                                              mid_x + scale * half_x, mid_y + scale * half_y)]

    def stratum_of(rect, e):
        """(inner, outer) rectangles of stratum ``e`` of ``rect``: the first one is a ring around its corner."""
        outer = scaled(rect, expansions[e])
        inner = [outer[0], outer[1], outer[0], outer[1]] if e == 0 else scaled(rect, expansions[e - 1])
        return inner, outer

    rects = [bounds(c) for c in regions]
    # this ray's own stratum of its own rectangle, its strip picked by area, a uniform point in the strip
    own_rect, own_ok = list(rects[0][0]), rects[0][1]
    for k in range(1, len(regions)):
        own_rect = [dr.select(sub == k, a, b) for a, b in zip(rects[k][0], own_rect, strict=True)]
        own_ok = dr.select(sub == k, rects[k][1], own_ok)
    inner, outer = stratum_of(own_rect, 0)
    for e in range(1, len(expansions)):
        e_inner, e_outer = stratum_of(own_rect, e)
        inner = [dr.select(stratum == e, a, b) for a, b in zip(e_inner, inner, strict=True)]
        outer = [dr.select(stratum == e, a, b) for a, b in zip(e_outer, outer, strict=True)]
    a0, a1, a2, a3 = _ring_strips(inner, outer)
    area = a0 + a1 + a2 + a3
    sampled = (sub < len(regions)) & (stratum < len(expansions)) & own_ok & (area > 0.0)
    x0, y0, x1, y1 = _picked_strip(dr, inner, outer, (a0, a1, a2, a3), pick * area)
    x0, y0 = dr.select(sampled, x0, zero), dr.select(sampled, y0, zero)
    x1, y1 = dr.select(sampled, x1, one), dr.select(sampled, y1, one)
    px, py = x0 + (x1 - x0) * v.x, y0 + (y1 - y0) * v.y
    own_rays = rays[-1]
    for e in range(len(expansions)):
        own_rays = dr.select(stratum == e, rays[e], own_rays)
    density = rays[-1]  # sum_s n_s q_s at the point: the whole aperture's, then each technique's
    for k, (rect, ok) in enumerate(rects):
        boxes = [scaled(rect, scale) for scale in expansions]
        inside_prev = mi.Bool(False)
        for e in range(len(expansions)):
            outer_e = boxes[e]
            inner_e = [outer_e[0], outer_e[1], outer_e[0], outer_e[1]] if e == 0 else boxes[e - 1]
            ring = sum(_ring_strips(inner_e, outer_e))
            in_outer = (px >= outer_e[0]) & (px <= outer_e[2]) & (py >= outer_e[1]) & (py <= outer_e[3])
            inside = in_outer & ~inside_prev
            inside_prev = in_outer
            usable = ok & (ring > 0.0)
            inside |= (stratum == e) & (sub == k)  # its own stratum holds the point, whatever rounding did
            q = dr.select(usable, dr.select(inside, 1.0 / ring, 0.0), 1.0)
            density += alloc[e][k] * q
    for e in range(len(expansions)):  # a stratum's rays that no rectangle takes sample the whole aperture
        density += rays[e] - sum(alloc[e][1:], alloc[e][0])
    return mi.Point2f(px, py), own_rays / density


def whole_aperture_estimates(scene, sensor, mincam: Mincam, replicates: int, spp: int, seed: int) -> np.ndarray:
    """(replicates, n_mixels) estimates of each mixel's irradiance [W/m^2] over the whole aperture, the aperture
    points on a jittered grid (per replicate and mixel, ``spp / replicates`` rays; the detector point uniform).

    Unbiased like the independent estimator of :mod:`.tracing`; on the tabletop of the benchmarks its standard
    error is ~3x smaller at equal rays. It is :func:`stratified_estimates` with a region that is the whole
    aperture: the rest stratum is then empty, and its one ray per group pools with the region's.
    """
    per = max(1, -(-int(spp) // int(replicates)))
    return stratified_estimates(scene, sensor, mincam, ApertureRegions.full(mincam), replicates, [per, 1], seed,
                                sobol=False)
