"""Checks of a built world that would otherwise give silent or misleading numbers: no light at all, a mincam
inside a shape or a shape through a mixel's housing (as built, and frame by frame for the shapes a run moves), a
scene whose size is implausible against the rig (modelled in other units than metres), a mincam so far from the
origin that 32-bit floats misplace what it sees, and the file units scaled to metres (``unit_m``)."""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Sequence

import numpy as np

from mincam_sim.errors import InputError
from mincam_sim.model.optics import Mincam, Mixel
from mincam_sim.render import backend
from mincam_sim.render.scene.world_input import WorldWarning

INSIDE_FRACTION = 0.5  # a mixel whose view meets the back of one-sided faces in this share of directions is inside
SCENE_TOO_LARGE = 1e3  # scene extent / rig size above this: a scene modelled in cm or mm, read as metres?
SCENE_TOO_SMALL = 1.0  # scene extent / rig size below this: the scene is smaller than the rig
MIN_RIG_M = 0.01  # a mincam is taken as at least this size [m] (a single mixel's 2 mm mask sits in a device)
# Mitsuba stores a loaded scene's coordinates in 32-bit floats: at a mincam this far from the file's origin the
# points near it fall on a grid of np.spacing(float32(distance)). Measured (a tilted pair, a car 0.4 m below):
# 1 and 1.2 km (0.06, 0.12 mm grid) read what the origin reads; 100 km (7.8 mm) 10-13 sigma low, 1000 km (62 mm) 2x.
FLOAT32_GRID_WARN_M = 2.5e-4  # [m] a coarser grid near the mincam: a warning (from 4,096 m; 1.2 km is tested)
FLOAT32_GRID_REFUSE_M = 1e-3  # [m] coarser than this: refused (from 16,384 m): the scene is not where it was put


def require_light(scene) -> None:
    """Refuse a world in which nothing emits: every mixel would read exactly 0 in every frame."""
    if not scene.emitters():
        raise InputError("the world holds no light (no area light, point or spot light, sky): every mixel would "
                         "measure 0 in every frame; add an emitter (e.g. ms.sky(1.0) or an area light)")


def require_triangles(scene, skip: set[str]) -> None:
    """Refuse a mesh without a triangle (an empty file, or vertices without faces): Mitsuba loads it, and it
    then fails deep in a gather (with ``face_normals``) or moves nothing."""
    empty = sorted(s.id() for s in scene.shapes()
                   if s.id() not in skip and s.is_mesh() and int(s.primitive_count()) == 0)
    if empty:
        raise InputError(f"{'shapes' if len(empty) > 1 else 'shape'} {', '.join(map(repr, empty))}: a mesh without "
                         "a single triangle (an empty file, or vertices without faces); give it faces or leave it "
                         "out of the scene")


def float32_grid_m(distance_m: float, unit_m: float = 1.0) -> float:
    """[m] the spacing of 32-bit floats at ``distance_m`` from the origin of a file in units of ``unit_m``: how
    finely a loaded scene's points there are placed."""
    return float(np.spacing(np.float32(abs(distance_m) / unit_m))) * unit_m


FLOAT32_GRID_NEAR_RATIO = 1e-3  # grid / distance from a mask to the nearest surface it sees above this: a warning
NEAR_CHECK_MIN_GRID_M = 1e-6  # [m] a finer grid (within ~16 m of the origin) is not worth the rays


def check_far_from_origin(scene, mincam_centre_m, skip: set[str], unit_m: float,
                          mincam: Mincam | None = None) -> None:
    """Refuse (warn for) a world whose mincam sits so far from the coordinates' origin that the 32-bit floats
    Mitsuba loads the scene in place the shapes around it on a grid coarser than :data:`FLOAT32_GRID_REFUSE_M`
    (:data:`FLOAT32_GRID_WARN_M`). A world with no shape of its own (a sky) has nothing to misplace.

    With ``mincam`` (in the scene's coordinates) it also warns where the grid is coarser than
    :data:`FLOAT32_GRID_NEAR_RATIO` times the distance from a mask to the nearest surface it sees: a shape a few
    mm from the masks is misplaced by a share of that distance (at 1.2 km, a 2 mm emitter 1 mm beyond a mask,
    misplaced by tens of um, read 2.8 % low, 17 sigma, with no word)."""
    if not any(s.id() not in skip and s.sensor() is None for s in scene.shapes()):
        return
    distance = float(np.max(np.abs(np.asarray(mincam_centre_m, dtype=float))))
    grid = float32_grid_m(distance, unit_m)
    near = nearest_surface_m(scene, mincam, skip) if mincam is not None and grid > NEAR_CHECK_MIN_GRID_M else None
    close = near is not None and grid > FLOAT32_GRID_NEAR_RATIO * near
    if grid <= FLOAT32_GRID_WARN_M and not close:
        return
    what = (f"the mincam sits {distance:.6g} m from the scene's origin, where the 32-bit floats Mitsuba loads a "
            f"scene in place its points on a {1e3 * grid:.2g} mm grid")
    fix = ("move the scene's origin near the mincam (subtract a local origin from the file's or the elements' "
           f"coordinates and from the mincam's position; within {_within_m(FLOAT32_GRID_WARN_M, unit_m):,.0f} m of "
           f"it the grid is {1e3 * float32_grid_m(_within_m(FLOAT32_GRID_WARN_M, unit_m) / 2, unit_m):.2g} mm or "
           "finer)")
    if grid > FLOAT32_GRID_REFUSE_M:
        raise InputError(f"{what}: the shapes near it are not where they were put and every reading would be off "
                         f"(at 100 km by 10-15 %); {fix}")
    if close and grid <= FLOAT32_GRID_WARN_M:  # where the grid is coarse anyway, the general warning says it
        within = _within_m(FLOAT32_GRID_NEAR_RATIO * near, unit_m)
        warnings.warn(f"{what}, and a surface its masks see lies {1e3 * near:.3g} mm from one: it may be misplaced by "
                      f"up to {100 * grid / near:.2g} % of that distance, and readings be off by about as much (at "
                      f"1.2 km, a lamp 1 mm beyond a mask read 2.8 % low); move the scene's origin within "
                      f"{within:,.0f} m of the mincam (subtract a local origin from the file's or the elements' "
                      "coordinates and from the mincam's position)",
                      WorldWarning, stacklevel=4)
        return
    warnings.warn(f"{what}: readings may be off by a little; {fix}", WorldWarning, stacklevel=4)


def nearest_surface_m(scene, mincam: Mincam, skip: set[str], n_directions: int = 256) -> float | None:
    """[m] the distance from the mask centres of ``mincam`` (in the coordinates of ``scene``) to the nearest
    surface of a shape but ``skip`` (the mincam's own bodies) that they see, along :func:`front_rays` (None if
    they see none)."""
    import drjit as dr

    mi = backend.mitsuba()
    ray, _ = front_rays(list(mincam), n_directions)
    si = scene.ray_intersect(ray)
    theirs = si.is_valid()
    for shape in scene.shapes():  # the few shapes that are not the user's: the bodies, a sensor's shape
        if shape.id() in skip or shape.sensor() is not None:
            theirs &= si.shape != mi.ShapePtr(shape)
    t = np.array(dr.select(theirs, si.t, dr.inf), dtype=float)
    return float(t.min()) if np.isfinite(t).any() else None


def _within_m(grid_m: float, unit_m: float) -> float:
    """[m] the largest distance from the origin whose float32 grid is at most ``grid_m``."""
    return float(2.0 ** (np.floor(np.log2(grid_m / unit_m / np.spacing(np.float32(1.0)))) + 1)) * unit_m


def rig_size_m(mincam: Mincam, least_m: float = MIN_RIG_M) -> float:
    """The rig's size [m]: the spread of its mixels' positions, its largest mask or detector, or ``least_m``
    (:data:`MIN_RIG_M`: the device a single mixel sits in), whichever is largest."""
    positions = np.array([m.pose.position_m for m in mincam])
    spread = float(np.linalg.norm(np.ptp(positions, axis=0)))
    parts = [max(m.mask.width_m, m.mask.height_m, m.detector_size_m) for m in mincam]
    return max(spread, max(parts), least_m)


def user_extent_m(scene, skip: set[str]) -> float | None:
    """The diagonal [m] of the bounding box of the scene's shapes but ``skip`` (None without any)."""
    boxes = [s.bbox() for s in scene.shapes() if s.id() not in skip and s.sensor() is None]
    if not boxes:
        return None
    lo = np.min([np.array(b.min, dtype=float).ravel() for b in boxes], axis=0)
    hi = np.max([np.array(b.max, dtype=float).ravel() for b in boxes], axis=0)
    extent = float(np.linalg.norm(hi - lo))
    return extent if np.isfinite(extent) else None


def warn_if_implausible_size(scene, mincam: Mincam, skip: set[str], unit_m: float) -> None:
    """One :class:`WorldWarning` when the scene is more than :data:`SCENE_TOO_LARGE` times the rig's size
    (:func:`rig_size_m`; a file modelled in cm or mm read as metres) or smaller than the rig."""
    extent, rig = user_extent_m(scene, skip), rig_size_m(mincam)
    if extent is None or rig <= 0:
        return
    units = "metres" if unit_m == 1.0 else f"units of {unit_m:g} m"
    if extent > SCENE_TOO_LARGE * rig:
        warnings.warn(f"the scene spans {extent:.4g} m, {extent / rig:.3g} times the mincam ({rig:.3g} m), read in "
                      f"{units}: a file modelled in cm or mm needs unit_m = 0.01 or 0.001 (a scene this large on "
                      "purpose needs nothing)", WorldWarning, stacklevel=4)
    elif extent < SCENE_TOO_SMALL * (own := rig_size_m(mincam, least_m=0.0)):
        # the rig's own size, without the device a single mixel is taken to sit in: a 2.8 mm lamp before one
        # 2 mm mask is a scene, not a unit mistake
        warnings.warn(f"the scene spans {extent:.4g} m, less than the mincam ({own:.3g} m): read in {units}; check "
                      "unit_m (files are in metres unless unit_m says otherwise)", WorldWarning, stacklevel=4)


def fibonacci_directions(n: int) -> np.ndarray:
    """``n`` unit vectors spread evenly over the sphere (n, 3)."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - z * z)
    phi = np.pi * (1.0 + 5.0**0.5) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


MASK_CORNER_INSET = 0.95  # test points at this share of the mask's half-size (its edges are the bodies' walls)
WATCH_DIRECTIONS = 32  # directions over the sphere of each mask point of a run's watch (15 lie in front)
HOUSING = 5  # the part of a mixel that stands for its housing: rays from the detector to the mask plane
PART_NAMES = ("mask centre", "mask corner", "mask corner", "mask corner", "mask corner", "housing")  # by part


def inside_shapes(scene, mincam: Mincam, skip: set[str], n_directions: int = 256) -> dict[str, str]:
    """Mixels (name -> shape id) that look out at the back of one shape's one-sided faces in at least
    :data:`INSIDE_FRACTION` of the directions in front of their mask: a mixel inside a closed shape (a wall, a
    box) sees only the inside of its faces, which a one-sided material leaves black. Shapes drawn through an
    ``instance`` count as the instance (the shapes of its group, as it places them)."""
    mixels = list(mincam)
    found = _findings(scene, mixels, [(k, 0) for k in range(len(mixels))], _user_shapes(scene, skip), {},
                      n_directions)
    return {mixels[k].name: shape for (k, _), shape in found.items()}


def housing_crossings(scene, mincam: Mincam, skip: set[str]) -> dict[str, str]:
    """Mixels (name -> shape id) whose housing a shape crosses: met by a ray from the detector's centre towards
    the mask before the mask plane (a 4 x 4 grid across the mask). A real mixel is blind to what it hides there;
    the renderer starts its rays at the mask and does not see it."""
    mixels = list(mincam)
    found = _findings(scene, mixels, [(k, HOUSING) for k in range(len(mixels))], _user_shapes(scene, skip), {})
    return {mixels[k].name: shape for (k, _), shape in found.items()}


def _user_shapes(scene, skip: set[str]) -> list:
    return [s for s in scene.shapes() if s.id() not in skip and s.sensor() is None]


def front_rays(mixels: Sequence[Mixel], n_directions: int = 256) -> tuple[object, np.ndarray]:
    """Rays (one ``mi.Ray3f``) from each mixel's mask centre into the directions of ``n_directions`` spread over
    the sphere that lie in front of its mask, and the (mixel, part) of each ray ((n, 2) ints; part 0, the mask
    centre)."""
    o, d, maxt, owner = _probe_rays(mixels, [(k, 0) for k in range(len(mixels))], n_directions)
    return _rays(o, d, maxt), owner


def mask_points_m(mixel: Mixel) -> np.ndarray:
    """The points [m] (5, 3) of ``mixel``'s mask a shape must not close round: its centre (part 0) and four
    points near its corners (:data:`MASK_CORNER_INSET` of its half-size; parts 1-4)."""
    hw, hh = MASK_CORNER_INSET * mixel.mask.width_m / 2, MASK_CORNER_INSET * mixel.mask.height_m / 2
    d = mixel.d_f_m
    return mixel.pose.to_world(np.array([[0.0, 0.0, d], [hw, hh, d], [-hw, hh, d], [-hw, -hh, d], [hw, -hh, d]]))


def _probe_rays(mixels: Sequence[Mixel], points: Sequence[tuple[int, int]],
                n_directions: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Origins, directions, lengths and (mixel, part) of the rays of ``points`` ((mixel index, part)): from a
    mask point (:func:`mask_points_m`) into the directions of ``n_directions`` over the sphere that lie in front
    of the mask, unbounded; for :data:`HOUSING`, from the detector's centre towards a 4 x 4 grid across the mask,
    up to the mask plane."""
    dirs = fibonacci_directions(n_directions)
    origins, directions, lengths, owners = [], [], [], []
    for k, part in points:
        mixel = mixels[k]
        forward = np.asarray(mixel.pose.axes()[2])
        if part != HOUSING:
            point = mask_points_m(mixel)[part]
            out = dirs[dirs @ forward > 0.05]
            length = np.full(len(out), np.inf)
        else:
            point = np.asarray(mixel.pose.position_m, dtype=float)
            u = MASK_CORNER_INSET * (np.arange(4) - 1.5) / 1.5
            x, y = np.meshgrid(u * mixel.mask.width_m / 2, u * mixel.mask.height_m / 2)
            grid = mixel.pose.to_world(np.column_stack([x.ravel(), y.ravel(), np.full(x.size, mixel.d_f_m)]))
            out = grid - point
            length = np.linalg.norm(out, axis=1)
            out /= length[:, None]
            length = length * (1.0 - 1e-4)  # short of the mask plane: what lies on it, the mask's rays meet too
        origins.append(np.repeat(point[None] + 1e-6 * forward, len(out), axis=0))
        directions.append(out)
        lengths.append(length)
        owners.append(np.tile([k, part], (len(out), 1)))
    return np.concatenate(origins), np.concatenate(directions), np.concatenate(lengths), np.concatenate(owners)


def _rays(o: np.ndarray, d: np.ndarray, maxt: np.ndarray):
    mi = backend.mitsuba()
    ray = mi.Ray3f(mi.Point3f(*[mi.Float(o[:, j]) for j in range(3)]),
                   mi.Vector3f(*[mi.Float(d[:, j]) for j in range(3)]))
    if np.isfinite(maxt).any():
        ray.maxt = mi.Float(np.where(np.isfinite(maxt), maxt, np.finfo(np.float32).max).astype(np.float32))
    return ray


def _findings(scene, mixels: Sequence[Mixel], points: Sequence[tuple[int, int]], candidates, known: dict | None,
              n_directions: int = WATCH_DIRECTIONS, rays=None) -> dict[tuple[int, int], str]:
    """The parts ``points`` ((mixel index, part)) that one of ``candidates`` (shapes of ``scene``, the scene the
    rays are traced in: a Mitsuba scene, or a split scene) closes round or crosses, and that shape's id: a mask
    point whose rays meet the back of the shape's one-sided faces first in at least :data:`INSIDE_FRACTION` of
    them; a housing that one of its rays meets the shape in (either side, any material). An ``instance`` is met
    where its group's shapes are met through it. ``rays`` (origins, directions, lengths, owners of
    :func:`_probe_rays`) are the rays to trace where given."""
    import drjit as dr

    mi = backend.mitsuba()
    o, d, maxt, owner = _probe_rays(mixels, points, n_directions) if rays is None else rays
    if not len(owner) or not candidates:
        return {}
    ray = _rays(o, d, maxt)
    si = scene.ray_intersect(ray)
    back = si.is_valid() & (dr.dot(si.n, ray.d) > 0)
    # one launch: the registry id of the shape each ray meets first (0: none), of the instance it meets it
    # through (0: none), and whether it meets the back of a face
    arrays = (dr.reinterpret_array(mi.UInt32, si.shape), dr.reinterpret_array(mi.UInt32, si.instance),
              mi.UInt32(back))
    dr.eval(*arrays)
    first, through, back = (np.array(v, dtype=np.uint32) for v in arrays)
    back = back > 0
    housing = owner[:, 1] == HOUSING
    flat, index = np.unique(owner[:, 0] * len(PART_NAMES) + owner[:, 1], return_inverse=True)
    keys = np.column_stack(np.divmod(flat, len(PART_NAMES)))
    counts = np.bincount(index, minlength=len(keys))
    found: dict[tuple[int, int], str] = {}
    met_ids = set(np.unique(first).tolist()) | set(np.unique(through).tolist())
    for shape in candidates:
        if _registry_id(mi, shape) not in met_ids:
            continue  # no ray met it (nor, for an instance, met anything through it): its group is not probed
        parts = _drawn(scene, shape, known)
        met = _met(mi, first, through, shape, parts)
        met_one_sided = _met(mi, first, through, shape, [part for part in parts if _one_sided(mi, part)])
        share = np.bincount(index, weights=back & met_one_sided & ~housing, minlength=len(keys)) / counts
        crossed = np.bincount(index, weights=met & housing, minlength=len(keys)) > 0
        for (k, part), inside, cross in zip(keys.tolist(), share >= INSIDE_FRACTION, crossed, strict=True):
            if (inside if part != HOUSING else cross) and (k, part) not in found:
                found[(k, part)] = shape.id()
    return found


def _registry_id(mi, shape) -> int:
    """The id a ray's ``si.shape`` (``si.instance``) holds for ``shape``."""
    import drjit as dr

    return int(np.array(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(shape)), dtype=np.uint32).ravel()[0])


def _met(mi, first: np.ndarray, through: np.ndarray, shape, parts: list) -> np.ndarray:
    """Booleans per ray (``first``, ``through``: the registry ids of the shape it meets first and of the instance
    it meets it through): its first hit lies on ``parts`` of ``shape`` (through ``shape`` if an instance)."""
    on_part = np.isin(first, [_registry_id(mi, part) for part in parts])
    if shape.class_name() != "Instance":
        return on_part
    return on_part & (through == _registry_id(mi, shape))


def _one_sided(mi, shape) -> bool:
    bsdf = shape.bsdf()
    if bsdf is None:
        return False
    flags = int(bsdf.flags())
    return not flags & int(mi.BSDFFlags.BackSide) and not flags & int(mi.BSDFFlags.Transmission)


def _drawn(scene, shape, known: dict | None) -> list:
    """The shapes that make ``shape``'s surface: the shape itself, or the shapes of the group an ``instance``
    draws (its own BSDF is a stand-in Mitsuba gives it)."""
    if shape.class_name() != "Instance":
        return [shape]
    from mincam_sim.render.kernels.change_geometry import drawn_parts

    return drawn_parts(scene, shape, known)


def warn_if_inside(scene, mincam: Mincam, skip: set[str]) -> None:
    """One :class:`WorldWarning` naming the mixels that sit inside a shape (:func:`inside_shapes`), and one naming
    those whose housing a shape crosses (:func:`housing_crossings`)."""
    inside = inside_shapes(scene, mincam, skip)
    if inside:
        where = ", ".join(f"{name} inside {shape!r}" for name, shape in sorted(inside.items()))
        warnings.warn(f"the mincam is inside a shape ({where}): its mixels see the back of one-sided faces, which "
                      "are black; move the mincam out of the shape (or give the shape a two-sided material)",
                      WorldWarning, stacklevel=4)
    crossed = housing_crossings(scene, mincam, skip)
    if crossed:
        where = ", ".join(f"{name} by {shape!r}" for name, shape in sorted(crossed.items()))
        warnings.warn(f"a shape crosses a mixel's housing, between its detector and its mask ({where}): a mixel "
                      "would be blind to what it hides there, and the renderer, which starts the rays at the mask, "
                      "reads as if it were not there; move the mincam or the shape apart", WorldWarning,
                      stacklevel=4)


class EngulfedWarning(WorldWarning):
    """A shape that a run moves closes round a mixel in one of the run's frames (or crosses its housing): the
    mixel sees only the back of the shape's faces there (black for a one-sided material), and its reading drops
    to about 0."""


class EngulfWatch:
    """Watches the shapes a run moves, frame by frame, for one that closes round a mixel or a part of one (the
    centre or a corner of its mask: :func:`mask_points_m`), as the check :func:`warn_if_inside` makes of the
    world as built, or crosses its housing between the detector and the mask (:func:`housing_crossings`), and
    says the first one found with one :class:`EngulfedWarning`; later frames are not checked. A moved
    ``instance`` is checked as the shapes of its group it draws.

    Per frame it costs a bounding box per moved shape against the boxes of the mixels' housings (numpy; on 2 CPU
    cores 15-17 us a frame for 4 or 64 mixels, as the mask centres alone cost); only the parts of the mixels whose
    housing a box reaches are traced (:data:`WATCH_DIRECTIONS` directions from each mask point the box holds, 16
    rays through each housing) in the scene the run traces: with a tray moving round the rig, whose box holds
    every mixel, 1.0-1.3 ms a frame for 4 mixels and 1.7-3.3 ms for 64 (the mask centres alone 0.6-0.8 and
    1.3-2.6 ms; fastest and median of 7 rounds on a shared machine).

    Parameters
    ----------
    mincam : Mincam
        The mincam in the coordinates of the scenes checked (the simulation's ``scene_mincam``).
    known : dict, optional
        The parts of the groups that instances draw, by instance name, kept for the scene checked
        (:func:`~mincam_sim.render.kernels.change_geometry.drawn_parts`; the simulation's ``known_parts``).
    """

    def __init__(self, mincam: Mincam, known: dict | None = None) -> None:
        self.mixels = list(mincam)
        n = len(self.mixels)
        self.points_m = np.concatenate([mask_points_m(m) for m in self.mixels])  # (5 n, 3) [m]
        bodies = np.array([m.body_corners_m() for m in self.mixels])  # (n, 8, 3) [m]
        self.housing_lo_m, self.housing_hi_m = bodies.min(axis=1), bodies.max(axis=1)
        self.point_keys = [(k, part) for k in range(n) for part in range(HOUSING)]
        self.known = {} if known is None else known
        self.found: tuple[str, str, list[str]] | None = None  # (where, shape, mixels) of the first finding
        self._rays: tuple[np.ndarray, ...] | None = None  # every part's rays, built once when first needed

    def check(self, scene, shapes: Iterable, where: str) -> None:
        """Warn (once per watch) when one of ``shapes`` (the shapes the current frame moved, as ``scene`` has
        them) closes round a mixel or a part of one, or crosses its housing; ``where`` names the frame
        (``"frame 12"``, ``"the background"``)."""
        if self.found is not None:
            return
        for shape in shapes:
            box = shape.bbox()
            lo, hi = np.array(box.min, dtype=float).ravel(), np.array(box.max, dtype=float).ravel()
            # a housing's box holds its mask points: a box that reaches no housing holds none of them
            reached = np.all((self.housing_hi_m >= lo) & (self.housing_lo_m <= hi), axis=1)
            if not reached.any() or shape.sensor() is not None:
                continue
            held = np.all((self.points_m >= lo) & (self.points_m <= hi), axis=1)
            if self._rays is None:
                every = self.point_keys + [(k, HOUSING) for k in range(len(self.mixels))]
                self._rays = _probe_rays(self.mixels, every, WATCH_DIRECTIONS)
            o, d, maxt, owner = self._rays
            wanted = np.concatenate([held.reshape(-1, HOUSING), reached[:, None]], axis=1)  # (n, 6)
            rows = wanted[owner[:, 0], owner[:, 1]]  # the rays of the parts the box reaches
            found = _findings(scene, self.mixels, [], [shape], self.known,
                              rays=(o[rows], d[rows], maxt[rows], owner[rows]))
            if found:
                self._say(shape.id(), sorted(found), where)
                return

    def _say(self, shape: str, found: list[tuple[int, int]], where: str) -> None:
        parts: dict[int, list[int]] = {}
        for k, part in found:
            parts.setdefault(k, []).append(part)
        named, whole, dark, crossed = [], True, False, False
        for k, held in sorted(parts.items()):
            corners = sum(1 <= p <= 4 for p in held)
            what = (["its mask centre"] * (0 in held) + [f"{corners} of its 4 mask corners"] * bool(corners)
                    + ["its housing, between detector and mask"] * (HOUSING in held))
            if any(p != HOUSING for p in held):
                whole &= 0 in held  # of the mixels it darkens, every one round its mask centre
                dark = True
            crossed |= HOUSING in held
            named.append(self.mixels[k].name + ("" if held == list(range(HOUSING)) else f" ({', '.join(what)})"))
        self.found = (where, shape, [self.mixels[k].name for k in sorted(parts)])
        effects = []
        if dark and whole:
            effects.append("they see only the back of its one-sided faces, which are black, so they read about 0 "
                           "there (a change measured there is off by the whole P), though the scene did not go dark")
        elif dark:
            effects.append("part of their view meets only the back of its one-sided faces, which are black, so they "
                           "read too little there")
        if crossed:
            effects.append("a mixel would be blind to what a shape hides inside its housing, and the renderer, which "
                           "starts the rays at the mask, reads as if it were not there")
        verb = "closes round" if dark else "cuts through"
        fix = "move the shape's path clear of the mincam" + (", or give the shape a two-sided material" if dark else "")
        warnings.warn(
            f"the moving shape {shape!r} {verb} mixel(s) {', '.join(named)} in {where} (the first place of this run "
            f"where a moved shape does; later frames are not checked): {'; '.join(effects)}; {fix}",
            EngulfedWarning, stacklevel=3)


def check_unit(unit_m) -> float:
    """``unit_m`` as a positive finite float, or one :class:`InputError`."""
    if isinstance(unit_m, bool) or not isinstance(unit_m, (int, float)) or not np.isfinite(unit_m) or unit_m <= 0:
        raise InputError(f"unit_m must be the length of the scene's unit in metres (0.01 for a scene modelled in "
                         f"cm), a positive number; got {unit_m!r}")
    return float(unit_m)


def light_pixels(scene, camera, per_side: int = 4) -> np.ndarray:
    """(rows, cols) booleans: the pixels of ``camera`` (a sensor of ``scene``) that see a light directly (an
    emitting shape, or nothing at all under an environment light such as a sky) at any of ``per_side`` x
    ``per_side`` points across them, and their 8 neighbours (a pixel's filter reaches past its edge). A lamp in
    view is far brighter than anything it lights, so a threshold relative to the brightest pixel leaves these
    out."""
    import drjit as dr

    mi = backend.mitsuba()
    cols, rows = (int(v) for v in camera.film().crop_size())
    sub = (np.arange(per_side) + 0.5) / per_side
    r, c, dr_, dc = np.meshgrid(np.arange(rows), np.arange(cols), sub, sub, indexing="ij")
    position = mi.Point2f(mi.Float(((c + dc).ravel() / cols).astype(np.float32)),
                          mi.Float(((r + dr_).ravel() / rows).astype(np.float32)))
    ray, _ = camera.sample_ray(0.0, 0.5, position, mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(ray)
    hit_light = si.is_valid() & si.shape.is_emitter()
    if scene.environment() is not None:
        hit_light |= ~si.is_valid()
    seen = np.array(dr.select(hit_light, 1, 0), dtype=bool).reshape(rows, cols, -1).any(axis=2)
    grown = np.pad(seen, 1)
    return np.any([grown[1 + i:1 + i + rows, 1 + j:1 + j + cols] for i in (-1, 0, 1) for j in (-1, 0, 1)], axis=0)
