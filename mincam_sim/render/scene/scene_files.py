"""Scenes from files: Mitsuba 3 XML scenes and meshes read by trimesh, with clear errors.

A Mitsuba XML scene is loaded with ``optimize=False`` (every shape keeps its id and its own parameters, never
merged into an anonymous mesh with others that share its material), its ``<default>`` values set by the caller's
``parameters`` through Mitsuba's own loader (:class:`SceneFile`). Its ``<integrator>``'s ``max_depth`` is read
back (:func:`file_max_depth`); its sensors are the mincam's business; its shape groups (:func:`shape_groups`)
travel with the instances that draw them and are never placed twice. Meshes in formats Mitsuba cannot read
(glTF / GLB, STL, and OBJ / PLY if asked) are read with trimesh and handed over as in-memory meshes (a glTF file
with its materials and nodes: :mod:`.gltf_files`).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mincam_sim.errors import InputError, is_finite_real
from mincam_sim.render import backend
from mincam_sim.render.scene.mincam_scene import as_param

Y_UP_TO_Z_UP = np.array([[1.0, 0, 0, 0], [0, 0, -1.0, 0], [0, 1.0, 0, 0], [0, 0, 0, 1.0]])  # +y -> +z, +z -> -y
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".gltf", ".glb", ".off")


@dataclass(frozen=True)
class SceneFile:
    """A Mitsuba 3 XML scene file as a world element: its path, the values of its ``<default>`` parameters
    (``name -> value`` as the XML writes them, e.g. ``{"lamp": "0, 0, 0"}``) and the axis it was authored with
    up (``"y"``: turned so that its +y is the world +z)."""

    path: Path
    parameters: Mapping[str, str] = field(default_factory=dict)
    up: str = "z"
    unit_m: float = 1.0  # the length of the file's unit [m] (0.01: modelled in cm)

    def __post_init__(self) -> None:
        object.__setattr__(self, "path", Path(self.path))
        object.__setattr__(self, "parameters", check_parameters(self.parameters))
        if self.up not in ("z", "y"):
            raise InputError(f"up must be 'z' or 'y' (the axis the scene file was authored with up), got {self.up!r}")
        if isinstance(self.unit_m, bool) or not isinstance(self.unit_m, (int, float)) or not (
                np.isfinite(self.unit_m) and self.unit_m > 0):
            raise InputError(f"unit_m must be the length of the file's unit in metres (0.01 for cm), a positive "
                             f"number; got {self.unit_m!r}")

    def load(self):
        """The loaded ``mi.Scene``, z-up and in metres."""
        scene = load_scene_file(self.path, self.parameters)
        if self.up == "y":
            turn_scene(scene, Y_UP_TO_Z_UP)
        if self.unit_m != 1.0:
            scale_scene(scene, float(self.unit_m))
        return scene


def check_parameters(parameters) -> dict[str, str]:
    """``parameters`` as ``name -> str`` (numbers and booleans written as the XML would), or one
    :class:`InputError` naming the bad entry."""
    if parameters is None:
        return {}
    if not isinstance(parameters, Mapping):
        raise InputError(f"parameters must be a dict name -> value (the scene file's <default> names), got "
                         f"{type(parameters).__name__}")
    out = {}
    for name, value in parameters.items():
        if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z_]\w*", name):
            raise InputError(f"parameters: {name!r} is not a parameter name (letters, digits, '_'; the name of a "
                             "<default> without '$')")
        if isinstance(value, (bool, np.bool_)):
            value = "true" if value else "false"
        elif is_finite_real(value):
            value = repr(value.item() if isinstance(value, np.generic) else value)
        elif isinstance(value, (list, tuple, np.ndarray)) and len(value) and all(is_finite_real(v) for v in value):
            value = ", ".join(repr(v.item() if isinstance(v, np.generic) else v) for v in value)
        elif isinstance(value, Path):
            value = str(value)
        if not isinstance(value, str):
            raise InputError(f"parameters[{name!r}] = {value!r}: give the value as the XML would write it (a string "
                             "such as '0, 0, 0', a finite number, a boolean or a list of numbers)")
        out[name] = value
    return out


def declared_parameters(path: Path) -> set[str]:
    """Names a scene file (and the files it ``<include>``s) declares as ``<default>`` or uses as ``$name``."""
    from mincam_sim.storage.identity import scene_file_digests

    names: set[str] = set()
    for file in scene_file_digests(path):
        if file.lower().endswith(".xml") and Path(file).is_file():
            text = Path(file).read_text(errors="replace")
            names |= set(re.findall(r"<default\b[^>]*\bname=\"(\w+)\"", text))
            names |= set(re.findall(r"\$(\w+)", text))
    return names


def load_scene_file(path: str | Path, parameters: Mapping[str, str] | None = None):
    """A Mitsuba 3 XML scene file as a loaded ``mi.Scene`` with every shape as built, its ``<default>`` values
    replaced by ``parameters`` (``name -> value`` as the XML writes them).

    Raises
    ------
    InputError
        The file is missing, not XML, a parameter is not one of the file's, or Mitsuba refuses it (its message,
        with the line, is kept).
    """
    path = Path(path)
    parameters = check_parameters(parameters)
    if not path.is_file():
        raise InputError(f"scene file {path} does not exist; check the path (relative paths are taken from the "
                         "config's folder)")
    if path.suffix.lower() in (".gltf", ".glb"):
        raise InputError(f"scene file {path} is glTF, which has no <default> parameters: give world={path.name!r} "
                         "without parameters (or a GltfFile element)")
    if path.suffix.lower() != ".xml":
        raise InputError(f"scene file {path} is not a Mitsuba XML scene (.xml) nor glTF (.gltf, .glb); meshes go in "
                         "[[world.object]] entries")
    unknown = sorted(set(parameters) - declared_parameters(path))
    if unknown:
        known = sorted(declared_parameters(path))
        raise InputError(f"parameters {unknown} are not parameters of {path.name} (its <default> / $names: "
                         f"{', '.join(known) or 'none'}); fix the name")
    mi = backend.mitsuba()
    try:
        return mi.load_file(str(path), optimize=False, **parameters)
    except Exception as exc:  # Mitsuba raises RuntimeError with the file, line and column in its text
        raise InputError(f"{path}: Mitsuba could not load the scene: {_mitsuba_message(exc)}") from None


def file_max_depth(scene) -> int | None:
    """The ``max_depth`` of a loaded scene's own ``<integrator>`` (None if it declares none or the integrator
    has no such setting); ``-1`` means unbounded."""
    integrator = scene.integrator()
    if integrator is None:
        return None
    found = re.search(r"max_depth\s*=\s*(-?\d+)", str(integrator))
    return int(found.group(1)) if found else None


def _mitsuba_message(exc: Exception) -> str:
    text = " ".join(str(exc).split())
    text = re.sub(r"^\[[^\]]*\]\s*", "", text)  # Mitsuba's "[xml.cpp:...]" source prefix
    return text[:600]


def read_mesh(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (n, 3) [file units], faces (m, 3)) of a mesh file read by trimesh (scenes are merged into one
    mesh in their own frame)."""
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise InputError(f"mesh file {path} does not exist; check the path (relative to the config's folder)")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise InputError(f"mesh file {path}: unknown format {path.suffix!r}; use one of {', '.join(MESH_SUFFIXES)}")
    try:
        loaded = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many kinds for a bad file
        raise InputError(f"mesh file {path} could not be read by trimesh: {' '.join(str(exc).split())[:300]}") \
            from None
    vertices = np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))), dtype=np.float64)
    faces = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))), dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1:] != (3,) or len(vertices) == 0 or faces.ndim != 2 or len(faces) == 0:
        raise InputError(f"mesh file {path} holds no triangles; export it as a triangle mesh")
    if not np.all(np.isfinite(vertices)):
        raise InputError(f"mesh file {path} has NaN or infinite vertex coordinates")
    return vertices, faces


def in_metres(key: str, value, unit_m: float, shape_ids: set[str]):
    """A position parameter in file units (a Mitsuba value or numpy; ``to_world`` 4 x 4) scaled to metres, as
    float64 numpy (unchanged for ``unit_m = 1``): a shape's
    ``to_world`` scaled as a whole (its size with it), a light's only in its translation (its transform orients
    it), vertex positions and positions multiplied."""
    if unit_m == 1.0:
        return value
    if key.endswith(".to_world"):
        matrix = np.array(getattr(value, "matrix", value), dtype=np.float64).reshape(4, 4).copy()
        if key.split(".", 1)[0] in shape_ids:
            matrix[:3, :] *= unit_m
        else:
            matrix[:3, 3] *= unit_m
        return matrix
    return np.asarray(value, dtype=np.float64) * unit_m


def scale_scene(scene, unit_m: float) -> None:
    """Scale a loaded scene modelled in units of ``unit_m`` [m] to metres, in place (:func:`in_metres` on every
    position-carrying parameter; environment and directional lights keep their orientation)."""
    mi = backend.mitsuba()
    params = mi.traverse(scene)
    shape_ids = {s.id() for s in scene.shapes()}
    directional = {e.id() for e in scene.emitters() if e.is_environment() or
                   int(e.flags()) & int(mi.EmitterFlags.Infinite)}
    for key in _placement_keys(mi, scene, params, ("to_world", "vertex_positions", "position")):
        name, _, rest = key.rpartition(".")
        if name not in directional and (
                rest != "to_world" or "Transform4" in type(params[key]).__name__):
            params[key] = as_param(mi, params[key], in_metres(key, params[key], unit_m, shape_ids), key)
    params.update()


def _placement_keys(mi, scene, params, parts: tuple[str, ...]) -> list[str]:
    """The parameters ``<name>.<part>`` that place an element as a whole, not the shapes inside a shape group
    (``group.shape.to_world``): the instances that draw a group are placed by their own ``to_world``, and moving
    both would move them twice."""
    groups = tuple(f"{group.id()}." for group in shape_groups(mi, scene))
    return [key for key in params.keys() if key.rpartition(".")[2] in parts and not key.startswith(groups)]


def shape_groups(mi, scene) -> list:
    """The ``shapegroup`` shapes of a loaded scene (``scene.shapes()`` leaves them out: only the ``instance``
    shapes that draw them are listed)."""
    return [obj for obj, (parent, _) in mi.traverse(scene).hierarchy.items()
            if parent is scene and isinstance(obj, mi.Shape) and obj.class_name() == "ShapeGroupPlugin"]



def turn_scene(scene, matrix: np.ndarray) -> None:
    """Apply a rigid ``matrix`` (4 x 4) to every position-carrying parameter of a loaded scene, in place:
    transforms, vertex positions and normals, point lights' positions."""
    mi = backend.mitsuba()
    params = mi.traverse(scene)
    rot = matrix[:3, :3]
    for key in _placement_keys(mi, scene, params, ("to_world", "vertex_positions", "vertex_normals", "position")):
        rest = key.rpartition(".")[2]
        value = params[key]
        if rest == "to_world" and "Transform4" in type(value).__name__:
            turned = matrix @ np.array(value.matrix, dtype=np.float64).reshape(4, 4)
        elif rest in ("vertex_positions", "vertex_normals", "position"):
            turned = np.array(value, dtype=np.float64).reshape(-1, 3) @ rot.T
            if rest != "vertex_normals":
                turned = turned + matrix[:3, 3]
            turned = turned.ravel()
        else:
            continue
        params[key] = as_param(mi, value, turned, key)
    params.update()
