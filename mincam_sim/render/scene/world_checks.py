"""Checks of a built world that would otherwise give silent or misleading numbers: no light at all, a mincam
inside a shape, a scene whose size is implausible against the rig (modelled in other units than metres), and
the file units scaled to metres (``unit_m``)."""

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


def check_far_from_origin(scene, mincam_centre_m, skip: set[str], unit_m: float) -> None:
    """Refuse (warn for) a world whose mincam sits so far from the coordinates' origin that the 32-bit floats
    Mitsuba loads the scene in place the shapes around it on a grid coarser than :data:`FLOAT32_GRID_REFUSE_M`
    (:data:`FLOAT32_GRID_WARN_M`). A world with no shape of its own (a sky) has nothing to misplace."""
    if not any(s.id() not in skip and s.sensor() is None for s in scene.shapes()):
        return
    distance = float(np.max(np.abs(np.asarray(mincam_centre_m, dtype=float))))
    grid = float32_grid_m(distance, unit_m)
    if grid <= FLOAT32_GRID_WARN_M:
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
    warnings.warn(f"{what}: readings may be off by a little; {fix}", WorldWarning, stacklevel=4)


def _within_m(grid_m: float, unit_m: float) -> float:
    """[m] the largest distance from the origin whose float32 grid is at most ``grid_m``."""
    return float(2.0 ** (np.floor(np.log2(grid_m / unit_m / np.spacing(np.float32(1.0)))) + 1)) * unit_m


def rig_size_m(mincam: Mincam) -> float:
    """The rig's size [m]: the spread of its mixels' positions, its largest mask or detector, or
    :data:`MIN_RIG_M`, whichever is largest."""
    positions = np.array([m.pose.position_m for m in mincam])
    spread = float(np.linalg.norm(np.ptp(positions, axis=0)))
    parts = [max(m.mask.width_m, m.mask.height_m, m.detector_size_m) for m in mincam]
    return max(spread, max(parts), MIN_RIG_M)


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
    elif extent < SCENE_TOO_SMALL * rig:
        warnings.warn(f"the scene spans {extent:.4g} m, less than the mincam ({rig:.3g} m): read in {units}; check "
                      "unit_m (files are in metres unless unit_m says otherwise)", WorldWarning, stacklevel=4)


def fibonacci_directions(n: int) -> np.ndarray:
    """``n`` unit vectors spread evenly over the sphere (n, 3)."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - z * z)
    phi = np.pi * (1.0 + 5.0**0.5) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def inside_shapes(scene, mincam: Mincam, skip: set[str], n_directions: int = 256) -> dict[str, str]:
    """Mixels (name -> shape id) that look out at the back of one shape's one-sided faces in at least
    :data:`INSIDE_FRACTION` of the directions in front of their mask: a mixel inside a closed shape (a wall, a
    box) sees only the inside of its faces, which a one-sided material leaves black."""
    mi = backend.mitsuba()
    candidates = [s for s in scene.shapes() if s.id() not in skip and s.sensor() is None and _one_sided(mi, s)]
    if not candidates:
        return {}
    mixels = list(mincam)
    return _looking_at_backs(scene, mixels, *front_rays(mixels, n_directions), candidates)


def front_rays(mixels: Sequence[Mixel], n_directions: int = 256) -> tuple[object, np.ndarray]:
    """Rays (one ``mi.Ray3f``) from each mixel's mask centre into the directions of ``n_directions`` spread over
    the sphere that lie in front of its mask, and the index of the mixel of each ray."""
    mi = backend.mitsuba()
    dirs = fibonacci_directions(n_directions)
    origins, directions, owners = [], [], []
    for k, mixel in enumerate(mixels):
        forward = np.asarray(mixel.pose.axes()[2])
        front = dirs[dirs @ forward > 0.05]
        centre = mixel.pose.to_world(np.array([0.0, 0.0, mixel.d_f_m]))
        origins.append(np.repeat(centre[None] + 1e-6 * forward, len(front), axis=0))
        directions.append(front)
        owners.append(np.full(len(front), k))
    o, d, owner = np.concatenate(origins), np.concatenate(directions), np.concatenate(owners)
    ray = mi.Ray3f(mi.Point3f(*[mi.Float(o[:, j]) for j in range(3)]),
                   mi.Vector3f(*[mi.Float(d[:, j]) for j in range(3)]))
    return ray, owner


def _looking_at_backs(scene, mixels: Sequence[Mixel], ray, owner: np.ndarray, candidates) -> dict[str, str]:
    """:func:`inside_shapes` with its rays (:func:`front_rays` of ``mixels``) and its candidate shapes given;
    ``scene`` is what the rays are traced in (a Mitsuba scene, or a split scene)."""
    import drjit as dr

    mi = backend.mitsuba()
    si = scene.ray_intersect(ray)
    back = si.is_valid() & (dr.dot(si.n, ray.d) > 0)
    found: dict[str, str] = {}
    for shape in candidates:
        hits = np.array(back & (si.shape == mi.ShapePtr(shape)), dtype=bool)
        for k, mixel in enumerate(mixels):
            mine = owner == k
            if mixel.name not in found and hits[mine].mean() >= INSIDE_FRACTION:
                found[mixel.name] = shape.id()
    return found


def _one_sided(mi, shape) -> bool:
    bsdf = shape.bsdf()
    if bsdf is None:
        return False
    flags = int(bsdf.flags())
    return not flags & int(mi.BSDFFlags.BackSide) and not flags & int(mi.BSDFFlags.Transmission)


def warn_if_inside(scene, mincam: Mincam, skip: set[str]) -> None:
    """One :class:`WorldWarning` naming the mixels that sit inside a shape (:func:`inside_shapes`)."""
    inside = inside_shapes(scene, mincam, skip)
    if inside:
        where = ", ".join(f"{name} inside {shape!r}" for name, shape in sorted(inside.items()))
        warnings.warn(f"the mincam is inside a shape ({where}): its mixels see the back of one-sided faces, which "
                      "are black; move the mincam out of the shape (or give the shape a two-sided material)",
                      WorldWarning, stacklevel=4)


class EngulfedWarning(WorldWarning):
    """A shape that a run moves closes round a mixel in one of the run's frames: the mixel sees only the back of
    the shape's faces there (black for a one-sided material), and its reading drops to about 0."""


class EngulfWatch:
    """Watches the shapes a run moves, frame by frame, for one that closes round a mixel (the check
    :func:`warn_if_inside` makes of the world as built), and says the first one found with one
    :class:`EngulfedWarning`; later frames are not checked.

    Per frame it costs a bounding box per moved shape against the mixels' mask centres (numpy); only a box that
    holds a mask centre runs the exact test of :func:`inside_shapes` (rays from the mask centres, built once; a
    launch of about 1.5 ms on 2 CPU cores) in the scene the run traces.

    Parameters
    ----------
    mincam : Mincam
        The mincam in the coordinates of the scenes checked (the simulation's ``scene_mincam``).
    """

    def __init__(self, mincam: Mincam) -> None:
        self.mixels = list(mincam)
        self.mask_centres_m = np.array([m.pose.to_world(np.array([0.0, 0.0, m.d_f_m])) for m in self.mixels])
        self.found: tuple[str, str, list[str]] | None = None  # (where, shape, mixels) of the first finding
        self._rays: tuple[object, np.ndarray] | None = None  # the exact test's rays, built once when first needed

    def check(self, scene, shapes: Iterable, where: str) -> None:
        """Warn (once per watch) when one of ``shapes`` (the shapes the current frame moved, as ``scene`` has
        them) closes round a mixel; ``where`` names the frame (``"frame 12"``, ``"the background"``)."""
        if self.found is not None:
            return
        for shape in shapes:
            box = shape.bbox()
            lo, hi = np.array(box.min, dtype=float).ravel(), np.array(box.max, dtype=float).ravel()
            near = np.flatnonzero(np.all((self.mask_centres_m >= lo) & (self.mask_centres_m <= hi), axis=1))
            if not near.size:
                continue
            if shape.sensor() is not None or not _one_sided(backend.mitsuba(), shape):
                continue
            if self._rays is None:
                self._rays = front_rays(self.mixels)
            inside = _looking_at_backs(scene, self.mixels, *self._rays, [shape])
            names = [self.mixels[k].name for k in near if self.mixels[k].name in inside]
            if names:
                self.found = (where, shape.id(), names)
                warnings.warn(
                    f"the moving shape {shape.id()!r} closes round mixel(s) {', '.join(names)} in {where} (the first "
                    f"place of this run where a moved shape does; later frames are not checked): they see only the "
                    "back of its one-sided faces, which are black, so they read about 0 there (a change measured "
                    "there is off by the whole P), though the scene did not go dark; move the shape's path clear "
                    "of the mincam, or give the shape a two-sided material", EngulfedWarning, stacklevel=2)
                return


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
