"""glTF 2.0 / GLB files with their materials, read by trimesh: one mesh per node, named by the node.

Each node that holds a mesh becomes an in-memory ``mi.Mesh`` in world coordinates (the node's transform, the file
turned z-up and scaled to metres), so that a mover may be a node (by its ``vertex_positions``, as every mesh).
Its material (glTF's metallic-roughness PBR) is taken as far as a diffuse world needs:

* ``baseColorFactor`` x ``baseColorTexture`` -> a diffuse reflectance (the texture's sRGB decoded to linear,
  the product taken to luminance: the world variants are monochrome); ``doubleSided`` -> a two-sided BSDF;
* ``emissiveFactor`` -> an area light of radiance ``emission_w_m2_sr`` x its luminance (glTF's emission has no
  physical unit: ``emission_w_m2_sr`` says what a white emissive factor of 1 is);
* everything else (metallic, roughness, normal, occlusion and emissive maps, alpha, cameras, lights, animation)
  is left out, and :meth:`GltfFile.elements` says what (the world then says it in one
  :class:`~mincam_sim.render.scene.world_input.WorldWarning`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mincam_sim.errors import InputError
from mincam_sim.render import backend

GLTF_SUFFIXES = (".gltf", ".glb")
LUMINANCE = np.array([0.212671, 0.715160, 0.072169])  # linear Rec. 709 RGB -> Y (Mitsuba's own weights)
DEFAULT_ALBEDO = 0.8  # a node without a material: grey, as a [[world.object]]
Y_UP_TO_Z_UP = np.array([[1.0, 0, 0, 0], [0, 0, -1.0, 0], [0, 1.0, 0, 0], [0, 0, 0, 1.0]])  # +y -> +z, +z -> -y


@dataclass(frozen=True)
class GltfFile:
    """A glTF / GLB file as a world element: its nodes as meshes with their materials.

    Parameters
    ----------
    path : path
        The ``.gltf`` or ``.glb`` file.
    up : {"y", "z"}
        The axis the file has up: glTF's own convention is ``"y"`` (turned so that its +y is the world +z).
    unit_m : float
        The length of the file's unit [m] (glTF's own is the metre).
    emission_w_m2_sr : float
        The radiance [W m^-2 sr^-1] of an emissive factor (1, 1, 1).
    """

    path: Path
    up: str = "y"
    unit_m: float = 1.0
    emission_w_m2_sr: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "path", Path(self.path))
        if self.up not in ("y", "z"):
            raise InputError(f"GltfFile up must be 'y' (glTF's own convention) or 'z', got {self.up!r}")
        for name in ("unit_m", "emission_w_m2_sr"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or (
                    value < 0 or (value == 0 and name == "unit_m")):
                what = "positive" if name == "unit_m" else ">= 0"
                raise InputError(f"GltfFile {name} must be a finite number {what}, got {value!r}")

    @property
    def parameters(self) -> dict:
        """A glTF file has no ``<default>`` parameters (the identity reads this as a scene file's)."""
        return {}

    def to_metres(self) -> np.ndarray:
        """4 x 4: file coordinates -> world metres (turned z-up, scaled)."""
        turn = Y_UP_TO_Z_UP if self.up == "y" else np.eye(4)
        return np.diag([self.unit_m] * 3 + [1.0]) @ turn

    def elements(self) -> tuple[dict, str | None]:
        """(node name -> ``mi.Mesh`` (world coordinates [m]) of every node that holds a mesh, one line saying
        which parts of the materials were left out, or None).

        Raises
        ------
        InputError
            The file is missing, not glTF, unreadable, holds no mesh, or two node names clash once made valid
            element names.
        """
        scene = read_gltf(self.path)
        base = self.to_metres()
        out: dict = {}
        dropped: set[str] = set()
        for node, name in node_names(scene, self.path).items():
            transform, geometry_name = scene.graph[node]
            geometry = scene.geometry[geometry_name]
            if not _has_triangles(geometry):
                dropped.add(f"node {node!r} ({type(geometry).__name__}, no triangles)")
                continue
            out[name] = node_mesh(name, geometry, base @ np.asarray(transform, dtype=np.float64),
                                  self.emission_w_m2_sr, dropped)
        if not out:
            raise InputError(f"glTF file {self.path} holds no triangle mesh; export the objects as meshes")
        note = None
        if dropped:
            note = (f"{self.path.name}: {', '.join(sorted(dropped))} left out (a world takes a glTF material's base "
                    "colour, its texture, double-sidedness and emissive factor)")
        return out, note


def read_gltf(path: Path):
    """The file as a ``trimesh.Scene``, or one :class:`InputError`."""
    import trimesh

    if not path.is_file():
        raise InputError(f"glTF file {path} does not exist; check the path")
    if path.suffix.lower() not in GLTF_SUFFIXES:
        raise InputError(f"{path} is not a glTF file ({' or '.join(GLTF_SUFFIXES)}); an XML scene is a "
                         "SceneFile, a bare mesh a [[world.object]]")
    try:
        scene = trimesh.load(path, force="scene", process=False)
    except Exception as exc:  # trimesh raises many kinds for a bad file
        raise InputError(f"glTF file {path} could not be read by trimesh: {' '.join(str(exc).split())[:300]}") \
            from None
    if not scene.graph.nodes_geometry:
        raise InputError(f"glTF file {path} holds no mesh node; export the objects as meshes")
    return scene


def node_names(scene, path: Path) -> dict[str, str]:
    """Node -> element name: the node's name with every character but letters, digits, '_' and '-' made '_'
    (Blender's ``Cube.001`` is ``Cube_001``: parameters are addressed as ``name.parameter``)."""
    out: dict[str, str] = {}
    for node in sorted(scene.graph.nodes_geometry):
        name = re.sub(r"[^A-Za-z0-9_-]", "_", str(node)) or "node"
        if name in out.values():
            clash = [k for k, v in out.items() if v == name]
            raise InputError(f"{path.name}: nodes {clash[0]!r} and {node!r} are both named {name!r} here (letters, "
                             "digits, '_' and '-' are kept); rename one of them in the file")
        out[node] = name
    return out


def node_mesh(name: str, geometry, matrix: np.ndarray, emission_w_m2_sr: float, dropped: set[str]):
    """One node's triangles placed by ``matrix`` (file -> world [m]) as an ``mi.Mesh`` with its material."""
    vertices = np.asarray(geometry.vertices, dtype=np.float64)
    faces = np.asarray(geometry.faces, dtype=np.int64)
    if np.linalg.det(matrix[:3, :3]) < 0:  # a mirroring transform: keep the faces' front side where it was
        faces = faces[:, ::-1]
    placed = vertices @ matrix[:3, :3].T + matrix[:3, 3]
    if not np.all(np.isfinite(placed)):
        raise InputError(f"glTF node {name!r} has NaN or infinite vertex coordinates")
    if getattr(geometry.visual, "kind", None) in ("vertex", "face"):
        dropped.add("vertex and face colours")
    material = getattr(geometry.visual, "material", None)
    uv = getattr(geometry.visual, "uv", None)
    bsdf, texture = material_bsdf(name, material, uv is not None, dropped)
    emitter = material_emitter(material, emission_w_m2_sr)
    return build_mesh(name, placed, faces, uv if texture else None, bsdf, emitter)


def _has_triangles(geometry) -> bool:
    import trimesh

    return isinstance(geometry, trimesh.Trimesh) and len(geometry.faces) > 0


def srgb_to_linear(values: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] decoded to linear (IEC 61966-2-1)."""
    values = np.asarray(values, dtype=np.float64)
    return np.where(values <= 0.04045, values / 12.92, ((values + 0.055) / 1.055) ** 2.4)


def _factor(value, size: int, default: float) -> np.ndarray:
    """A glTF colour factor as floats in [0, 1] (trimesh keeps base colours as 8-bit integers)."""
    if value is None:
        return np.full(size, default)
    arr = np.asarray(value).ravel()[:size]
    return arr / 255.0 if arr.dtype.kind in "ui" else arr.astype(np.float64)


def material_bsdf(name: str, material, has_uv: bool, dropped: set[str]) -> tuple[dict, bool]:
    """(the diffuse BSDF dict of a glTF material, whether it uses the base-colour texture)."""
    from mincam_sim.render.scene.textures import texture_tensor

    if material is None or not hasattr(material, "baseColorFactor"):
        if material is not None:  # a SimpleMaterial (OBJ-style): its diffuse colour
            rgb = _factor(getattr(material, "diffuse", None), 3, DEFAULT_ALBEDO)
            return {"type": "diffuse", "reflectance": {"type": "spectrum", "value": float(LUMINANCE @ rgb)}}, False
        return {"type": "diffuse", "reflectance": {"type": "spectrum", "value": DEFAULT_ALBEDO}}, False
    base = _factor(material.baseColorFactor, 3, 1.0)
    image = getattr(material, "baseColorTexture", None)
    _note_dropped(material, dropped)
    if image is not None and has_uv:
        rgb = np.asarray(image.convert("RGB"), dtype=np.float64) / 255.0
        albedo = np.clip(srgb_to_linear(rgb) * base, 0.0, 1.0) @ LUMINANCE
        reflectance = {"type": "bitmap", "data": texture_tensor(albedo), "raw": True, "filter_type": "bilinear",
                       "wrap_mode": "repeat"}
        used = True
    else:
        if image is not None:
            dropped.add(f"the base-colour texture of {name!r} (no texture coordinates)")
        reflectance = {"type": "spectrum", "value": float(np.clip(LUMINANCE @ base, 0.0, 1.0))}
        used = False
    bsdf = {"type": "diffuse", "reflectance": reflectance}
    if getattr(material, "doubleSided", False):
        bsdf = {"type": "twosided", "material": bsdf}
    return bsdf, used


def _note_dropped(material, dropped: set[str]) -> None:
    for attr, what in (("metallicFactor", "metallic"), ("metallicRoughnessTexture", "metallic-roughness maps"),
                       ("normalTexture", "normal maps"), ("occlusionTexture", "occlusion maps"),
                       ("emissiveTexture", "emissive maps")):
        value = getattr(material, attr, None)
        if value is not None and not (attr == "metallicFactor" and float(value) == 0.0):
            dropped.add(what)
    if getattr(material, "alphaMode", None) not in (None, "OPAQUE"):
        dropped.add("alpha")


def material_emitter(material, emission_w_m2_sr: float) -> dict | None:
    """An area light for a glTF material with a non-zero emissive factor, else None."""
    emissive = _factor(getattr(material, "emissiveFactor", None), 3, 0.0)
    radiance = float(emission_w_m2_sr * (LUMINANCE @ emissive))
    if not radiance > 0:
        return None
    return {"type": "area", "radiance": {"type": "spectrum", "value": radiance}}


def build_mesh(name: str, vertices_m: np.ndarray, faces: np.ndarray, uv: np.ndarray | None, bsdf: dict,
               emitter: dict | None):
    """An in-memory ``mi.Mesh`` (flat-shaded) with texture coordinates (trimesh's, origin at the image's
    bottom: flipped to Mitsuba's, whose ``v = 0`` is the image's first row), a BSDF and an optional emitter."""
    mi = backend.mitsuba()
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(bsdf)
    if emitter is not None:
        props["emitter"] = mi.load_dict(emitter)
    mesh = mi.Mesh(name, len(vertices_m), len(faces), props=props, has_vertex_texcoords=uv is not None)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(np.asarray(vertices_m, dtype=np.float32).ravel().copy())
    params["faces"] = mi.UInt32(np.asarray(faces, dtype=np.uint32).ravel().copy())
    if uv is not None:
        uv = np.asarray(uv, dtype=np.float64)
        params["vertex_texcoords"] = mi.Float(np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1).astype(np.float32)
                                              .ravel())
    params.update()
    return mesh


def gltf_referenced_files(path: Path) -> list[Path]:
    """The files a glTF / GLB file names (``buffers`` and ``images`` by a relative ``uri``, not embedded
    ``data:`` ones) that exist: their content determines the numbers too. An unreadable file gives none here
    (the loader reports it)."""
    import json
    import struct
    from urllib.parse import unquote

    path = Path(path)
    try:
        data = path.read_bytes()
        if data[:4] == b"glTF":  # GLB: 12-byte header, then the JSON chunk (length, type, content)
            length = struct.unpack_from("<I", data, 12)[0]
            data = data[20:20 + length]
        header = json.loads(data)
    except (OSError, ValueError, struct.error):
        return []
    found = []
    for entry in [*header.get("buffers", []), *header.get("images", [])]:
        uri = entry.get("uri") if isinstance(entry, dict) else None
        if isinstance(uri, str) and uri and not uri.startswith("data:"):
            file = path.parent / unquote(uri)
            if file.is_file() and file not in found:
                found.append(file)
    return found
