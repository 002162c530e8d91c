"""What a world scene accepts: elements, loaded scenes and parameter updates, checked at the boundary.

Every check raises :class:`~mincam_sim.errors.InputError` naming the element or parameter and the fix, so a
user's mistake is one clear line and never a silently wrong measurement (a NaN vertex rendered, a vertex array
of another mesh's size accepted, a negative radiance giving negative irradiance, a loaded scene rendering 0).
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from mincam_sim.errors import InputError
from mincam_sim.render import backend

RADIANT_PARTS = ("radiance", "intensity", "irradiance")  # emitter parameters that must be >= 0
# material parameters that must lie in [0, 1]: a surface reflects or transmits at most the light it receives
FRACTION_PARTS = ("reflectance", "diffuse_reflectance", "specular_reflectance", "specular_transmittance")


class WorldWarning(UserWarning):
    """A world input that is taken, but not as it may have been meant (a file's camera ignored, a mincam inside
    a shape, a scene in other units than metres)."""


@dataclass
class LoadedScenes:
    """What the loaded scenes among a world's elements bring beside their shapes: the scene files (for the
    identity), their integrator's ``max_depth`` (with where it came from) and the sensors that are ignored."""

    files: list = field(default_factory=list)  # SceneFile, GltfFile
    max_depth: tuple[int, str] | None = None
    ignored_sensors: list[str] = field(default_factory=list)
    static: set[str] = field(default_factory=set)  # shapes and lights without an id, and shape groups: not movers

    def note(self) -> None:
        """One :class:`WorldWarning` if a loaded scene brought sensors (the mincam is the world's sensor)."""
        if self.ignored_sensors:
            warnings.warn(f"the scene's own sensor(s) ({', '.join(self.ignored_sensors)}) and their films are "
                          "ignored: the mincam measures the world (give camera=... for a ground-truth camera)",
                          WorldWarning, stacklevel=4)


# Mitsuba shapes given as objects that a Simulation took into its scene, by id(): their state as it left them
# (class, id, bounding box [m]) and whether it moved them. A Simulation moves such an object in place into its own
# coordinates (metres, around its mincam); a second Simulation given the same object reads it there, misplaced,
# and moving it again misplaces it in the first. The state tells the object apart from a new one that Python
# placed at a freed object's address.
_TAKEN: dict[int, tuple[tuple, bool]] = {}


def _taken_state(value) -> tuple | None:
    """What marks a Mitsuba shape as a Simulation left it (None for anything else: dicts are loaded anew)."""
    mi = backend.mitsuba()
    if not isinstance(value, mi.Shape):
        return None
    box = value.bbox()
    return (value.class_name(), value.id(), tuple(np.array(box.min, dtype=float).ravel()),
            tuple(np.array(box.max, dtype=float).ravel()))


def refuse_taken(elements: Mapping, moves: bool) -> None:
    """One :class:`~mincam_sim.errors.InputError` for an element that is a Mitsuba shape object an earlier
    :class:`~mincam_sim.render.simulation.Simulation` took (:func:`note_taken`), where it or this one ``moves``
    its shapes (scene coordinates other than the world's, or file units other than metres)."""
    for name, value in elements.items():
        state, moved = _TAKEN.get(id(value), (None, False))
        if state is not None and (moved or moves) and state == _taken_state(value):
            raise InputError(
                f"element {name!r} is a Mitsuba object that an earlier Simulation took into its scene, where it "
                "lies in that simulation's own coordinates (metres, around its mincam): this one would read it "
                "misplaced, or move it under the other; give each Simulation objects of its own (call "
                "ms.mesh_object again, load the scene again) or pass dicts, which every Simulation loads anew")


def note_taken(elements: Mapping, moved: bool) -> None:
    """Remember the Mitsuba shape objects among ``elements`` as a Simulation leaves them, and whether it
    ``moved`` them (:func:`refuse_taken`)."""
    for value in elements.values():
        state = _taken_state(value)
        if state is not None:
            _TAKEN[id(value)] = (state, moved)


def expand_elements(elements) -> tuple[dict, LoadedScenes]:
    """``elements`` (name -> Mitsuba dict, Mitsuba object, a loaded ``mi.Scene``, a
    :class:`~mincam_sim.render.scene.scene_files.SceneFile` or a
    :class:`~mincam_sim.render.scene.gltf_files.GltfFile`, whose nodes come under their own names) as a flat
    dict whose values are dicts or single Mitsuba objects, and what the loaded scenes bring besides.

    A loaded scene contributes its shapes (those without an id as static geometry, named
    ``<element>_shape<i>``), its emitters that are not attached to a shape, under their own ids, and its shape
    groups (``shapegroup``: the shapes its ``instance`` shapes draw, which a scene rebuilt around the mincam
    needs beside them; static: an instance moves by its own ``to_world``); its integrator's ``max_depth`` is
    offered to the caller, its sensors ignored."""
    from mincam_sim.render.scene.gltf_files import GltfFile
    from mincam_sim.render.scene.scene_files import SceneFile, file_max_depth

    if not isinstance(elements, Mapping):
        raise InputError(f"elements must be a dict name -> Mitsuba dict or object, got {type(elements).__name__}")
    mi = backend.mitsuba()
    out: dict = {}
    loaded = LoadedScenes()
    objects: dict[int, str] = {}  # id of each Mitsuba object given -> its element name

    def add(name, value, origin: str) -> None:
        if name in out:
            raise InputError(f"element name {name!r} ({origin}) is used twice; rename one of them")
        if isinstance(value, mi.Object):  # one object is one shape in Mitsuba: a second name would be dropped
            if id(value) in objects:
                raise InputError(f"elements {objects[id(value)]!r} and {name!r} are the same Mitsuba object (one "
                                 "shape, which the scene would hold once, under one name); make a second object "
                                 "(e.g. call ms.mesh_object again) for a second shape")
            objects[id(value)] = name
        out[name] = value

    for name, value in elements.items():
        if not isinstance(name, str) or not name or "." in name:
            raise InputError(f"element name {name!r} must be a non-empty string without '.' (parameters are "
                             "addressed as 'name.parameter'); rename it")
        if isinstance(value, GltfFile):
            loaded.files.append(value)
            nodes, note = value.elements()
            for node, mesh in nodes.items():
                add(node, mesh, f"a node of {value.path.name}")
            if note:
                warnings.warn(note, WorldWarning, stacklevel=3)
            continue
        if isinstance(value, SceneFile):
            loaded.files.append(value)
            value = value.load()
            where = f"the <integrator> of {loaded.files[-1].path.name}"
        else:
            where = f"the integrator of the loaded scene {name!r}"
        if isinstance(value, mi.Scene):
            for item_name, item, named in _scene_items(mi, value, name):
                add(item_name, item, f"from the loaded scene {name!r}")
                if not named:
                    loaded.static.add(item_name)
            depth = file_max_depth(value)
            if depth is not None and loaded.max_depth is None:
                loaded.max_depth = (depth, where)
            loaded.ignored_sensors += [s.id() or "<sensor>" for s in value.sensors()]
            continue
        if isinstance(value, Mapping):
            kind = value.get("type")
            if not isinstance(kind, str) or not kind:
                raise InputError(f"element {name!r} has no plugin 'type' (e.g. 'obj', 'rectangle', 'area'); "
                                 "give one")
            if kind == "shapegroup":
                loaded.static.add(name)  # its shapes are drawn by instances: an instance moves, never the group
            if kind == "scene":
                raise InputError(f"element {name!r} is a whole scene dict; pass its shapes and emitters as "
                                 "elements, or load it with mi.load_dict(..., optimize=False) and pass the scene")
        elif not isinstance(value, mi.Object):
            raise InputError(f"element {name!r} is a {type(value).__name__}, not a Mitsuba dict or object")
        add(name, value, "given")
    return out, loaded


def _scene_items(mi, scene, element: str) -> list[tuple[str, object, bool]]:
    """(name, object, whether it can move) of a loaded scene's shape groups, shapes and its emitters that are no
    shape's: by their id, those without one (static geometry: nothing addresses them) as ``<element>_shape<i>``
    / ``<element>_light<i>``; shape groups (by their id, never movers) first."""
    shapes = list(scene.shapes())
    lights = [e for e in scene.emitters() if not int(e.flags()) & int(mi.EmitterFlags.Surface)]
    if not shapes and not lights:
        raise InputError("a loaded scene passed as an element holds no shapes and no emitters")
    generated = re.compile(rf"{re.escape(element)}_(shape|light)\d+")  # named by an earlier load of this scene
    items = [(s.id() or f"{element}_shape{i}", s) for i, s in enumerate(shapes)]
    items += [(e.id() or f"{element}_light{i}", e) for i, e in enumerate(lights)]
    movable = [(name, item, bool(item.id()) and not generated.fullmatch(item.id())) for name, item in items]
    from mincam_sim.render.scene.scene_files import shape_groups

    return [(group.id(), group, False) for group in shape_groups(mi, scene)] + movable


def check_radiant_params(params, keys: Sequence[str] | None = None) -> None:
    """Refuse a negative or non-finite emitter radiance / intensity / irradiance among ``keys`` (default:
    every parameter)."""
    for key in params.keys() if keys is None else keys:
        parts = key.split(".")
        if not any(p in RADIANT_PARTS for p in parts[1:]) or parts[-1] not in ("value", *RADIANT_PARTS):
            continue
        value = params[key]
        try:
            arr = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            continue  # a texture or bitmap: its values are checked where they are made
        if arr.size and not (np.all(np.isfinite(arr)) and np.all(arr >= 0)):
            raise InputError(f"{key} = {arr.ravel()[:4].tolist()} must be finite and >= 0 (a light cannot emit "
                             "negative power); fix the emitter's value")


def _is_fraction_key(key: str) -> bool:
    parts = key.split(".")
    return parts[-1] == "value" and any(p in FRACTION_PARTS for p in parts[1:-1])


def check_built_params(params) -> None:
    """Refuse values a world is built with that would give silently wrong numbers: a negative or non-finite
    light (:func:`check_radiant_params`), a reflectance or transmittance outside [0, 1] (negative irradiance, or
    more light out of a surface than onto it), a mesh with NaN or infinite vertices, a non-finite placement."""
    check_radiant_params(params)
    for key in params.keys():
        checked = _is_fraction_key(key) or key.endswith((".vertex_positions", ".to_world"))
        if not checked:
            continue
        try:
            arr = np.asarray(params[key], dtype=np.float64)
        except (TypeError, ValueError):
            continue  # a texture or bitmap: its values are checked where they are made
        if not np.all(np.isfinite(arr)):
            raise InputError(f"{key} holds NaN or infinite values: the {key.split('.', 1)[0]!r} element was built "
                             "with them; give finite numbers")
        if _is_fraction_key(key) and arr.size and not (arr.min() >= 0 and arr.max() <= 1):
            raise InputError(f"{key} = {arr.ravel()[:4].tolist()} must lie in [0, 1] (a surface reflects or "
                             "transmits at most the light it receives); fix the material's value")


def check_update(key: str, current, value) -> None:
    """Refuse an update whose size does not match the parameter it replaces, or that is not finite."""
    if not isinstance(value, np.ndarray):
        try:
            value = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            if isinstance(value, str | bytes | list | tuple | Mapping):
                raise InputError(f"{key}: the update must be numbers, got {type(value).__name__} "
                                 f"{value!r:.60}") from None
            return  # a Mitsuba object of another kind: Mitsuba checks its type
    if value.dtype.kind not in "biuf":
        raise InputError(f"{key}: the update must be numeric, got an array of {value.dtype}")
    if not np.all(np.isfinite(value)):
        raise InputError(f"{key}: the update holds NaN or infinite values; give finite numbers")
    if key.endswith(".to_world"):
        if value.shape != (4, 4):
            raise InputError(f"{key}: a transform must be a 4 x 4 matrix, got shape {value.shape}")
        scales = np.linalg.svd(value[:3, :3], compute_uv=False)
        if scales.max() == 0 or scales.min() <= 1e-7 * scales.max():
            raise InputError(f"{key}: the transform is singular (zero scale along some axis: scales "
                             f"{np.round(scales, 9).tolist()}); fix the matrix")
        if not np.allclose(value[3], (0.0, 0.0, 0.0, 1.0), rtol=0.0, atol=1e-9):
            raise InputError(f"{key}: the last row of a transform must be [0, 0, 0, 1] (an affine map; a projective "
                             f"row is not applied to shapes), got {value[3].tolist()}; fix the matrix")
        return
    if key.endswith(".vertex_positions"):
        import drjit as dr

        expected = int(dr.width(current))  # a flat Float: no copy of the mesh per update
        if value.size != expected:
            raise InputError(f"{key}: the mesh has {expected // 3} vertices ({expected} values), the update has "
                             f"{value.size} values; an update moves the vertices of the same mesh (same count and "
                             "order)")
    if key.endswith(".value"):  # a spectrum's value (one number in the mono variants Mitsuba runs here)
        import drjit as dr

        held = int(dr.width(current)) if dr.is_array_v(current) else np.asarray(current).size
        if value.size != held:
            raise InputError(f"{key}: the parameter holds {held} value{'s' if held != 1 else ''}, the update has "
                             f"{value.size}; give {'one number' if held == 1 else f'{held} numbers'}")
    if key.split(".")[-1] in ("value", *RADIANT_PARTS) and any(p in RADIANT_PARTS for p in key.split(".")[1:]):
        if np.any(value < 0):
            raise InputError(f"{key}: a light cannot emit negative power; give values >= 0")
    if _is_fraction_key(key) and not (value.min() >= 0 and value.max() <= 1):
        raise InputError(f"{key}: a reflectance or transmittance must lie in [0, 1] (a surface reflects or "
                         f"transmits at most the light it receives), got {value.ravel()[:4].tolist()}")


def check_frames(frames, background) -> None:
    """Frames must be a sequence of parameter dicts and the background one dict."""
    if isinstance(frames, (Mapping, str, bytes)) or not isinstance(frames, Sequence):
        raise InputError(f"frames must be a list of parameter-update dicts (one per frame), got "
                         f"{type(frames).__name__}; wrap a single frame as [update]")
    for i, frame in enumerate(frames):
        if not isinstance(frame, Mapping):
            raise InputError(f"frames[{i}] must be a dict 'name.parameter' -> value, got {type(frame).__name__}")
        check_update_keys(frame, f"frames[{i}]")
    if not isinstance(background, Mapping):
        raise InputError(f"background must be a dict 'name.parameter' -> value ({{}} = the scene as built), got "
                         f"{type(background).__name__}")
    check_update_keys(background, "background")


def check_update_keys(updates: Mapping, where: str) -> None:
    """Refuse a key of ``updates`` that is not a ``"name.parameter"`` string (``where`` names the dict)."""
    for key in updates:
        if not isinstance(key, str):
            raise InputError(f"{where}: a key must be a 'name.parameter' string (e.g. 'box.to_world'), got {key!r} "
                             f"({type(key).__name__})")
