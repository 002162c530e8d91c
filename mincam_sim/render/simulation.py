"""One front door: a :class:`Simulation` holds a mincam in a scene; solvers and a budget measure it.

::

    import mincam_sim as ms

    sim = ms.Simulation(ms.pair_layout(spacing_m=0.033), screen=ms.Screen())
    m = sim.measure(frames, solver=ms.ResponseMap(), budget=ms.Budget(target_rel_stderr=1e-3))

    world = ms.Simulation(ms.cross_layout(), world="room.xml")          # or a dict of elements, or an mi.Scene
    ch = world.measure_changes(frames, solver=ms.StratifiedChange(), budget=ms.Budget(spp=1 << 15))
    ch.dp, ch.p, ch.info.rays_per_mixel_per_frame, ch.info.reached_rel_stderr

Display scenes measure frames (radiance images, row 0 at the top); world scenes measure parameter updates
(``"name.parameter" -> value``, positions in world coordinates [m], as :attr:`Simulation.params` reads them),
absolutely (:meth:`Simulation.measure`) or as changes against a background (:meth:`Simulation.measure_changes`).
Each measurement is ``solver.plan(self, frames, budget)`` run through a sink (:mod:`mincam_sim.frames`).
Persistence (the identity, the lock, resume) is the business of :class:`mincam_sim.runs.run.Run`; a simulation
builds no identity, it only says what determines its scene's numbers (:meth:`Simulation.identity`).

A world scene is built around the mincam: Mitsuba offsets every secondary ray by ~1e-4 x (1 + max|p|) scene
units, so a table 50 m (1 km) from the origin lost 1.2 % (3.7 %) of a toy's dP to shadow rays that started past
it. Positions in (updates to) the user's elements are shifted on their way in and out: the API speaks world
coordinates only (:attr:`Simulation.params`, :meth:`Simulation.update`).
"""

from __future__ import annotations

import contextlib
import difflib
import functools
import os
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from os import PathLike
from pathlib import Path

import numpy as np

from mincam_sim.budget import Budget
from mincam_sim.changes import Changes
from mincam_sim.errors import IgnoredSettingWarning, InputError
from mincam_sim.frames import FrameSink, MemorySink, collect
from mincam_sim.measurements import Measurements
from mincam_sim.model.optics import Mincam
from mincam_sim.progress import progress
from mincam_sim.render import backend
from mincam_sim.render.camera_change import CameraChange, outside
from mincam_sim.render.kernels.camera_window import FilmProjection, Window, change_windows, window_render
from mincam_sim.render.kernels.change_geometry import (
    change_points_each,
    changed_shapes,
    delta_light_spheres,
    delta_surfaces,
    emitters_among,
    redirects_light,
)
from mincam_sim.render.kernels.change_region import ApertureRegions, mixel_regions_each
from mincam_sim.render.kernels.frozen import keeps_recording, recordings
from mincam_sim.render.kernels.guided_path import MAX_GUIDES, guide_spheres, spheres_of
from mincam_sim.render.kernels.map_tracing import FRAME_CHUNK_BYTES, check_radiance
from mincam_sim.render.kernels.stratified import buffers_key
from mincam_sim.render.scene.gltf_files import GLTF_SUFFIXES, GltfFile
from mincam_sim.render.scene.mincam_scene import CAMERA_KEY, SENSOR_KEY, MincamScene, camera_render
from mincam_sim.render.scene.scene_dicts import mincam_body_keys
from mincam_sim.render.scene.scene_files import SceneFile, check_parameters, in_metres
from mincam_sim.render.scene.updates import removal_updates
from mincam_sim.render.scene.world_checks import (
    check_far_from_origin,
    check_unit,
    require_light,
    require_triangles,
    warn_if_implausible_size,
    warn_if_inside,
)
from mincam_sim.render.scene.world_input import (
    check_built_params,
    check_update,
    check_update_keys,
    expand_elements,
    note_taken,
    refuse_taken,
)
from mincam_sim.render.solvers import Aperture, ResponseMap, Solver, StratifiedChange
from mincam_sim.scene.display import FrameSource, Screen, as_frame_source
from mincam_sim.storage.identity import display_frames_identity, fingerprint, scene_file_digests, updates_fingerprint

Updates = Mapping[str, np.ndarray]
DEFAULT_SOLVERS = {"display": ResponseMap, "world": Aperture}  # Simulation.measure's solver by scene kind
DEFAULT_MAX_DEPTH = 3  # world scenes without a given depth or a file's integrator: one inter-reflection
MAX_FILE_DEPTH = 16  # a file's unbounded (-1) or longer max_depth is taken as this
MOVING_SUFFIXES = (".to_world", ".vertex_positions", ".position")  # the parameters that move a shape or light


class Simulation:
    """A mincam in a display scene or in a world.

    Parameters
    ----------
    mincam : Mincam
        The mixels, with their poses in world coordinates [m].
    screen : Screen, optional
        An emissive display in a dark room (frames are its radiance images).
    world : dict, mitsuba.Scene, or path, optional
        A world: elements ``name -> Mitsuba dict or object`` (a loaded ``mi.Scene`` or a
        ``SceneFile`` (``render/scene/scene_files.py``) among them contributes its shapes and lights), a
        loaded ``mi.Scene``, or a Mitsuba 3 XML scene file (loaded with every shape kept as built, addressed by its
        id; shapes without an id are static geometry). Lengths in metres, or in units of ``unit_m``.
    max_depth : int, optional
        World scenes: longest path, in segments from the mask (2 = direct light only; 3 adds one bounce). Default:
        the scene file's ``<integrator>`` ``max_depth`` if it has one, else 3 (``max_depth_source`` says
        which).
    camera : dict, optional
        World scenes: a ground-truth pinhole camera (``mincam_sim.render.scene.scene_dicts.pinhole_camera``).
    parameters : dict, optional
        A scene file's ``<default>`` values, ``name -> value`` as the XML writes them (``{"lamp": "0, 0, 0"}``),
        set through Mitsuba's loader; part of :meth:`identity`.
    unit_m : float
        World scenes: the length of one scene unit in metres (0.01 for a scene modelled in cm); the mincam, the
        camera, :attr:`params` and updates stay in metres.
    """

    def __init__(self, mincam: Mincam, *, screen: Screen | None = None, world=None, max_depth: int | None = None,
                 camera: dict | None = None, parameters: Mapping[str, object] | None = None,
                 unit_m: float = 1.0) -> None:
        if not isinstance(mincam, Mincam):
            raise InputError(f"mincam must be a Mincam (e.g. mincam_sim.cross_layout()), got {type(mincam).__name__}")
        if (screen is None) == (world is None):
            raise InputError("a Simulation holds either screen=Screen(...) or world=..., exactly one of them")
        if screen is not None and not isinstance(screen, Screen):
            raise InputError(f"screen must be a mincam_sim.Screen, got {type(screen).__name__}")
        if screen is not None and (parameters or unit_m != 1.0):
            raise InputError("parameters and unit_m belong to world scenes (a scene file); a display has neither")
        self.mincam, self.screen = mincam, screen
        self.kind = "display" if screen is not None else "world"
        self.source: Path | None = None
        self._display_scene: MincamScene | None = None
        if world is not None:
            self.unit_m = check_unit(unit_m)
            self._build_world(self._world_elements(world, parameters), max_depth, camera)

    def _world_elements(self, world, parameters) -> dict:
        """``world`` as elements: a file path becomes a ``SceneFile`` (with ``parameters``), a loaded scene
        one element."""
        if isinstance(world, (str, PathLike)):
            self.source = Path(world)
            if self.source.suffix.lower() in GLTF_SUFFIXES and not parameters:  # glTF has no <default> parameters
                return {"scene": GltfFile(self.source)}
            return {"scene": SceneFile(self.source, check_parameters(parameters))}
        if parameters:
            raise InputError("parameters set a scene file's <default> values: give world='scene.xml' (or a SceneFile "
                             "element) with them")
        if isinstance(world, Mapping):
            return dict(world)
        if isinstance(world, backend.mitsuba().Scene):
            return {"scene": world}
        raise InputError(f"world must be a dict of elements, a loaded mitsuba Scene or the path of a Mitsuba XML "
                         f"scene file, got {type(world).__name__}")

    # ------------------------------------------------------------------------------------------ world state
    def _build_world(self, elements, max_depth: int | None, camera: dict | None) -> None:
        backend.require_jit("The fast mixel sensor (a Python Mitsuba plugin)")
        # replay the stratified launches (dr.freeze) instead of tracing them per frame: on LLVM, where the moving
        # meshes' vertices are written in place and their buffers' addresses key the recordings
        self.freeze_launches = backend.variant().startswith("llvm")
        self.pair_lanes = True  # background pass: trace again only the lanes whose frame paths met a moving shape
        # change runs: static geometry in a scene of its own, built once (static_split.py): None = where the static
        # shapes hold >= solvers.change.SPLIT_MIN_TRIANGLES triangles, True = wherever it applies, False = never
        self.split_static: bool | None = None
        self.static_splits: dict = {}  # that scene and the movers', kept while no static parameter changes
        elements, self._loaded = expand_elements(elements)
        self._loaded.note()
        max_depth, self.max_depth_source = _resolved_depth(max_depth, self._loaded.max_depth)
        self.scene_origin_m = self.mincam.centre_m
        moves = bool(np.any(self.scene_origin_m != 0)) or self.unit_m != 1.0  # the given objects, in place
        refuse_taken(elements, moves)  # a shape object another Simulation took into its own coordinates
        self.scene_mincam = self.mincam.translated(-self.scene_origin_m)
        try:
            self.mincam_scene = MincamScene.world(self.scene_mincam, elements, max_depth, camera)
        except ValueError as exc:
            raise InputError(str(exc)) from None
        try:
            self.scene = self.mincam_scene.fast_scene
        except RuntimeError as exc:  # Mitsuba's own message names the plugin and the parameter
            raise InputError(f"Mitsuba could not build the scene: {str(exc).strip()}") from None
        self.sensor = self.mincam_scene.sensor(SENSOR_KEY)
        self.camera = self.mincam_scene.sensor(CAMERA_KEY)
        self._own = mincam_body_keys(self.scene_mincam) | {SENSOR_KEY}  # built in scene coordinates
        scene_params = self.mincam_scene.params
        check_built_params(scene_params)
        self._shifted = _shifted_keys(self.scene, scene_params, self._own)
        shape_ids = {s.id() for s in self.scene.shapes()}
        # file units -> metres once (not the camera, given in metres), then the scene is built around the mincam
        self.mincam_scene.update({key: _shift(key, scene_params[key] if key.startswith(CAMERA_KEY) else in_metres(
            key, scene_params[key], self.unit_m, shape_ids), -self.scene_origin_m)
            for key in self._shifted})
        note_taken(elements, moves)
        skip = self._own | {CAMERA_KEY}
        require_triangles(self.scene, skip)
        check_far_from_origin(self.scene, self.scene_origin_m, skip, self.unit_m, self.scene_mincam)
        warn_if_implausible_size(self.scene, self.scene_mincam, skip, self.unit_m)
        warn_if_inside(self.scene, self.scene_mincam, skip)
        self._restore: dict[str, object] = {}  # what the last run set, to put back with the next update
        self._params = WorldParameters(self)
        self.known_parts: dict[str, list] = {}  # instance name -> the shapes of the group it draws (change_geometry)
        self._mirrors = delta_surfaces(self.scene, self.known_parts)
        self._content_key: str | None = None
        self._content_key = self._content_fingerprint()  # before any update: the scene as built
        self._as_built: dict[str, object] = {}  # each updated parameter's value (world coordinates) before updates
        self._camera_frozen_images, self._camera_traced = 0, False  # camera renders replayed, or traced from now
        self._camera_frozen_windows, self._film_projection = 0, None  # camera windows replayed; their projection
        self._last_set: dict[str, np.ndarray] = {}  # the last numpy value each parameter was set to
        self.revisions: dict[str, int] = {}  # how often each parameter was changed (who replays a scene checks it)
        self._traversals: dict = {}  # mi.traverse of the objects buffers_key reads (read afresh every call)

    def _require_world(self, what: str) -> None:
        if self.kind != "world":
            raise InputError(f"this Simulation holds a display; {what} belong to world scenes")

    @property
    def params(self) -> WorldParameters:
        """The world's parameters in world coordinates (read-only mapping; see :class:`WorldParameters`)."""
        self._require_world("parameters and updates")
        self._put_back()
        return self._params

    def update(self, updates: Updates) -> None:
        """Set world parameters (numpy arrays or Mitsuba values; positions in world coordinates [m], as
        :attr:`params` reads them) and apply them without reloading."""
        self._check_updates(updates)
        if self._restore:  # what the last run set goes back with this update, in one rebuild
            updates, self._restore = {**self._restore, **updates}, {}
        for key in updates:
            self._remember_as_built(key)
        updates = self._new_values(updates)
        for key in updates:
            self.revisions[key] = self.revisions.get(key, 0) + 1
        self.mincam_scene.update(self._in_scene(updates))
        if any(key.split(".", 1)[0] in self._mirrors for key in updates):
            self._mirrors = delta_surfaces(self.scene, self.known_parts)

    def scene_updates(self, updates: Updates) -> dict:
        """``updates`` (world coordinates, as :meth:`update` takes them) checked and in scene coordinates, as the
        world scene's parameters take them; nothing is applied."""
        self._check_updates(updates)
        return self._in_scene(updates)

    def _check_updates(self, updates: Updates) -> None:
        self._require_world("parameters and updates")
        if not isinstance(updates, Mapping):
            raise InputError(f"an update must be a dict 'name.parameter' -> value, got {type(updates).__name__}")
        check_update_keys(updates, "update")
        scene_params = self.mincam_scene.params
        for key, value in updates.items():
            if key not in scene_params or key.split(".", 1)[0] in self._own:
                raise InputError(_unknown_parameter(key, self._params.keys(), key.split(".", 1)[0] in self._own))
            check_update(key, scene_params[key], value)

    def _in_scene(self, updates: Updates) -> dict:
        return {key: _shift(key, value, -self.scene_origin_m) if key in self._shifted else value
                for key, value in updates.items()}

    def _new_values(self, updates: Updates) -> dict:
        """The updates that change something: a numpy value equal to the one set last is left out, so a frame
        that re-parks every idle toy moves only the toy that moves (its shapes keep their buffers, and a frozen
        launch keeps its recordings)."""
        out = {}
        for key, value in updates.items():
            if isinstance(value, np.ndarray):
                last = self._last_set.get(key)
                if last is not None and last.dtype == value.dtype and np.array_equal(last, value):
                    continue
                self._last_set[key] = value.copy()
            else:
                self._last_set.pop(key, None)
            out[key] = value
        return out

    def complete_background(self, frames: Sequence[Updates], background: Updates) -> dict:
        """``background`` plus, for every parameter the frames set and it leaves out, that parameter's value in the
        scene as built (so that restoring the background undoes every frame)."""
        missing = sorted({key for f in frames for key in f} - set(background))
        for key in missing:
            self._remember_as_built(key)
        return {**background, **{key: self._as_built[key] for key in missing if key in self._as_built}}

    def _remember_as_built(self, key: str) -> None:
        if key not in self._as_built and key in self._params:
            self._as_built[key] = self._world_value(key)  # never set before: as built, with nothing to put back

    def movable(self) -> list[str]:
        """Names of the user's shapes and lights that updates can move: shapes with a ``to_world`` or vertex
        positions, point and spot lights (not the ground-truth camera, an environment, shapes a loaded scene gave
        without an id, or the mincam's bodies)."""
        keys = set(self._params.keys())
        names = {key.split(".", 1)[0] for key in keys if key.endswith(MOVING_SUFFIXES)}
        directional = {e.id() for e in self.scene.emitters() if e.is_environment() or
                       int(e.flags()) & int(backend.mitsuba().EmitterFlags.Infinite)}
        return sorted(names - directional - {CAMERA_KEY} - self._own - self._loaded.static)

    def without(self, *names: str) -> dict:
        """Parameter updates that take the named shapes or lights out of the scene (a change's background):
        a mesh's vertices all at its centre (no area left), a shape with a ``to_world`` shrunk about its centre
        to a speck of 1 um, with its emission set to 0 if it emits, a point or spot light's intensity set to 0.

        Raises
        ------
        InputError
            A name that is not a movable shape or light (the message lists those that are).
        """
        self._require_world("parameters and updates")
        movable, out = self.movable(), {}
        for name in names:
            if name not in movable:
                raise InputError(f"{name!r} is not a shape or light of the scene that can move; movable: "
                                 f"{', '.join(movable) or 'none'}")
            out.update(removal_updates(self._params, name, name in self.shapes_by_id))
        return out

    @functools.cached_property
    def shapes_by_id(self) -> dict:
        """The scene's shapes by their id (fixed once the scene is loaded)."""
        return {shape.id(): shape for shape in self.scene.shapes()}

    def buffers_key(self) -> tuple:
        """``stratified.buffers_key`` of every shape whose parameters were updated (the whole scene if an
        updated parameter belongs to something else: a shared BSDF, an environment emitter)."""
        names = {key.split(".", 1)[0] for key in self._as_built}
        shapes = self.shapes_by_id
        objects = [shapes[name] for name in sorted(names) if name in shapes]
        return buffers_key(objects if len(objects) == len(names) else [self.scene], self._traversals)

    def world_value(self, key: str):
        """Parameter ``key`` as :meth:`update` takes it back, in world coordinates: positions (``to_world``
        as a 4 x 4 matrix, ``vertex_positions`` flat (3 n,), a point light's ``position``) as float64 numpy,
        anything else as a copy of the Mitsuba value."""
        self._put_back()
        return self._world_value(key)

    def _world_value(self, key: str):
        value = _param_value(self.mincam_scene.params[key])
        return _shift(key, value, self.scene_origin_m) if key in self._shifted else value

    def change_regions(self, moving: Sequence[str]) -> ApertureRegions:
        """Aperture regions (per mixel) that the named shapes, in their current place, their shadows and their
        images in the scene's planar mirrors reach (and every other delta surface: glass, curved mirrors): the
        bounding rectangle of each shape's own region; the whole aperture if one of them is unbounded."""
        return self.change_reach(moving)[0]

    def change_guide(self, moving: Sequence[str]) -> list[tuple[np.ndarray, float]] | None:
        """Spheres (centre, radius [m], scene coordinates) toward which guided bounces aim: one per group of the
        named shapes, in their current place, with their shadow volumes; None if a change is unbounded."""
        return self.change_reach(moving)[1]

    def change_reach(self, moving: Sequence[str], scene=None) -> tuple[ApertureRegions, list | None, list[str]]:
        """:meth:`change_regions`, :meth:`change_guide` and why a change is unbounded, from one look at the
        scene (``scene``: the world as a static split has it, else the world scene)."""
        self._put_back()
        each, spheres, reasons = self.change_reach_each(moving, scene)
        regions = ApertureRegions.empty(self.mincam)
        for part in each:
            regions = regions.union(part)
        return regions, spheres, reasons

    def change_reach_each(self, moving: Sequence[str],
                          scene=None) -> tuple[list[ApertureRegions], list | None, list[str]]:
        """:meth:`change_reach` with the regions of each named shape apart (in sorted name order; each one's
        own and its mirror images' bounding rectangle), or ``[whole aperture]`` if a change is unbounded."""
        self._put_back()
        scene = self.scene if scene is None else scene
        points, regions = self._reach_of_each(sorted(moving), scene)
        reasons = [why for _, why in regions.values() if why]
        if reasons:
            return [ApertureRegions.full(self.mincam)], None, reasons
        each = [r for r, _ in regions.values()]
        spheres = guide_spheres(list(points.values()))
        if spheres:  # light reaching the change through a mirror: bounces aimed at the lights' images find it
            spheres = spheres + self._mirrors.light_image_spheres(scene)
            # light a moving glass block throws: bounces aimed at the lights and their images in its faces, as many
            # as fit beside the others (the lights first); more would merge all into one sphere holding the view
            through = delta_light_spheres(scene, moving, taken=len(spheres), known=self.known_parts)
            spheres = spheres_of(spheres + through[:max(0, MAX_GUIDES - len(spheres))])
        return each, (spheres or None), []

    def change_regions_each(self, moving: Sequence[str]) -> dict[str, tuple[ApertureRegions, str]]:
        """Each named shape's aperture regions on its own (its own and its mirror images' bounding rectangle; the
        whole aperture where its change is unbounded) and why it is unbounded ("" if not), from one look at the
        scene: what :meth:`change_reach` of each name alone gives, without the guides."""
        self._put_back()
        return self._reach_of_each(sorted(moving), self.scene)[1]

    def _reach_of_each(self, names: list[str], scene) -> tuple[dict, dict]:
        """(change points of each bounded name, {name: (regions, why unbounded or "")}) for ``names``."""
        hulls = self._hull_sets(names, scene)
        bounded = {name: sets for name, (sets, _) in hulls.items() if sets is not None}
        flat = iter(mixel_regions_each(self.scene_mincam, [q for sets in bounded.values() for q in sets]))
        regions = {}
        for name, sets in bounded.items():  # the shape's own region, then its images' (in order)
            own = next(flat)
            for _ in sets[1:]:
                own = own.union(next(flat))
            regions[name] = (own, "")
        full = ApertureRegions.full(self.mincam)
        return ({name: sets[0] for name, sets in bounded.items()},
                {name: regions[name] if name in regions else (full, hulls[name][1]) for name in names})

    def _hull_sets(self, names: list[str], scene) -> dict[str, tuple[list | None, str]]:
        """Per name, the corner points [m] of the shape's change hull as ``scene`` is now followed by those of its
        images in the delta surfaces (mirror images, boxes of curved ones), or None and why the change is
        unbounded."""
        out = {}
        for name, (p, why) in zip(names, change_points_each(scene, [[n] for n in names], self._mirrors), strict=True):
            out[name] = (None, why) if p is None else ([p, *self._mirrors.images(p, exclude=name)], "")
        return out

    def camera_image(self, spp: int = 64, seed: int = 0) -> np.ndarray:
        """The ground-truth camera's image [W m^-2 sr^-1], row 0 at the top (world scenes)."""
        self._require_world("ground-truth cameras")
        self._put_back()
        key = self._camera_freeze_key()
        image = self.mincam_scene.camera_image(spp, seed, freeze=key)
        if key is not None:
            self._camera_frozen_images += 1
            recorded = recordings(self.mincam_scene.fast_scene, camera_render)
            if keeps_recording(recorded, self._camera_frozen_images):
                self._camera_traced = True  # every image records anew (a shape moved by a changing transform)
        return image

    def camera_changes(self, frames: Sequence[Updates], background: Updates, spp: int = 64, seed: int = 0,
                       elsewhere_spp: int = 0, show_progress: bool = False) -> list[CameraChange]:
        """The ground-truth camera's view of each frame (updates applied on top of ``background``) and of the
        background over the windows of its film where the two can differ by direct sight or direct light: the
        images of the frame's changed shapes' boxes and shadow volumes, in the frame and in the background
        (``kernels.camera_window.change_windows``: a window per mover unless they overlap; the whole film where a
        change is unbounded: a moving light or environment light, a moving mirror or glass shape), both rendered
        there with ``spp`` samples a pixel and the same ``seed``, lane by lane
        (:class:`~mincam_sim.render.camera_change.CameraChange`).

        A change that reaches a pixel outside the windows only by an inter-reflection is not in them; with
        ``elsewhere_spp`` > 0 the whole film of each frame and of the background is rendered too, with that many
        samples a pixel and the same seed, and their difference outside the windows is kept
        (``CameraChange.elsewhere``: for sums over the whole film). Frames first, then the background's windows
        (one update a frame); the world is left as it was before the call."""
        self._require_world("ground-truth cameras")
        if self.camera is None:
            raise InputError("this world has no ground-truth camera; pass camera=pinhole_camera(...)")
        for name, value, least in (("spp", spp, 1), ("elsewhere_spp", elsewhere_spp, 0)):
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < least:
                raise InputError(f"camera_changes: {name} (samples per pixel) must be an integer >= {least}, got "
                                 f"{value!r}")
        with self._world_kept({*background, *(key for frame in frames for key in frame)}):
            if self._film_projection is None:
                self._film_projection = FilmProjection(self.camera)
            self.update(background)
            names = [sorted(changed_shapes(frame, background)) for frame in frames]
            moved = sorted(set().union(*names))
            at_background = dict(zip(moved, self._change_hulls(moved), strict=True))
            windows, frame_pixels, frame_films = [], [], []
            for frame, changed in zip(progress(frames, desc="ground truth: frames", disable=not show_progress), names,
                                      strict=True):
                self.update({**background, **frame})
                hulls = [h for per_name in (*(at_background[name] for name in changed), *self._change_hulls(changed))
                         for h in per_name]
                windows.append(change_windows(self._film_projection, hulls))
                frame_pixels.append(self._camera_windows(windows[-1], spp, seed))
                frame_films.append(self.camera_image(elsewhere_spp, seed) if elsewhere_spp else None)
            self.update(background)
            background_film = self.camera_image(elsewhere_spp, seed) if elsewhere_spp else None
            changes = []
            # the background over a window is the same render whichever frame asks for it (one scene state, one
            # seed, random numbers by the window's shape): each window rendered once
            background_pixels: dict[tuple, tuple[np.ndarray, ...]] = {}
            for k in progress(range(len(frames)), desc="ground truth: background", disable=not show_progress):
                elsewhere = None if background_film is None else outside(frame_films[k] - background_film, windows[k])
                frame_films[k] = None  # one film a frame held at a time beyond the differences
                if windows[k] not in background_pixels:
                    background_pixels[windows[k]] = self._camera_windows(windows[k], spp, seed)
                changes.append(CameraChange(windows[k], frame_pixels[k], background_pixels[windows[k]], elsewhere))
            return changes

    def _change_hulls(self, names: list[str]) -> list:
        """Per name, the corner points [m] of the shape's change hull as the world is now and of its mirror
        images ([None] where the change is unbounded: a moving light, an environment light, or a moving mirror or
        glass, whose reflected and refracted light lands beyond its shadow)."""
        return [[None] if sets is None or redirects_light(self.scene, self.shapes_by_id[name], self.known_parts)
                else sets for name, (sets, _) in self._hull_sets(names, self.scene).items()]

    def _camera_windows(self, windows: tuple[Window, ...], spp: int, seed: int) -> tuple[np.ndarray, ...]:
        """The camera's pixels over each of ``windows`` as the world is now."""
        out = []
        key = self._camera_freeze_key()
        for window in windows:
            out.append(self.mincam_scene.camera_window(window, spp, seed, freeze=key))
            if key is not None:
                self._camera_frozen_windows += 1
                if keeps_recording(recordings(self.mincam_scene.fast_scene, window_render),
                                   self._camera_frozen_windows):
                    self._camera_traced = True
        return tuple(out)

    def _camera_freeze_key(self) -> tuple | None:
        """The key of a frozen camera render (:meth:`buffers_key`), or None (trace) off LLVM, once the images
        kept recording instead of replaying, or where an updated object emits light or is not a shape (an
        emitter's sampling tables are rebuilt where a replay cannot see them)."""
        if not self.freeze_launches or self._camera_traced:
            return None
        names = {key.split(".", 1)[0] for key in self._as_built}
        if not names <= set(self.shapes_by_id) or emitters_among(self.scene, names):
            return None
        return self.buffers_key()

    # ------------------------------------------------------------------------------------------ identity
    def _content_fingerprint(self) -> str:
        """Content key of the world as Mitsuba holds it: every traversable parameter's value (meshes, textures,
        transforms, radiances), the element names and plugin types, and the path depth."""
        if self._content_key is None:
            params = self._params
            parts = {key: _param_array(params[key]) for key in sorted(params.keys())
                     if not key.startswith(SENSOR_KEY)}
            types = {name: (value.get("type") if isinstance(value, dict) else type(value).__name__)
                     for name, value in self.mincam_scene.elements.items()}
            self._content_key = fingerprint({"params": parts, "types": types,
                                             "max_depth": self.mincam_scene.max_depth})
        return self._content_key

    def identity(self) -> dict:
        """What determines this scene's numbers (JSON-able): the mincam and the screen (displays); the mincam,
        the scene's content as built and, for a world from a file, every file it names, recursively
        (``<include>``d files, meshes and textures, also through ``$parameter`` defaults or the ``parameters``
        given), the parameters given and the unit (``unit_m``) when it is not the metre."""
        # the masks again by mixel, so that a refusal names the masks that changed rather than "the mincam"
        masks = {m.name: fingerprint(m.mask) for m in self.mincam}
        if self.kind == "display":
            return {"kind": "display", "mincam": fingerprint(self.mincam), "masks": masks,
                    "screen": fingerprint(self.screen)}
        out = {"kind": "world", "mincam": fingerprint(self.mincam), "masks": masks, "scene": self._content_key}
        if self._loaded.files:
            top = self._loaded.files[0].path.resolve().parent
            out["files"] = {}
            for file in self._loaded.files:
                digests = scene_file_digests(file.path, parameters=file.parameters)
                out["files"].update({os.path.relpath(k, top): v for k, v in digests.items()})
                if file.parameters:  # absent when none are set: the identity of a run without them is unchanged
                    out.setdefault("parameters", {}).update(file.parameters)
                if file.unit_m != 1.0:
                    out.setdefault("file_unit_m", {})[os.path.relpath(file.path.resolve(), top)] = file.unit_m
        if self.unit_m != 1.0:
            out["unit_m"] = self.unit_m
        return out

    def world_meta(self) -> dict:
        """What a world result's meta records of the scene's own settings: the path depth and where it came
        from, the unit."""
        self._require_world("scene settings")
        return {"max_depth": self.mincam_scene.max_depth, "max_depth_from": self.max_depth_source,
                "unit_m": self.unit_m}

    def content_fingerprint(self) -> str:
        """Content key of the scene (world: every traversed parameter as built; display: the screen)."""
        return self._content_key if self.kind == "world" else fingerprint(self.screen)

    def frames_identity(self, frames, background: Updates | None = None) -> dict:
        """What determines the frames (for a run's identity): a display source's description or content, hashed
        as it streams (every frame validated on the way); a world's update dicts and background."""
        if self.kind == "display":
            source = self.frame_source(frames)
            return display_frames_identity(source, source.chunk_size(FRAME_CHUNK_BYTES), check_radiance)
        return {"frames": updates_fingerprint(frames), "background": updates_fingerprint([background or {}])}

    # ------------------------------------------------------------------------------------------ measuring
    def frame_source(self, frames) -> FrameSource:
        """Display frames as a source of the screen's shape (an array (n, rows, cols), a list, or a source)."""
        frames = as_frame_source(frames)
        if tuple(frames.frame_shape) != tuple(self.screen.shape):
            raise InputError(f"frames have shape {frames.frame_shape} but this screen's frames are "
                             f"{self.screen.shape} (rows, cols)")
        return frames

    def display_scene(self, form: str = "fast") -> MincamScene:
        """The mincam in front of the screen (built on first use, shared by the display ray solvers)."""
        if self._display_scene is None:
            self._display_scene = MincamScene.display(self.mincam, self.screen)
        return self._display_scene

    def solver_for(self, solver: Solver | None, changes: bool = False) -> Solver:
        """``solver`` (or this scene kind's default), checked against the scene kind and the measurement."""
        if solver is None:
            solver = StratifiedChange() if changes else DEFAULT_SOLVERS[self.kind]()
        if not isinstance(solver, Solver):
            raise InputError(f"solver must be one of mincam_sim's solvers (e.g. ms.ResponseMap(), ms.Aperture(), "
                             f"ms.StratifiedChange()), got {type(solver).__name__}")
        solver.check(self.kind, changes)
        return solver

    @staticmethod
    def _budget(budget: Budget | None) -> Budget:
        if budget is None:
            return Budget()
        if not isinstance(budget, Budget):
            raise InputError(f"budget must be a mincam_sim.Budget, got {type(budget).__name__}")
        return budget

    def _solve(self, solver: Solver, frames, budget: Budget, background, sink: FrameSink | None,
               show_progress: bool):
        if self.kind == "world":
            require_light(self.scene)
        self._warn_ignored_budget(solver, budget)
        sink = MemorySink() if sink is None else sink
        sets = () if self.kind != "world" else {
            *(background if isinstance(background, Mapping) else {}),
            *(key for frame in (frames if isinstance(frames, Sequence) else ()) if isinstance(frame, Mapping)
              for key in frame)}
        with self._world_kept(sets):
            plan = solver.plan(self, frames, budget, background=background, cache=sink.cache,
                               show_progress=show_progress)
            table = sink.open(plan.n_rows, plan.columns)
            return plan.result(*collect(plan.rows(table.pending()), table))

    @contextlib.contextmanager
    def _world_kept(self, sets: Iterable[str] = ()) -> Iterator[None]:
        """A run's frames and background are its own: when the run ends (also by an error or an interrupt) every
        world parameter it set goes back to its value before the run, and the next run, :attr:`params`, the
        camera and the change regions see the world as the caller left it (as built, plus what :meth:`update`
        set). The values go back with the next update (a next run that sets the same background rebuilds
        nothing) or before the world is next read; ``sets`` (the keys this run sets) wait for the run's own
        first update, the others go back now."""
        if self.kind != "world":
            yield
            return
        sets = set(sets)
        if self._restore and any(key not in sets for key in self._restore):
            now = {key: value for key, value in self._restore.items() if key not in sets}
            later = {key: value for key, value in self._restore.items() if key in sets}
            self._restore = {}
            self.update(now)
            self._restore = later
        before = {key: self._restore[key] if key in self._restore else self._world_value(key)
                  for key in self._as_built}
        try:
            yield
        finally:
            # a parameter first set during the run was as built before it
            self._restore = {key: before.get(key, value) for key, value in self._as_built.items()
                             if not _same_value(self._last_set.get(key), before.get(key, value))}

    def _put_back(self) -> None:
        """Apply what the last run leaves to put back (:meth:`_world_kept`) before the world is read."""
        if self._restore:
            self.update({})

    def _warn_ignored_budget(self, solver: Solver, budget: Budget) -> None:
        """One warning naming the budget fields ``solver`` does not read on this scene (nothing is refused)."""
        reads = solver.budget_fields(self.kind)
        ignored = [name for name in budget.given_fields() if name not in reads]
        if ignored:
            what = f"reads {', '.join(reads)}" if reads else "is deterministic and reads no budget"
            warnings.warn(f"Budget.{', Budget.'.join(ignored)} {'is' if len(ignored) == 1 else 'are'} ignored: the "
                          f"{solver.name} solver on {self.kind} scenes {what}", IgnoredSettingWarning, stacklevel=4)

    def measure(self, frames, solver: Solver | None = None, budget: Budget | None = None, *,
                sink: FrameSink | None = None, show_progress: bool = False) -> Measurements:
        """What each mixel measures in each frame, with its standard error [W/m^2], (n_frames, n_mixels).

        Display scenes: ``frames`` are radiance images (an array (n, rows, cols), a list, or a FrameSource);
        default solver :class:`~.solvers.ResponseMap` (its result carries the maps as ``m.maps``). World scenes:
        ``frames`` are parameter updates, each applied to the scene as built; solver :class:`~.solvers.Aperture`,
        or :class:`~.solvers.PlaneReplay` for frames that only move one textured plane within its plane.
        ``sink`` (:class:`mincam_sim.frames.FrameSink`) takes the per-frame rows; :class:`mincam_sim.runs.run.Run`
        hands one that keeps them on disk and resumes.
        """
        return self._solve(self.solver_for(solver), frames, self._budget(budget), None, sink, show_progress)

    def measure_changes(self, frames, background: Updates | None = None, solver: Solver | None = None,
                        budget: Budget | None = None, *, sink: FrameSink | None = None,
                        show_progress: bool = False) -> Changes:
        """Each frame's change from the background, ``dP = P(frame) - P(background)``, and ``P`` (world scenes).

        Parameters
        ----------
        frames : list of dict
            Parameter updates of each frame (on top of ``background``).
        background : dict, optional
            Updates that make the background; a parameter the frames set that it leaves out takes its value in
            the scene as built (default ``{}``: the scene as built).
        solver : StratifiedChange (default) or PlainChange
        budget : Budget
            ``spp`` rays per mixel per frame and pass (or a target), replicates (default 8), seed.
        sink : FrameSink, optional
            Takes the per-frame rows (:class:`mincam_sim.runs.run.Run` hands one on disk). Default: in memory.
        """
        return self._solve(self.solver_for(solver, changes=True), frames, self._budget(budget),
                           {} if background is None else background, sink, show_progress)

    def response_maps(self, budget: Budget | None = None, *, show_progress: bool = False):
        """Each mixel's response map over the screen (display scenes), at the budget's samples per texel."""
        if self.kind != "display":
            raise InputError("response maps are maps over a screen's texels: display scenes only")
        solver, budget = ResponseMap(), self._budget(budget)
        self._warn_ignored_budget(solver, budget)
        maps, _ = solver.maps(self, budget, show_progress=show_progress)
        return maps

    def export_maps(self, out_dir: str | PathLike, budget: Budget | None = None, *, solver: Solver | None = None,
                    psf_grid: tuple[int, int] | None = None, show_progress: bool = False,
                    say: Callable[[str], None] | None = None) -> Path:
        """Write each mixel's response map as NumPy arrays with a JSON sidecar (display scenes), for other tools.

        ``maps/<mixel>.npy`` (rows, cols) [sr: W/m^2 per W m^-2 sr^-1 of each texel] and its standard error,
        ``forward_matrix.npy`` (n_mixels, rows * cols), with ``psf_grid = (nx, ny)`` ``psfs.npy``: responses to
        point sources on that grid, and ``maps.json`` (units, conventions, screen, geometry, how they were made).
        ``solver``: :class:`~.solvers.ResponseMap` (default, the physics at the budget's samples per texel) or
        :class:`~.solvers.DotProduct` (the idealised model). Returns the sidecar's path.

        The folder holds one export: the files of an earlier export there that this one does not write (the maps
        of mixels no longer there, ``psfs.npy`` without a grid) are removed, as the earlier ``maps.json`` lists
        them; no other file is touched. ``say`` is told so in one line. ``mincam-sim export-maps`` also locks the
        folder while it exports (a second process is refused, naming the holder); from Python, hold
        :func:`mincam_sim.storage.store.lock_out_dir` around the call where several processes share a folder.
        """
        from mincam_sim.render.kernels.map_export import export_maps
        from mincam_sim.render.solvers import DotProduct
        if self.kind != "display":
            raise InputError("response maps are maps over a screen's texels: display scenes only")
        if psf_grid is not None:
            grid = tuple(psf_grid) if isinstance(psf_grid, (tuple, list)) else ()
            if len(grid) != 2 or any(isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1
                                     for n in grid):
                raise InputError(f"psf_grid must be two positive integers (nx, ny), got {psf_grid!r}")
            cols, rows = self.screen.resolution
            if grid[0] > cols or grid[1] > rows:  # 20000 x 20000 took 24 GB before the kernel killed it
                raise InputError(f"psf_grid (--psf-grid) {grid[0]} x {grid[1]} is finer than the screen's {cols} x "
                                 f"{rows} texels: a point's response is its texel's weight, so a finer grid repeats "
                                 f"them; give at most {cols} x {rows}")
        if not (solver is None or isinstance(solver, DotProduct | ResponseMap)):
            raise InputError(f"export_maps takes the ResponseMap or DotProduct solver, got {type(solver).__name__}")
        if isinstance(solver, DotProduct):
            maps = solver.maps(self.mincam, self.screen, show_progress)
        else:
            maps = self.response_maps(budget, show_progress=show_progress)
        return export_maps(maps, self.mincam, self.screen, out_dir, psf_grid, say)


class WorldParameters(Mapping):
    """The scene's parameters as the user's elements define them, in world coordinates (read-only).

    Keys are ``"name.parameter"`` (``mi.traverse`` names) of the user's elements; the mincam's own bodies and
    sensor are not among them. Values are what :meth:`Simulation.update` takes back: positions
    (``to_world`` 4 x 4, ``vertex_positions`` flat (3 n,), a point light's ``position``) as float64 numpy in
    world coordinates [m], anything else a copy of the Mitsuba value. Reading a value and writing it back
    changes nothing.
    """

    def __init__(self, sim: Simulation) -> None:
        self._renderer = sim

    def _visible(self, key: str) -> bool:
        return key.split(".", 1)[0] not in self._renderer._own and "." in key

    def __getitem__(self, key: str):
        if key not in self._renderer.mincam_scene.params or not self._visible(key):
            raise KeyError(key)
        return self._renderer.world_value(key)

    def __contains__(self, key) -> bool:
        return isinstance(key, str) and key in self._renderer.mincam_scene.params and self._visible(key)

    def __iter__(self) -> Iterator[str]:
        return (k for k in self._renderer.mincam_scene.params.keys() if self._visible(k))

    def __len__(self) -> int:
        return sum(1 for _ in self)



def _resolved_depth(given: int | None, from_file: tuple[int, str] | None) -> tuple[int, str]:
    """(max_depth, where it came from): the caller's, else the loaded scene's integrator's, else 3."""
    if given is not None:
        return given, "given"
    if from_file is None:
        return DEFAULT_MAX_DEPTH, "default (no max_depth given and no integrator in the scene)"
    depth, where = from_file
    if depth < 0 or depth > MAX_FILE_DEPTH:
        return MAX_FILE_DEPTH, f"{where} (max_depth {depth}, taken as {MAX_FILE_DEPTH}: pass max_depth to choose)"
    if depth < 2:
        raise InputError(f"{where} has max_depth {depth}: the mincam's paths need at least 2 segments (mask -> "
                         "emitter); pass max_depth=2 or more, or fix the file")
    return depth, where


def _param_array(value) -> np.ndarray:
    """A traversed Mitsuba parameter as a numeric array (transforms by their matrix)."""
    matrix = _transform_matrix(value)
    arr = matrix if matrix is not None else np.asarray(value)
    if arr.dtype.hasobject:
        arr = np.frombuffer(repr(value).encode(), dtype=np.uint8)
    return arr


def _shifted_keys(scene, params, ours: set[str]) -> set[str]:
    """Parameters that hold positions, of every element but ``ours``: ``to_world`` (not of environment or
    directional emitters, whose transforms only turn directions), ``vertex_positions`` and point lights'
    ``position``."""
    directional = {e.id() for e in scene.emitters() if e.is_environment() or
                   int(e.flags()) & int(backend.mitsuba().EmitterFlags.Infinite)}
    keys = set()
    for key in params.keys():
        name, _, rest = key.partition(".")
        if name not in ours and name not in directional and rest in ("to_world", "vertex_positions", "position"):
            keys.add(key)
    return keys


def _shift(key: str, value, offset_m: np.ndarray):
    """A position parameter moved by ``offset_m`` [m] (float64 numpy, the form :meth:`Simulation.update`
    takes)."""
    if key.endswith(".to_world"):
        matrix = _transform_matrix(value)
        moved = (np.array(value, dtype=np.float64).reshape(4, 4) if matrix is None else matrix).copy()
        moved[:3, 3] += offset_m
        return moved
    points = np.array(value, dtype=np.float64).reshape(-1, 3) + offset_m
    return points.ravel()


def _transform_matrix(value) -> np.ndarray | None:
    """The matrix of a Mitsuba transform parameter (4 x 4, or 3 x 3 for texture transforms; float64), None for
    anything else."""
    if "Transform" not in type(value).__name__:
        return None
    matrix = np.array(value.matrix, dtype=np.float64)
    side = int(round(np.sqrt(matrix.size)))
    return matrix.reshape(side, side)


def _param_value(value):
    """A copy of a traversed parameter that :meth:`Simulation.update` accepts back (transforms as 4 x 4 numpy
    matrices, arrays and tensors as Mitsuba values of their own type and shape)."""
    matrix = _transform_matrix(value)
    if matrix is not None:
        return matrix
    if isinstance(value, (bool, int, float)):
        return value
    return type(value)(np.array(value))


def _same_value(last, value) -> bool:
    """True if ``last`` (the value an update set last, or None) is known to equal ``value`` (numpy values only)."""
    return (isinstance(last, np.ndarray) and isinstance(value, np.ndarray) and last.shape == value.shape
            and bool(np.array_equal(last, value)))


def _unknown_parameter(key: str, known, own: bool) -> str:
    if own:
        return (f"{key!r} belongs to the mincam's own body or sensor; move the mixels through the Mincam, not the "
                "scene")
    name = str(key).split(".", 1)[0]
    own_keys = sorted((k for k in known if k.split(".", 1)[0] == name),
                      key=lambda k: (not k.endswith(MOVING_SUFFIXES), k))
    if own_keys:  # a known shape or light: what it has (a cube, a mesh, moves by its vertex positions)
        more = f" and {len(own_keys) - 4} more" if len(own_keys) > 4 else ""
        hint = f"; '{name}' has {', '.join(map(repr, own_keys[:4]))}{more}"
    else:
        close = difflib.get_close_matches(str(key), list(known), n=3)
        hint = f"; did you mean {', '.join(map(repr, close))}?" if close else "; see the renderer's params.keys()"
    return f"unknown scene parameter {key!r}{hint}"


__all__ = ["DEFAULT_SOLVERS", "Simulation", "WorldParameters"]
