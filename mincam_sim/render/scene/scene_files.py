"""Scenes from files: Mitsuba 3 XML scenes and meshes read by trimesh, with clear errors.

A Mitsuba XML scene is loaded with ``optimize=False`` (every shape keeps its id and its own parameters, never
merged into an anonymous mesh with others that share its material). Meshes in formats Mitsuba cannot read
(glTF / GLB, STL, and OBJ / PLY if asked) are read with trimesh and handed over as in-memory meshes.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from mincam_sim.errors import InputError
from mincam_sim.render import backend
from mincam_sim.render.scene.mincam_scene import as_param

Y_UP_TO_Z_UP = np.array([[1.0, 0, 0, 0], [0, 0, -1.0, 0], [0, 1.0, 0, 0], [0, 0, 0, 1.0]])  # +y -> +z, +z -> -y
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".gltf", ".glb", ".off")


def load_scene_file(path: str | Path):
    """A Mitsuba 3 XML scene file as a loaded ``mi.Scene`` with every shape as built.

    Raises
    ------
    InputError
        The file is missing, not XML, or Mitsuba refuses it (its message, with the line, is kept).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"scene file {path} does not exist; check the path (relative paths are taken from the "
                         "config's folder)")
    if path.suffix.lower() != ".xml":
        raise InputError(f"scene file {path} is not a Mitsuba XML scene (.xml); meshes go in [[world.object]] "
                         "entries")
    mi = backend.mitsuba()
    try:
        return mi.load_file(str(path), optimize=False)
    except Exception as exc:  # Mitsuba raises RuntimeError with the file, line and column in its text
        raise InputError(f"{path}: Mitsuba could not load the scene: {_mitsuba_message(exc)}") from None


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


def turn_scene(scene, matrix: np.ndarray) -> None:
    """Apply a rigid ``matrix`` (4 x 4) to every position-carrying parameter of a loaded scene, in place:
    transforms, vertex positions and normals, point lights' positions."""
    mi = backend.mitsuba()
    params = mi.traverse(scene)
    rot = matrix[:3, :3]
    for key in list(params.keys()):
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
