"""The plane-replay solver: a textured plane that moves within its own plane, traced once and replayed for every
placement.

A road under a vehicle's mixel, a conveyor belt, a turntable: when all that changes between frames is where a
diffuse rectangle lies *in its own plane*, every ray of a seeded launch meets that plane at the same point
``p_k`` in every frame. If no other surface of the scene reflects light (every other shape is black: the mixels'
own bodies, occluders, area lights), the path tracer's value along ray ``k`` is::

    v_k = rho(uv_t(p_k)) g_k    if p_k lies on the rectangle in its placement t (albedo rho there)
    v_k = o_k                   if the ray passes where the rectangle is not

``g_k`` (the value per unit albedo: the mask weight times the sky light reaching ``p_k`` past the bodies) and
``o_k`` (the value of the ray going on) do not depend on the placement, because the integrator draws the same
random numbers along a lane whatever the albedo is. So two traces of the renderer's own launches, same seeds as
the aperture solver's, give every frame: one with the plane a white sheet over all placements (``g_k`` and
``p_k``), one with the plane gone (``o_k``). A frame is then one texture lookup per ray, with
Mitsuba's own lookup, so it equals the traced frame up to float32 rounding, not just in expectation.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from mincam_sim.budget import Budget
from mincam_sim.errors import InputError
from mincam_sim.measurements import Measurements
from mincam_sim.render import backend
from mincam_sim.render.kernels.monte_carlo import replicate_mean_stderr
from mincam_sim.render.kernels.tracing import lane_sums, sensor_launches
from mincam_sim.render.solvers.base import Plan, Row, Solver, check_update_frames

PLANE_TOLERANCE = 1e-6  # [rad], and [m] per metre from the origin: placements off the first one's plane by more
# are not in-plane motion (the scene holds its matrices in float32, ~1e-7 relative)
DEFAULT_REPLICATES = 8
_ABSENT_SCALE = 1e-6  # the plane "removed": its cover shrunk a million times (micrometres), met by no ray (checked)


@dataclass
class _Lanes:
    """One launch: the points where its rays meet the plane (relative to the cover's centre, scene frame), the
    lanes that meet it first, and their values per unit albedo and with the plane gone."""

    groups: slice
    samples: int
    offset: object  # mi.Vector3f, p_k - centre [m]
    meets: object  # mi.Bool
    per_albedo: object  # mi.Spectrum, g_k
    without: object  # mi.Spectrum, o_k


class SlidingPlane:
    """Measurements of a mincam over a diffuse textured rectangle placed anywhere in its own plane.

    Parameters
    ----------
    world : Simulation
        The world scene, as it stands (nothing else may change while the plane is replayed). It is left as found.
    name : str
        The rectangle's element name (a ``rectangle`` with a ``diffuse`` BSDF, its reflectance a bitmap).
    placements_m : sequence of (4, 4) arrays
        Every ``to_world`` matrix (world coordinates [m], as ``world.params[name + ".to_world"]``) the plane
        will be replayed at; all must lie in one plane and face one way (rigid motion within the plane: slides,
        turns). Later placements may not reach beyond the rectangle that covers these.
    spp : int
        Rays per mixel per frame, as the aperture solver.
    seed : int
        Seed, as the aperture solver: the same seed gives the numbers its
        trace would give.
    replicates : int
        Independent estimates per measurement.

    Notes
    -----
    Exact for any seed and budget only in the scenes this holds for (checked,
    :class:`~mincam_sim.errors.InputError` otherwise): every shape but the plane is black, and the plane only
    moves within its plane.
    The plane's texture may change between frames (it is looked up when a frame is replayed); anything else
    the renderer changes after the replay is built is refused (:meth:`estimates`). Frames that also move
    other shapes must be traced (the aperture solver). It holds about
    40 bytes per ray (point, two values, a flag): 2^19 rays for each of 4 mixels take ~80 MiB.
    """

    def __init__(self, world, name: str, placements_m: Sequence[np.ndarray], spp: int, seed: int,
                 replicates: int) -> None:
        backend.require_jit("Replaying a sliding plane")
        self.mi = backend.mitsuba()
        self.world, self.name = world, name
        self._shape = _check_scene(world, name)
        placements = _check_placements(placements_m, name)
        self._origin = np.asarray(world.scene_origin_m, dtype=np.float64)
        self._normal, self._centre, self._cover_m = _cover(placements, self._origin)
        self.replicates = int(replicates)
        self.n_mixels = len(world.mincam)
        self._plan = world.mincam_scene.fast_plan(spp, self.replicates, seed)
        self._to_world, self._texture = f"{name}.to_world", f"{name}.bsdf.reflectance.data"
        self._lanes = self._trace()
        self._revisions = self._scene_revisions()

    def _scene_revisions(self) -> dict[str, int]:
        # the plane's own placement and texture may change (a frame's texture is looked up when it is replayed)
        return {k: v for k, v in self.world.revisions.items() if k not in (self._to_world, self._texture)}

    def _trace(self) -> list[_Lanes]:
        world, name = self.world, self.name
        to_world, data = self._to_world, self._texture
        as_found = {to_world: world.world_value(to_world), data: world.world_value(data)}
        absent = self._cover_m.copy()
        absent[:3, :2] *= _ABSENT_SCALE
        try:
            world.update({to_world: self._cover_m, data: np.ones(tuple(as_found[data].shape), dtype=np.float32)})
            white = self._launch_values()
            world.update({to_world: absent})
            gone = self._launch_values()
        finally:
            world.update(as_found)
        if any(_any(meets) for _, _, _, meets, _ in gone):
            raise RuntimeError(f"a ray met the removed plane {name!r} (shrunk {1 / _ABSENT_SCALE:g} times)")
        return [_Lanes(*lanes, without=removed[-1]) for lanes, removed in zip(white, gone, strict=True)]

    def _launch_values(self) -> list[tuple]:
        import drjit as dr

        mi, scene = self.mi, self.world.scene
        integrator, sensor = scene.integrator(), self.world.sensor
        shape = self.mi.ShapePtr(self._shape)
        centre = mi.Point3f(*(float(c) for c in self._centre))
        out = []
        for launch in sensor_launches(sensor, *self._plan):
            hit = scene.ray_intersect(mi.Ray3f(launch.ray))
            meets = hit.is_valid() & (hit.shape == shape)
            radiance, _, _ = integrator.sample(scene, launch.sampler, launch.ray, None, True)
            value = launch.weight * radiance
            offset = hit.p - centre
            dr.eval(meets, value, offset)
            out.append((launch.groups, launch.samples, offset, meets, value))
        return out

    def estimates(self, placement_m: np.ndarray) -> np.ndarray:
        """(replicates, n_mixels) estimates [W/m^2] with the plane at ``placement_m`` (4 x 4, world [m]): what
        ``world.update({name + ".to_world": placement_m}); the aperture solver's estimates`` gives, up to float32
        rounding."""
        import drjit as dr

        mi = self.mi
        matrix = _check_placements([placement_m], self.name)[0]
        self._check_in_plane(matrix)
        changed = sorted(k for k, v in self._scene_revisions().items() if self._revisions.get(k) != v)
        if changed:
            raise InputError(f"the scene changed since the SlidingPlane of {self.name!r} was built ({changed}); its "
                             "traced rays no longer hold: build a new SlidingPlane")
        local = np.linalg.inv(matrix[:3, :3])
        shift = local @ (self._centre + self._origin - matrix[:3, 3])  # local coordinates of the cover's centre
        rows = [[dr.opaque(mi.Float, float(v)) for v in row] for row in local[:2]]
        base = [dr.opaque(mi.Float, float(v)) for v in shift[:2]]
        bsdf = self._shape.bsdf()
        totals = np.zeros(self.replicates * self.n_mixels, dtype=np.float64)
        for lanes in self._lanes:
            q = lanes.offset
            x = dr.fma(rows[0][0], q.x, dr.fma(rows[0][1], q.y, dr.fma(rows[0][2], q.z, base[0])))
            y = dr.fma(rows[1][0], q.x, dr.fma(rows[1][1], q.y, dr.fma(rows[1][2], q.z, base[1])))
            on = lanes.meets & (dr.abs(x) <= 1) & (dr.abs(y) <= 1)
            si = dr.zeros(mi.SurfaceInteraction3f, dr.width(x))
            si.uv = mi.Point2f(dr.fma(x, 0.5, 0.5), dr.fma(y, 0.5, 0.5))  # the rectangle's uv
            albedo = bsdf.eval_diffuse_reflectance(si, on)
            totals[lanes.groups] += lane_sums(dr.select(on, albedo * lanes.per_albedo, lanes.without), lanes.samples)
        means = totals / self._plan[1]
        return means.reshape(self.n_mixels, self.replicates).T

    def _check_in_plane(self, matrix: np.ndarray) -> None:
        normal, offset = _plane_of(matrix, self._origin)
        if not (abs(offset - float(self._normal @ self._centre)) <= PLANE_TOLERANCE * (1 + np.abs(self._centre).max())
                and np.linalg.norm(np.cross(normal, self._normal)) <= PLANE_TOLERANCE and normal @ self._normal > 0):
            raise InputError(f"placement of {self.name!r} leaves the plane it was replayed in; a SlidingPlane "
                             "replays motion within that plane only: trace other motion with world.estimates")
        corners = _corners(matrix, self._origin) - self._centre
        cover = np.linalg.inv(self._cover_m[:3, :3]) @ corners.T
        if np.abs(cover[:2]).max() > 1 + 1e-9:
            raise InputError(f"placement of {self.name!r} reaches beyond the placements the SlidingPlane was "
                             "built for: pass every placement to SlidingPlane(..., placements_m=...)")


@dataclass(frozen=True)
class PlaneReplay(Solver):
    """The :class:`~.aperture.Aperture` solver's rays traced once, and every frame replayed: for frames that only
    move one diffuse textured rectangle (``plane``, its ``to_world``) within its own plane, in a scene where every
    other shape is black (:class:`SlidingPlane`). Slides give the Aperture solver's numbers to float32 rounding;
    turns agree within the standard error.

    Parameters
    ----------
    plane : str
        The rectangle's element name (e.g. ``"road"``).
    """

    plane: str = "road"
    name: ClassVar[str] = "plane_replay"
    budget_reads: ClassVar[tuple[str, ...]] = ("spp", "replicates", "seed")  # traced once: no target search
    scenes: ClassVar[tuple[str, ...]] = ("world",)

    def plan(self, sim, frames, budget: Budget, *, background=None, cache=None, show_progress: bool = False) -> Plan:
        return ReplayPlan(self, sim, frames, budget)


class ReplayPlan(Plan):
    """Each frame's (replicates, n_mixels) estimates by one :class:`SlidingPlane` over every frame's placement
    (built over all of them, so that a resumed run replays the same rays); the frames may set only the plane's
    ``to_world``."""

    def __init__(self, solver: PlaneReplay, sim, frames, budget: Budget) -> None:
        self.solver, self.sim, self.frames = solver, sim, check_update_frames(frames)
        self.budget, self.replicates = budget, budget.replicates_or(DEFAULT_REPLICATES)
        self.n_rows, self.columns = len(self.frames), list(sim.mincam.names)
        plane = solver.plane
        key = f"{plane}.to_world"
        if key not in sim.params:
            raise InputError(f"PlaneReplay(plane={plane!r}): the scene has no parameter {key!r}; name the textured "
                             "rectangle's element")
        for i, frame in enumerate(self.frames):  # dicts: check_update_frames
            other = sorted(k for k in frame if k != key)
            if other:
                raise InputError(f"frames[{i}] sets {other}: the PlaneReplay solver replays frames that move only "
                                 f"{key!r}; measure other frames with solver=ms.Aperture()")
        as_built = sim.complete_background(self.frames, {})
        unset = as_built[key] if key in as_built else sim.params[key]  # a frame that leaves the plane where it is
        self.placements = [frame.get(key, unset) for frame in self.frames]
        self.replay = None
        if self.placements:
            self.replay = SlidingPlane(sim, plane, self.placements, budget.rays(), budget.seed, self.replicates)

    def rows(self, pending: np.ndarray) -> Iterator[Row]:
        for i in pending:
            mean, err = replicate_mean_stderr(self.replay.estimates(self.placements[int(i)]))
            yield [int(i)], mean[None], err[None]

    def result(self, values: np.ndarray, errors: np.ndarray) -> Measurements:
        meta = {"solver": self.solver.name, "form": "fast_world", "seed": self.budget.seed,
                "replicates": self.replicates, "spp_per_mixel_per_frame": self.budget.rays()}
        shape = (self.n_rows, len(self.columns))  # (0, n_mixels) for no frames
        return Measurements(values.reshape(shape), errors.reshape(shape), self.sim.mincam.names, meta)


def _any(mask) -> bool:
    import drjit as dr

    return bool(dr.any(mask))


def _check_scene(world, name: str):
    """The plane's shape, if the replay is exact in this scene (else :class:`InputError` naming the fix)."""
    shapes = world.shapes_by_id
    named = {key.split(".", 1)[0] for key in world.params}  # the user's elements (the mincam's bodies are hidden)
    users = sorted(k for k in shapes if k in named)
    if not isinstance(name, str) or name not in users:
        raise InputError(f"SlidingPlane: no element named {name!r} among the scene's shapes ({users})")
    shape = shapes[name]
    if shape.shape_type() != backend.mitsuba().ShapeType.Rectangle:
        raise InputError(f"SlidingPlane: element {name!r} is a {shape.class_name()}, not a rectangle")
    bsdf = shape.bsdf()
    if shape.emitter() is not None:
        raise InputError(f"SlidingPlane: element {name!r} also emits light, which its albedo does not scale; "
                         "replay only a plane that reflects")
    if bsdf.class_name() != "SmoothDiffuse" or f"{name}.bsdf.reflectance.data" not in world.mincam_scene.params:
        raise InputError(f"SlidingPlane: element {name!r} needs a diffuse BSDF with a bitmap reflectance "
                         "(mincam_sim.render.scene.scene_dicts.textured_plane), got "
                         f"{bsdf.class_name()}")
    reflecting = sorted(s.id() for s in world.scene.shapes() if s.id() != name and not _black(backend.mitsuba(), s))
    if reflecting:
        raise InputError(f"SlidingPlane: the replay is exact only when {name!r} is the one surface that reflects "
                         f"light, but {reflecting} reflect too; trace such scenes with world.estimates")
    return shape


def _black(mi, shape) -> bool:
    """True if the shape reflects no light (a diffuse BSDF of constant reflectance 0)."""
    bsdf = shape.bsdf()
    if bsdf is None or bsdf.class_name() != "SmoothDiffuse":
        return False
    params = mi.traverse(bsdf)
    return list(params.keys()) == ["reflectance.value"] and float(np.max(np.asarray(params["reflectance.value"]))) == 0


def _check_placements(placements_m, name: str) -> list[np.ndarray]:
    try:
        placements = [np.asarray(m, dtype=np.float64) for m in placements_m]
    except (TypeError, ValueError):
        placements = []
    if not placements or any(m.shape != (4, 4) or not np.isfinite(m).all() for m in placements):
        raise InputError(f"SlidingPlane: placements_m of {name!r} must be a non-empty sequence of finite 4 x 4 "
                         "to_world matrices [m]")
    if any(abs(np.linalg.det(m[:3, :3])) < 1e-300 or np.any(m[3] != (0, 0, 0, 1)) for m in placements):
        raise InputError(f"SlidingPlane: placements_m of {name!r} must be invertible affine matrices")
    return placements


def _plane_of(matrix: np.ndarray, origin: np.ndarray) -> tuple[np.ndarray, float]:
    """Unit normal (local +z side) and offset ``n . x`` of a placement's plane, in scene coordinates."""
    normal = np.cross(matrix[:3, 0], matrix[:3, 1])
    normal /= np.linalg.norm(normal)
    return normal, float(normal @ (matrix[:3, 3] - origin))


def _corners(matrix: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """The rectangle's 4 corners (local (+-1, +-1, 0)) in scene coordinates [m]."""
    local = np.array([[sx, sy, 0.0, 1.0] for sx in (-1, 1) for sy in (-1, 1)])
    return (local @ matrix.T)[:, :3] - origin


def _cover(placements: list[np.ndarray], origin: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The plane's unit normal, and the centre (scene coordinates) and world matrix of a rectangle in the first
    placement's plane that covers every placement (in-plane axes of the first one; refuses placements out of
    that plane)."""
    normal, offset = _plane_of(placements[0], origin)
    e1 = placements[0][:3, 0] / np.linalg.norm(placements[0][:3, 0])
    e1 -= normal * (normal @ e1)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    points = []
    for i, m in enumerate(placements):
        n_i, off_i = _plane_of(m, origin)
        scale = 1 + np.abs(m[:3, 3] - origin).max()
        if np.linalg.norm(np.cross(n_i, normal)) > PLANE_TOLERANCE or n_i @ normal < 0 \
                or abs(off_i - offset) > PLANE_TOLERANCE * scale:
            raise InputError(f"SlidingPlane: placements_m[{i}] is not in the plane of placements_m[0] (normal "
                             f"{np.round(n_i, 9).tolist()} vs {np.round(normal, 9).tolist()}, offset "
                             f"{off_i - offset:.3g} m); only motion within one plane, facing one way, replays")
        points.append(_corners(m, origin))
    points = np.concatenate(points)
    a, b = points @ e1, points @ e2
    half = np.array([a.max() - a.min(), b.max() - b.min()]) / 2 * (1 + 1e-6)
    centre = e1 * (a.max() + a.min()) / 2 + e2 * (b.max() + b.min()) / 2 + normal * offset
    cover = np.eye(4)
    cover[:3, 0], cover[:3, 1], cover[:3, 2], cover[:3, 3] = e1 * half[0], e2 * half[1], normal, centre + origin
    return normal, centre, cover


__all__ = ["PlaneReplay", "ReplayPlan", "SlidingPlane"]
