"""A world split for a change run: a *static* scene built once, and small *movers* scenes rebuilt per frame.

Mitsuba 3.9 rebuilds every geometry of a scene (nested shape groups included) when one of its shapes moves, so
a change run that updates the whole world per frame and per background pays for every static triangle twice a
frame. Split, the static scene (every shape no frame moves, every light) is built once and kept with the
:class:`~mincam_sim.render.simulation.Simulation` while none of its parameters changes; the moving shapes are
copied into a small scene, moved to each frame and back to the background, and both passes trace the static
scene with it (:class:`~mincam_sim.render.kernels.split_scene.SplitScene`). The world scene itself stays at the
background through the run.

The split holds where every moving shape is a triangle mesh moved by its vertex positions, emits no light, has no
delta BSDF (a moving mirror moves the images the change regions are bounded with) and every shape has an id of
its own, and where no light reaches from infinity (a directional or environment light is told the whole scene's
bounds). :func:`split_refusal` says why not otherwise; the run then updates the world scene as before.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from mincam_sim.render import backend
from mincam_sim.render.kernels import frozen
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
    lights = [e.id() for e in scene.emitters() if not int(e.flags()) & int(mi.EmitterFlags.Surface)]
    if "" in ids + lights or len(set(ids + lights)) != len(ids + lights):
        return "a shape or light of the scene has no id of its own"
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
    them changes while the split is used), built once.

    The lights keep their order (an emitting shape where ``scene`` has its emitter, a point or spot light between
    them where ``scene`` has it), so an emitter sample picks the same light as in ``scene``."""
    mi = backend.mitsuba()
    moving = set(moving)
    content: dict = {"type": "scene"}
    emitting = iter([shape for shape in scene.shapes() if shape.is_emitter()])
    for emitter in scene.emitters():  # each surface emitter is the next emitting shape's (both in load order)
        item = next(emitting) if int(emitter.flags()) & int(mi.EmitterFlags.Surface) else emitter
        content[item.id()] = item  # keyed by its own id: the loader names an object after its key
    for shape in scene.shapes():
        if shape.id() not in moving and shape.id() not in content:
            content[shape.id()] = shape
    return mi.load_dict(content, optimize=False)


def mesh_copy(mesh):
    """A new Mitsuba mesh with ``mesh``'s id, buffers (copied) and BSDF (shared)."""
    mi = backend.mitsuba()
    import drjit as dr

    props = mi.Properties()
    if mesh.bsdf() is not None:
        props["bsdf"] = mesh.bsdf()
    copy = mi.Mesh(mesh.id(), mesh.vertex_count(), mesh.face_count(), props, mesh.has_vertex_normals(),
                   mesh.has_vertex_texcoords())
    source, target = mi.traverse(mesh), mi.traverse(copy)
    for key in COPIED:
        if key in source:
            target[key] = dr.copy(source[key])  # a buffer of its own, made by Dr.Jit (not mapped from numpy)
    target.update()
    copy.set_id(mesh.id())
    return copy


class StaticSplit:
    """The static scene of a run and its movers scene, traced together as :attr:`scene`.

    Parameters
    ----------
    scene : mitsuba.Scene
        The world scene, with the moving shapes where the background has them.
    moving : iterable of str
        The shapes the frames move (:func:`split_refusal` found none that stops a split).

    One split serves the runs of a :class:`~mincam_sim.render.simulation.Simulation` while no static parameter
    changes (the run that builds it keeps it there). A frame moves the copies to the frame, then back to the
    background: one :class:`~mincam_sim.render.kernels.split_scene.SplitScene` for both passes, so both replay
    the same frozen launches (their buffers keep their addresses), and a rebuild costs a dozen triangles.
    """

    def __init__(self, scene, moving: Iterable[str]) -> None:
        mi = backend.mitsuba()
        names = sorted(set(moving))
        shapes = {shape.id(): shape for shape in scene.shapes()}
        self.static = static_scene(scene, names)
        self.copies = {name: mesh_copy(shapes[name]) for name in names}
        movers = mi.load_dict({"type": "scene", **self.copies}, optimize=False)
        self._params = mi.traverse(movers)
        self.scene = SplitScene(self.static, movers)
        frozen.release_with(self, self.scene)
        self.scene.set_movers_box(*_box_of(self.copies.values()))
        self.view = _ShapesView(self.static, self.copies, movers)
        self.movers_updates = 0  # rebuilds of the movers scene (the static scene is never updated)

    def move(self, updates: Mapping[str, object]) -> None:
        """Move the copies (``updates``: ``name.vertex_positions`` in scene coordinates, as the world scene's
        parameters take them; in place where the buffer allows, as its address keys frozen launches) and rebuild
        the movers scene, nothing else, if one of them changed."""
        mi = backend.mitsuba()
        params = self._params
        changed = False
        for key, value in updates.items():
            if key not in params:
                raise KeyError(f"{key!r} is not a parameter of the moving shapes {sorted(self.copies)}")
            if isinstance(value, np.ndarray) and np.array_equal(np.asarray(params[key]).ravel(),
                                                                np.asarray(value, dtype=np.float32).ravel()):
                continue
            if not _write_in_place(params, key, value):
                params[key] = as_param(mi, params[key], value, key)
            changed = True
        if changed:
            params.update()
            self.movers_updates += 1
            self.scene.set_movers_box(*_box_of(self.copies.values()))


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
