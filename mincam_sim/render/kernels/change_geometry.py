"""The geometry oracle of the change solvers: where a frame's change can reach in a world scene.

The scene's delta surfaces (mirrors, glass) and their images, the lights and their images in the faces of a
moving glass block (:func:`delta_light_spheres`: where bounces are guided through it), the corner points of the
moving shapes with their shadow volumes from every light (:func:`change_points_of`), where lights shine from
(:func:`light_bounds`), which shapes an update moves or changes, and the boxes a path must cross to meet a shape.
Read by ``mincam_sim.render.solvers.change`` and by :class:`~mincam_sim.render.simulation.Simulation` (its change
regions and guides).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from mincam_sim.render import backend
from mincam_sim.render.kernels.change_region import box_corners, change_points
from mincam_sim.render.kernels.guided_path import MAX_GUIDES, guide_sphere, guide_spheres
from mincam_sim.render.scene.mincam_scene import CAMERA_KEY, SENSOR_KEY

Updates = Mapping[str, np.ndarray]


class DeltaSurfaces:
    """The scene's delta surfaces (mirrors, glass, null BSDFs): planar ones by their plane, which mirrors a
    change into an image the mixels can see; curved ones by their bounding box (rays that reach them may go
    anywhere after)."""

    def __init__(self, planes: dict[str | tuple[str, int], tuple[np.ndarray, float]],
                 boxes: dict[str | tuple[str, int], np.ndarray]) -> None:
        self.planes, self.boxes = planes, boxes

    def __contains__(self, name: str) -> bool:
        return any(_owner(key) == name for key in (*self.planes, *self.boxes))

    def images(self, points: np.ndarray, exclude: str = "") -> list[np.ndarray]:
        """Point sets to add to a change's region: its mirror images in each planar delta surface, and the
        boxes of the curved ones (``exclude``: the moving shape itself, an instance's surfaces all)."""
        return self.reflect(points, exclude) + [box for name, box in self.boxes.items() if _owner(name) != exclude]

    def reflect(self, points: np.ndarray, exclude: str = "") -> list[np.ndarray]:
        """``points`` (m, 3) mirrored in each planar delta surface's plane but ``exclude``'s."""
        return [points - 2.0 * (points @ n - c)[:, None] * n for name, (n, c) in self.planes.items()
                if _owner(name) != exclude]

    def with_images(self, boxes: list, directions: list) -> tuple[list, list]:
        """Light boxes and directions plus their images in each planar delta surface (first-order reflections):
        the shadow a mover casts in light that a mirror throws."""
        images = [(im.min(axis=0), im.max(axis=0)) for lo, hi in boxes for im in self.reflect(box_corners(lo, hi))]
        turned = [d - 2.0 * (np.asarray(d) @ n) * n for d in directions for n, _ in self.planes.values()]
        return boxes + images, list(directions) + turned

    def light_image_spheres(self, scene) -> list[tuple[np.ndarray, float]]:
        """Spheres around the images of the scene's emitting shapes and point lights in each planar delta
        surface: the direction in which a bounce meets a light through a mirror."""
        if not self.planes:
            return []
        lights, _ = light_bounds(scene)
        boxes = [] if lights is None else list(lights[0])
        boxes += [(np.array(s.bbox().min, dtype=float), np.array(s.bbox().max, dtype=float))
                  for s in scene.shapes() if s.is_emitter()]
        return [guide_sphere(im) for lo, hi in boxes for im in self.reflect(box_corners(lo, hi))]


def _owner(key: str | tuple[str, int]) -> str:
    """The shape a delta surface's key belongs to (``name``, or ``(name, k)``: the k-th surface an instance draws)."""
    return key[0] if isinstance(key, tuple) else key


MAX_FACE_PLANES = 16  # a delta mesh with more distinct face planes (curved glass) is guided toward the lights only


def face_planes(shape, tolerance: float = 1e-5) -> list[tuple[np.ndarray, float]]:
    """Distinct planes ``(unit normal, offset [m])`` of a mesh's triangles (a plane and its flip count once);
    empty for a shape that is not a mesh."""
    if not hasattr(shape, "faces_buffer") or not hasattr(shape, "vertex_positions_buffer"):
        return []
    v = np.array(shape.vertex_positions_buffer(), dtype=float).reshape(-1, 3)
    f = np.array(shape.faces_buffer(), dtype=np.int64).reshape(-1, 3)
    if not len(f):
        return []
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    length = np.linalg.norm(n, axis=1)
    keep = length > 0
    n = n[keep] / length[keep, None]
    n *= np.where(n[np.arange(len(n)), np.abs(n).argmax(axis=1)] < 0, -1.0, 1.0)[:, None]  # one sign per plane
    c = np.einsum("ij,ij->i", n, v[f[keep, 0]])
    size = 1.0 + float(np.abs(v).max())
    planes: list[tuple[np.ndarray, float]] = []
    for normal, offset in zip(n, c, strict=True):
        if not any(np.all(np.abs(normal - m) < tolerance) and abs(offset - o) < tolerance * size for m, o in planes):
            planes.append((normal, float(offset)))
    return planes


def light_boxes(scene) -> list[tuple[np.ndarray, np.ndarray]]:
    """Boxes [m] where the scene's point-like lights and emitting shapes are (directional and environment
    lights have none)."""
    lights, _ = light_bounds(scene)
    boxes = [] if lights is None else list(lights[0])
    return boxes + [(np.array(s.bbox().min, dtype=float), np.array(s.bbox().max, dtype=float))
                    for s in scene.shapes() if s.is_emitter()]


def delta_light_point_sets(scene, moving, known: dict | None = None) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Where a bounce meets a light through a moving delta shape (glass, a mirror): the lights' corners (a slab
    with parallel faces shifts a ray but keeps its direction, so light refracted through it comes from the lights'
    directions), and their images in each face plane of the moving delta meshes, an instance's included
    (:func:`delta_face_planes`: light the faces reflect, Fresnel's share for glass), one point set per light and
    per light and plane; ([], []) when no moving shape has a delta BSDF. ``known``: as :func:`drawn_parts`."""
    delta = [planes for s in scene.shapes() if s.id() in moving and not s.is_emitter()
             for planes in delta_face_planes(scene, s, known)]
    boxes = light_boxes(scene) if delta else []
    if not boxes:
        return [], []
    lights = [box_corners(lo, hi) for lo, hi in boxes]
    images = []
    for planes in delta:
        if len(planes) > MAX_FACE_PLANES:
            continue
        for n, c in planes:
            images += [p - 2.0 * (p @ n - c)[:, None] * n for p in lights]
    return lights, images


def delta_light_spheres(scene, moving, taken: int = 0, known: dict | None = None) -> list[tuple[np.ndarray, float]]:
    """Guide spheres around :func:`delta_light_point_sets`: one around the lights, and around their images
    (compact groups merged) as many as :data:`~.guided_path.MAX_GUIDES` leaves beside ``taken`` (the spheres
    the movers already use) and the lights' (at least one)."""
    lights, images = delta_light_point_sets(scene, moving, known)
    if not lights:
        return []
    spheres = [guide_sphere(np.concatenate(lights))]
    if images:
        spheres += guide_spheres(images, max_spheres=max(1, MAX_GUIDES - taken - 1))
    return spheres


def delta_surfaces(scene, known: dict | None = None) -> DeltaSurfaces:
    """The scene's delta surfaces, planar or not, from 64 points sampled on each; those an instance draws too
    (:func:`drawn_parts`, under the instance's ``to_world``; keyed by the instance's name, ``(name, k)`` for its
    k-th of several), looked for only where a shape group holds one. ``known``: as :func:`drawn_parts`."""
    mi = backend.mitsuba()
    grouped = None  # does a shape group hold a delta surface? (read once, when an instance is met)
    planes, boxes = {}, {}
    for shape in scene.shapes():
        if shape.is_emitter() or shape.is_sensor():
            continue
        matrix = None
        if shape.class_name() == "Instance":
            if grouped is None:
                hierarchy = mi.traverse(scene).hierarchy
                grouped = any(isinstance(obj, mi.Shape) and isinstance(parent, mi.Shape)
                              and parent.class_name() == "ShapeGroupPlugin" and delta_bsdf(obj)
                              for obj, (parent, _) in hierarchy.items())
            if not grouped:
                continue
            parts = [part for part in drawn_parts(scene, shape, known) if delta_bsdf(part)]
            matrix = np.array(mi.traverse(shape)["to_world"].matrix, dtype=float).reshape(4, 4)
        else:
            parts = [shape] if delta_bsdf(shape) else []
        for k, part in enumerate(parts):
            key = shape.id() if len(parts) == 1 else (shape.id(), k)
            bb = part.bbox()
            corners = box_corners(np.array(bb.min, dtype=float).ravel(), np.array(bb.max, dtype=float).ravel())
            g = np.linspace(0.05, 0.95, 8)
            uu, vv = np.meshgrid(g, g)
            ps = part.sample_position(0.0, mi.Point2f(uu.ravel(), vv.ravel()))
            p = np.array(ps.p, dtype=float).reshape(3, -1).T
            n = np.array(ps.n, dtype=float).reshape(3, -1).T
            if matrix is not None:  # the group's coordinates -> the scene's
                p, corners = p @ matrix[:3, :3].T + matrix[:3, 3], corners @ matrix[:3, :3].T + matrix[:3, 3]
                n = n @ np.linalg.inv(matrix[:3, :3])
                n /= np.linalg.norm(n, axis=1)[:, None]
            lo, hi = corners.min(axis=0), corners.max(axis=0)
            normal = n[0] / np.linalg.norm(n[0])
            size = max(float(np.linalg.norm(hi - lo)), 1e-9)
            if np.all(np.abs(n @ normal) > 1 - 1e-6) and np.all(np.abs((p - p[0]) @ normal) < 1e-6 * size):
                planes[key] = (normal, float(p[0] @ normal))
            else:
                boxes[key] = box_corners(lo, hi)
    return DeltaSurfaces(planes, boxes)


def watch_box(shape) -> tuple[np.ndarray, np.ndarray]:
    """The shape's bounding box (scene coordinates [m]) grown by a margin past Mitsuba's ray offsets: a path that
    stays out of it cannot meet the shape."""
    box = shape.bbox()
    lo, hi = np.array(box.min, dtype=float).ravel(), np.array(box.max, dtype=float).ravel()
    margin = 1e-3 * (1.0 + float(np.max(np.abs(np.concatenate([lo, hi])))))
    return lo - margin, hi + margin


def static_box(scene, moving) -> tuple[np.ndarray, np.ndarray] | None:
    """The bounding box (scene coordinates [m]) of every shape not named in ``moving``, or None if there is none."""
    los, his = [], []
    for shape in scene.shapes():
        if shape.id() not in moving:
            box = shape.bbox()
            los.append(np.array(box.min, dtype=float).ravel())
            his.append(np.array(box.max, dtype=float).ravel())
    if not los:
        return None
    return np.min(los, axis=0), np.max(his, axis=0)


def merge_parked(boxes: list, keep_clear: tuple[np.ndarray, np.ndarray] | None) -> list:
    """``boxes`` (watch boxes, (lo, hi) [m]) with those that lie wholly outside ``keep_clear`` (the static
    shapes' box) replaced by one box holding them all, where that box stays outside it too (else unchanged).

    Parked background places (a mover put far away) are watched to pair a frame's lanes with its background's:
    one box instead of many costs each path segment fewer box tests. A lane whose path crosses the merged box
    but none of the boxes it holds is traced again in the paired pass rather than copied, which gives the value
    a full pass gives (see :func:`.stratified.stratified_lanes`): the numbers do not change, only the work."""
    if keep_clear is None or len(boxes) < 2:
        return list(boxes)
    lo_c, hi_c = keep_clear

    def outside(lo, hi):
        return bool(np.any(hi < lo_c) or np.any(lo > hi_c))

    parked = [b for b in boxes if outside(*b)]
    if len(parked) < 2:
        return list(boxes)
    merged = (np.min([b[0] for b in parked], axis=0), np.max([b[1] for b in parked], axis=0))
    if not outside(*merged):
        return list(boxes)
    return [b for b in boxes if not outside(*b)] + [merged]


def redirects_light(scene, shape, known: dict | None = None) -> bool:
    """True if ``shape`` has a specular (delta) BSDF, a mirror or glass (for an ``instance``: one of the shapes it
    draws, :func:`drawn_parts`): moved, it reflects or refracts the lights' light onto places no box or shadow
    volume of it bounds (a glass block throws a caustic beside its shadow)."""
    return any(specular(part) for part in drawn_parts(scene, shape, known))


def delta_bsdf(shape) -> bool:
    """True if the shape's own BSDF has a delta component (a mirror, glass, a null BSDF)."""
    mi = backend.mitsuba()
    bsdf = shape.bsdf()
    return bsdf is not None and bool(int(bsdf.flags()) & int(mi.BSDFFlags.Delta))


def specular(shape) -> bool:
    """True if the shape's own BSDF has a delta reflection or a delta transmission (a mirror, glass)."""
    mi = backend.mitsuba()
    bsdf = shape.bsdf()
    return bsdf is not None and bool(int(bsdf.flags()) & (int(mi.BSDFFlags.DeltaReflection)
                                                          | int(mi.BSDFFlags.DeltaTransmission)))


INSTANCE_PROBE_RAYS = 1024


def drawn_parts(scene, shape, known: dict | None = None) -> list:
    """The shapes that make ``shape``'s surface: the shape itself, or for an ``instance`` the shapes of the group it
    draws. An instance holds no link to its group that Python can read (and Mitsuba gives it a diffuse BSDF of its
    own): its group is the one whose shapes :data:`INSTANCE_PROBE_RAYS` rays, cast through the scene at its box
    from a sphere around it, meet through it ([] if none is met).

    ``known`` (a dict the caller keeps for one scene) holds the parts found, by the instance's name: the group an
    instance draws never changes, so it is probed once; a probe that met nothing (an instance hidden where it
    stands) is not kept, and the next call probes where it stands then."""
    if shape.class_name() != "Instance":
        return [shape]
    if known is not None and shape.id() in known:
        return known[shape.id()]
    mi = backend.mitsuba()
    import drjit as dr

    box = shape.bbox()
    lo, hi = np.array(box.min, dtype=float).ravel(), np.array(box.max, dtype=float).ravel()
    rng = np.random.default_rng(0)
    towards = rng.uniform(lo, hi, (INSTANCE_PROBE_RAYS, 3))
    away = rng.standard_normal((INSTANCE_PROBE_RAYS, 3))
    away /= np.linalg.norm(away, axis=1)[:, None]
    origins = 0.5 * (lo + hi) + away * (0.51 * np.linalg.norm(hi - lo) + 1e-4)
    ray = mi.Ray3f(mi.Point3f(*(mi.Float(v) for v in origins.T)),
                   dr.normalize(mi.Vector3f(*(mi.Float(v) for v in (towards - origins).T))))
    si = scene.ray_intersect(ray)
    met = si.is_valid() & (si.instance == mi.ShapePtr(shape))
    hierarchy = mi.traverse(scene).hierarchy
    groups = [obj for obj, (parent, _) in hierarchy.items()
              if parent is scene and isinstance(obj, mi.Shape) and obj.class_name() == "ShapeGroupPlugin"]
    for group in groups:
        parts = [obj for obj, (parent, _) in hierarchy.items() if parent is group and isinstance(obj, mi.Shape)]
        if any(dr.any(met & (si.shape == mi.ShapePtr(part))) for part in parts):
            if known is not None:
                known[shape.id()] = parts
            return parts
    return []


def delta_face_planes(scene, shape, known: dict | None = None) -> list[list[tuple[np.ndarray, float]]]:
    """For each shape with a delta BSDF (mirror, glass, null) that makes ``shape``'s surface (:func:`drawn_parts`),
    its distinct face planes in scene coordinates (:func:`face_planes`; an instance's group's planes under the
    instance's ``to_world``; [] for a shape that is not a mesh)."""
    mi = backend.mitsuba()
    parts = [part for part in drawn_parts(scene, shape, known) if delta_bsdf(part)]
    if shape.class_name() != "Instance":
        return [face_planes(part) for part in parts]
    matrix = np.array(mi.traverse(shape)["to_world"].matrix, dtype=float).reshape(4, 4)
    turn = np.linalg.inv(matrix[:3, :3]).T  # normals go with the inverse transpose
    out = []
    for part in parts:
        planes = []
        for normal, offset in face_planes(part):
            n = turn @ normal
            n /= np.linalg.norm(n)
            n *= -1.0 if n[np.abs(n).argmax()] < 0 else 1.0  # one sign per plane, as face_planes
            planes.append((n, float(n @ (matrix[:3, :3] @ (normal * offset) + matrix[:3, 3]))))
        out.append(planes)
    return out


def emitters_among(scene, names) -> bool:
    """True if one of the named shapes emits light (its sampling tables are rebuilt when it moves, at
    addresses a frozen launch cannot see: such runs are traced unfrozen)."""
    return any(s.id() in names and s.emitter() is not None for s in scene.shapes())


def moving_shapes(updates: Sequence[Updates]) -> set[str]:
    """Names of the shapes whose parameters the updates set (the part before the first dot of each key)."""
    return {key.split(".", 1)[0] for u in updates for key in u} - {SENSOR_KEY, CAMERA_KEY}


def changed_shapes(update: Updates, background: Updates) -> set[str]:
    """Names of the shapes that ``update``, applied on top of ``background``, sets to other values."""
    names = set()
    for key, value in update.items():
        same = False
        if key in background:
            try:
                same = np.array_equal(np.asarray(value), np.asarray(background[key]))
            except (TypeError, ValueError):
                same = False
        if not same:
            names.add(key.split(".", 1)[0])
    return names - {SENSOR_KEY, CAMERA_KEY}


def change_points_of(scene, moving, mirrors: DeltaSurfaces | None = None) -> tuple[np.ndarray | None, str]:
    """Corner points whose hull holds the moving shapes and their shadow volumes [m] (from the lights and their
    images in planar mirrors), or None and why the change is unbounded (an environment light, a moving emitter,
    an emitter of a kind not bounded here, or a moved parameter that belongs to no shape)."""
    return change_points_each(scene, [moving], mirrors)[0]


def change_points_each(scene, groups, mirrors: DeltaSurfaces | None = None) -> list[tuple[np.ndarray | None, str]]:
    """:func:`change_points_of` of each group of moving shapes names in ``groups``, the scene's lights, their
    mirror images and its bounding box read once for all (the same numbers as a call per group)."""
    shapes = {s.id(): s for s in scene.shapes()}

    def box(shape):
        bb = shape.bbox()
        return np.array(bb.min, dtype=float), np.array(bb.max, dtype=float)

    shared = None
    out = []
    for moving in groups:
        why = ""
        for name in moving:
            if name not in shapes:
                why = (f"'{name}' is not a shape (a moving light or another parameter): its change reaches "
                       "anywhere")
                break
            if shapes[name].is_emitter():
                why = f"'{name}' is an emitting shape: the light it moves reaches anywhere"
                break
        if why:
            out.append((None, why))
            continue
        if shared is None:
            lights, why = light_bounds(scene)
            if lights is None:
                shared = (None, why)
            else:
                boxes, directions = lights
                boxes = boxes + [box(s) for s in scene.shapes() if s.is_emitter()]
                if mirrors is not None:
                    boxes, directions = mirrors.with_images(boxes, directions)
                shared = ((boxes, directions, box(scene)), "")
        if shared[0] is None:
            out.append(shared)
            continue
        boxes, directions, scene_box = shared[0]
        objects = [box(shapes[name]) for name in sorted(moving)]
        out.append((change_points(objects, boxes, scene_box, directions), ""))
    return out


def light_bounds(scene) -> tuple[tuple[list, list] | None, str]:
    """Where the scene's non-shape emitters shine from: point-like ones (point, spot) as zero-size boxes [m],
    directional ones by the direction their rays travel; None (and why) for an environment light or any other
    kind."""
    mi = backend.mitsuba()
    boxes, directions = [], []
    for emitter in scene.emitters():
        flags = int(emitter.flags())
        if flags & int(mi.EmitterFlags.Surface):
            continue  # an emitting shape: bounded by its shape's box
        if emitter.is_environment():
            return None, f"the environment light '{emitter.id()}' casts shadows anywhere"
        params = mi.traverse(emitter)
        if flags & int(mi.EmitterFlags.DeltaDirection) and "to_world" in params:
            directions.append(np.array(params["to_world"].matrix, dtype=float).reshape(4, 4)[:3, 2])
        elif flags & int(mi.EmitterFlags.DeltaPosition) and ("position" in params or "to_world" in params):
            where = (np.array(params["position"], dtype=float).ravel() if "position" in params
                     else np.array(params["to_world"].matrix, dtype=float).reshape(4, 4)[:3, 3])
            boxes.append((where, where))
        else:
            return None, f"the light '{emitter.id()}' is of a kind not bounded here (an area light without a shape?)"
    return (boxes, directions), ""
