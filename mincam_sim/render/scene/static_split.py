"""A world split for a change run: a *static* scene built once, and small *movers* scenes rebuilt per frame.

Mitsuba 3.9 rebuilds every geometry of a scene (nested shape groups included) when one of its shapes moves, so
a change run that updates the whole world per frame and per background pays for every static triangle twice a
frame. Split, the static scene (every shape no frame moves, every light) is built once and kept with the
:class:`~mincam_sim.render.simulation.Simulation` while none of its parameters changes; the moving shapes are
copied into two small scenes, one held where the background has them and one updated to each frame, and a pass
traces the static scene with one of them (:class:`~mincam_sim.render.kernels.split_scene.SplitScene`). The world
scene itself stays at the background through the run.

The split holds where every moving shape is a triangle mesh moved by its vertex positions, emits no light, has no
delta BSDF (a moving mirror moves the images the change regions are bounded with) and every shape has an id of
its own, and where no light reaches from infinity (a directional or environment light is told the whole scene's
bounds). :func:`split_refusal` says why not otherwise; the run then updates the world scene as before.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from mincam_sim.render import backend
from mincam_sim.render.kernels.change_geometry import watch_box
from mincam_sim.render.kernels.split_scene import SplitScene
from mincam_sim.render.scene.mincam_scene import _write_in_place, as_param

SPLIT_PARAMETERS = ("vertex_positions",)  # what a frame may set on a moving shape for the run to be split
COPIED = ("faces", "vertex_positions", "vertex_normals", "vertex_texcoords")  # a mover's copy: its mesh buffers
MESH_KEYS = {*COPIED, "silhouette_sampling_weight"}  # a mesh's own parameters (besides its BSDF's)


def split_refusal(scene, moving: Iterable[str], updates: Iterable[Mapping[str, object]]) -> str:
    """Why a change run over the world ``scene`` that moves the shapes ``moving`` with ``updates`` (the frames
    and the background) cannot be split into static and movers scenes; ``""`` if it can."""
    mi = backend.mitsuba()
    moving = set(moving)
    if not moving:
        return "nothing moves"
    ids = [shape.id() for shape in scene.shapes()]
    if "" in ids or len(set(ids)) != len(ids):
        return "a shape of the scene has no id of its own"
    for emitter in scene.emitters():
        if int(emitter.flags()) & int(mi.EmitterFlags.Infinite):
            return f"the light '{emitter.id()}' reaches from infinity (it is told the whole scene's bounds)"
    shapes = dict(zip(ids, scene.shapes(), strict=True))
    for shape in shapes.values():
        emitter = shape.emitter()
        if emitter is not None and int(emitter.flags()) & int(mi.EmitterFlags.SpatiallyVarying):
            # such a mesh keeps a pointer to the last scene built with it (for its UV parameterisation)
            return f"'{shape.id()}' emits a textured radiance"
    for name in sorted(moving):
        why = _mover_refusal(mi, name, shapes.get(name))
        if why:
            return why
    for update in updates:
        for key in update:
            if key.split(".", 1)[-1] not in SPLIT_PARAMETERS:
                return f"a frame sets '{key}' (only the vertex positions of moving meshes are split)"
    return ""


def _mover_refusal(mi, name: str, shape) -> str:
    if shape is None:
        return f"'{name}' is not a shape"
    if not isinstance(shape, mi.Mesh):
        return f"'{name}' is not a triangle mesh"
    if shape.is_emitter() or shape.is_sensor():
        return f"'{name}' emits light or measures it"
    bsdf = shape.bsdf()
    if bsdf is not None and int(bsdf.flags()) & int(mi.BSDFFlags.Delta):
        return f"'{name}' is a mirror or glass"
    extra = [key for key in mi.traverse(shape).keys() if key not in MESH_KEYS and not key.startswith("bsdf.")]
    if extra:
        return f"'{name}' has parameters a copy would not carry ({', '.join(sorted(extra))})"
    return ""


def static_scene(scene, moving: Iterable[str]):
    """A Mitsuba scene of ``scene``'s shapes but ``moving`` and of its lights (the same objects, shared: none of
    them changes while the split is used), built once."""
    mi = backend.mitsuba()
    moving = set(moving)
    content: dict = {"type": "scene"}
    for shape in scene.shapes():
        if shape.id() not in moving:
            content[shape.id()] = shape  # keyed by its own id: the loader names an object after its key
    for emitter in scene.emitters():
        if not int(emitter.flags()) & int(mi.EmitterFlags.Surface):
            content[emitter.id()] = emitter
    return mi.load_dict(content, optimize=False)


def mesh_copy(mesh):
    """A new Mitsuba mesh with ``mesh``'s id, buffers (copied) and BSDF (shared)."""
    mi = backend.mitsuba()
    props = mi.Properties()
    if mesh.bsdf() is not None:
        props["bsdf"] = mesh.bsdf()
    copy = mi.Mesh(mesh.id(), mesh.vertex_count(), mesh.face_count(), props, mesh.has_vertex_normals(),
                   mesh.has_vertex_texcoords())
    source, target = mi.traverse(mesh), mi.traverse(copy)
    for key in COPIED:
        if key in source:
            target[key] = type(source[key])(np.array(source[key]))
    target.update()
    copy.set_id(mesh.id())
    return copy


class StaticSplit:
    """The static scene of a run and its two movers scenes (the background's, the current frame's).

    Parameters
    ----------
    scene : mitsuba.Scene
        The world scene, with the moving shapes where the background has them.
    moving : iterable of str
        The shapes the frames move (:func:`split_refusal` found none that stops a split).

    One split serves the runs of a :class:`~mincam_sim.render.simulation.Simulation` while no static parameter
    changes (the run that builds it keeps it there): its scenes keep their frozen launches' recordings.
    """

    def __init__(self, scene, moving: Iterable[str]) -> None:
        mi = backend.mitsuba()
        names = sorted(set(moving))
        shapes = {shape.id(): shape for shape in scene.shapes()}
        self.static = static_scene(scene, names)
        self.frame_copies = {name: mesh_copy(shapes[name]) for name in names}
        self.background_copies = {name: mesh_copy(shapes[name]) for name in names}
        frame_movers = mi.load_dict({"type": "scene", **self.frame_copies}, optimize=False)
        background_movers = mi.load_dict({"type": "scene", **self.background_copies}, optimize=False)
        self._frame_params = mi.traverse(frame_movers)
        self._background_params = mi.traverse(background_movers)
        self.frame_scene = SplitScene(self.static, frame_movers)
        self.background_scene = SplitScene(self.static, background_movers)
        self.view = _ShapesView(self.static, self.frame_copies, frame_movers)
        self.background_scene.set_movers_box(*_box_of(self.background_copies.values()))
        self.frame_scene.set_movers_box(*_box_of(self.frame_copies.values()))
        self.movers_updates = 0  # rebuilds of the frame's movers scene (the static scene is never updated)

    def set_frame(self, updates: Mapping[str, object]) -> None:
        """Move the frame's copies (``updates``: ``name.vertex_positions`` in scene coordinates, as the world
        scene's parameters take them) and rebuild the frame's movers scene, nothing else."""
        if self._move(self._frame_params, self.frame_scene, self.frame_copies, updates):
            self.movers_updates += 1

    def set_background(self, updates: Mapping[str, object]) -> None:
        """Move the background's copies (as :meth:`set_frame`): a new run over the same shapes."""
        self._move(self._background_params, self.background_scene, self.background_copies, updates)

    @staticmethod
    def _move(params, scene: SplitScene, copies: Mapping[str, object], updates: Mapping[str, object]) -> bool:
        """Write ``updates`` into ``params`` (in place where the buffer allows: its address keys frozen
        launches), rebuild ``scene``'s movers if one changed (True) and hold them in its box."""
        mi = backend.mitsuba()
        changed = False
        for key, value in updates.items():
            if key not in params:
                raise KeyError(f"{key!r} is not a parameter of the moving shapes {sorted(copies)}")
            if isinstance(value, np.ndarray) and np.array_equal(np.asarray(params[key]).ravel(),
                                                                np.asarray(value, dtype=np.float32).ravel()):
                continue
            if not _write_in_place(params, key, value):
                params[key] = as_param(mi, params[key], value, key)
            changed = True
        if changed:
            params.update()
            scene.set_movers_box(*_box_of(copies.values()))
        return changed

    def copies(self) -> list:
        """The moving shapes' copies (frame's, then background's): what a frozen launch's key reads."""
        return [*self.frame_copies.values(), *self.background_copies.values()]


def _box_of(shapes) -> tuple[np.ndarray, np.ndarray]:
    """A box (lo, hi) [m] holding ``shapes``, grown by a margin past Mitsuba's ray offsets (as the change
    geometry's watch boxes)."""
    boxes = [watch_box(shape) for shape in shapes]
    return np.min([lo for lo, _ in boxes], axis=0), np.max([hi for _, hi in boxes], axis=0)


class _ShapesView:
    """The world as the frame has it, as the change geometry reads a scene: shapes (the static ones and the
    frame's copies), emitters and bounding box."""

    def __init__(self, static, copies: Mapping[str, object], movers) -> None:
        self._static, self._copies, self._movers = static, copies, movers

    def shapes(self) -> list:
        return [*self._static.shapes(), *self._copies.values()]

    def emitters(self) -> list:
        return list(self._static.emitters())

    def bbox(self):
        return SplitScene(self._static, self._movers).bbox()


__all__ = ["SPLIT_PARAMETERS", "StaticSplit", "mesh_copy", "split_refusal", "static_scene"]
