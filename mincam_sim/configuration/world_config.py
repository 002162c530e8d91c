"""TOML configuration of a world render: your own scene (a Mitsuba XML file and/or meshes and lights), movers on
trajectories, the mincam in the scene's world coordinates (pure Python/numpy; validated field by field).

The sections are dataclasses of :mod:`mincam_sim.configuration.schema` (the ``[mincam]`` section extends the render
file's);
:data:`WORLD_SCHEMA` lists them and writes the documented example (``mincam-sim config-example --world`` prints
:func:`world_example_toml`). Every problem raises :class:`~mincam_sim.errors.ConfigError` naming the field and
the fix. Relative paths resolve against the config file's directory.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mincam_sim.budget import Budget
from mincam_sim.configuration.config import (
    MincamSection,
    MixelTable,
    _build_mincam,
    budget_field,
    make_budget,
    make_solver,
    refuse_old_solver_keys,
    solver_check,
    warn_ignored_mincam,
)
from mincam_sim.configuration.schema import (
    Choice,
    Integer,
    Number,
    Part,
    Schema,
    Text,
    Vector,
    describe,
    read_section,
    setting,
    warn_ignored,
)
from mincam_sim.configuration.schema import number as _number
from mincam_sim.configuration.schema import path as _path
from mincam_sim.configuration.schema import string as _string
from mincam_sim.configuration.schema import vector as _vector
from mincam_sim.configuration.toml_files import read_document
from mincam_sim.errors import ConfigError
from mincam_sim.model.geometry import Pose
from mincam_sim.model.optics import Mincam
from mincam_sim.render.scene.gltf_files import gltf_referenced_files
from mincam_sim.render.solvers import Solver

UP_AXES = ("z", "y")
LIGHT_KINDS = ("area", "point", "spot", "sky")
BACKGROUNDS = ("without_movers", "as_built", "first_frame")
MAX_WORLD_FRAMES = 1_000_000
#: The ``[[world.light]]`` keys each kind uses (``id`` and ``kind`` aside); the others are ignored with a warning.
LIGHT_KEYS = {"area": ("position_m", "forward", "size_m", "radiance_w_m2_sr"),
              "point": ("position_m", "intensity_w_sr"),
              "spot": ("position_m", "forward", "intensity_w_sr", "cutoff_deg"),
              "sky": ("radiance_w_m2_sr",)}


def _world_variant(section: str, key: str, value: Any) -> str:
    if value not in ("", "cuda_ad_mono", "llvm_ad_mono"):
        raise ConfigError(f"[run] variant {value!r}: world scenes need '', 'cuda_ad_mono' or 'llvm_ad_mono'")
    return value


def _depth(section: str, key: str, value: Any) -> int:
    depth = Integer(minimum=0, maximum=16)(section, key, value)
    if depth == 1:
        raise ConfigError(f"[{section}] {key} = 1 sees nothing through a mask (a path needs 2 segments: mask -> "
                          "light); give 2 or more, or 0 for the scene file's own")
    return depth


def _parameters(section: str, key: str, value: Any) -> dict[str, str]:
    if not isinstance(value, dict):
        raise ConfigError(f"[{section}] {key} must be a table name = value (the scene file's <default> names), got "
                          f"{describe(value)}")
    out = {}
    for name, v in value.items():
        if isinstance(v, bool):
            v = "true" if v else "false"
        elif isinstance(v, (int, float)) and np.isfinite(v):
            v = repr(v)
        elif isinstance(v, list) and v and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                               and np.isfinite(x) for x in v):
            v = ", ".join(repr(x) for x in v)
        if not isinstance(v, str):
            raise ConfigError(f"[{section}.{key}] {name} = {describe(v)}: give the value as the XML writes it (a "
                              "string such as \"0, 0, 0\", a number, a boolean or a list of numbers)")
        out[str(name)] = v
    return out


def _rows_check(width: int):
    def check(section: str, key: str, value: Any) -> np.ndarray:
        return _rows(section, key, value, width)
    return check


def _times(section: str, key: str, value: Any) -> list[float]:
    if not isinstance(value, list) or not value:
        raise ConfigError(f"{section}: {key} must be a non-empty list of times in seconds, got {describe(value)}")
    return [_number(section, f"{key}[{j}]", v) for j, v in enumerate(value)]


def _below(limit: float):
    def check(section: str, key: str, value: Any) -> float:
        v = _number(section, key, value, positive=True)
        if v >= limit:
            raise ConfigError(f"{section} {key} must be below {limit:g}, got {v}")
        return v
    return check


def _positive_pair(section: str, key: str, value: Any) -> tuple[float, float]:
    size = _vector(section, key, value, 2)
    if min(size) <= 0:
        raise ConfigError(f"{section}: {key} must be two positive lengths, got {list(size)}")
    return size  # type: ignore[return-value]


def _world_id(section: str, key: str, value: Any) -> str:
    text = _string(section, key, value)
    if not text or "." in text or text.strip() != text:
        raise ConfigError(f"{section}: id {text!r} must be a non-empty name without '.' or surrounding spaces")
    return text


# ------------------------------------------------------------------------------------------------ sections
@dataclass(frozen=True)
class WorldRunSection:
    """``[run]`` of a world render: the solver and its budget."""

    solver: str = setting("stratified_change", '"stratified_change" (rays where the change is) or "plain_change" '
                          "(whole-aperture rays, the reference)", solver_check("world"))
    spp: int = setting(16384, "rays per mixel per frame and pass", budget_field)
    target_rel_stderr: float = setting(0.0, "> 0: raise spp until the worst significant dP reaches this",
                                       budget_field)
    replicates: int = setting(8, "independent estimates per value, for the standard error", budget_field)
    seed: int = setting(0, "same seed, same numbers", budget_field)
    max_depth: int = setting(0, "path length from the mask: 2 = direct light, 3 = one inter-reflection; 0 = the "
                             "scene file's <integrator> max_depth, else 3", _depth)
    variant: str = setting("", '"" = automatic (cuda_ad_mono > llvm_ad_mono)', _world_variant)
    out_dir: str = setting("out/world", "measurements.npz / .csv and a plot of dP; relative to this file",
                           Text(nonempty=True))


@dataclass(frozen=True)
class WorldMincamSection(MincamSection):
    """``[mincam]`` of a world render: the display config's keys, the layout's pose in world coordinates."""

    layout: str = setting("cross", '"pair", "cross" or "custom" ([[mixel]] tables, poses in world coordinates)',
                          Choice(("pair", "cross", "custom")))
    position_m: tuple[float, float, float] = setting((0.0, 0.0, 0.5), "pair / cross: the centre of the layout, "
                                                     "world coordinates", Vector(3))
    forward: tuple[float, float, float] = setting((0.0, 0.0, -1.0), "pair / cross: viewing direction", Vector(3))
    up: tuple[float, float, float] = setting((0.0, 1.0, 0.0), "pair / cross: the layout's up (its +y)", Vector(3))


@dataclass(frozen=True)
class WorldSection:
    """``[world]``: the scene file, its orientation and timing."""

    scene: str = setting("", "a Mitsuba 3 XML scene (shapes addressed by their id) or a glTF / GLB file (its nodes "
                         "by their name); relative to this file", Text())
    up: str = setting("z", '"z", or "y" for a scene authored y-up (turned so that its +y is the world +z); a glTF '
                      'file is "y" unless set', Choice(UP_AXES))
    frame_rate_hz: float = setting(30.0, "frames per second: the time column, and keyframe sampling",
                                   Number(positive=True))
    background: str = setting("without_movers", '"without_movers" (movers removed), "as_built", or "first_frame"',
                              Choice(BACKGROUNDS))
    unit_m: float = setting(1.0, "the length of the scene file's unit in metres (0.01: modelled in cm; the mincam, "
                            "movers and lights here stay in metres)", Number(positive=True))
    emission_w_m2_sr: float = setting(1.0, "a glTF file's emission: the radiance of an emissive factor (1, 1, 1)",
                                      Number(minimum=0.0))
    parameters: Any = setting(None, "the scene file's <default> values, name = value as the XML writes them (or a "
                              "[world.parameters] table)", _parameters, example={"lamp": "0, 0, 0"})


@dataclass(frozen=True)
class ObjectTable:
    """One ``[[world.object]]``: a mesh file placed in the scene."""

    id: str | None = setting(None, "the name movers and parameters use (required)", _world_id, example="toy",
                             shown=True)
    mesh: str | None = setting(None, "OBJ, PLY, STL, glTF/GLB (read by trimesh; relative to this file; required)",
                               Text(), example="toy.obj", shown=True)
    albedo: float = setting(0.8, "diffuse grey reflectance in [0, 1]", Number(minimum=0.0, maximum=1.0))
    position_m: tuple[float, float, float] = setting((0.0, 0.0, 0.0), "where its file origin goes", Vector(3))
    rotation_deg: tuple[float, float, float] = setting((0.0, 0.0, 0.0), "about x, then y, then z (degrees)",
                                                       Vector(3))
    scale: float = setting(1.0, "file units to metres", Number(positive=True))


@dataclass(frozen=True)
class LightTable:
    """One ``[[world.light]]``: an emitter added to the scene."""

    id: str | None = setting(None, "its name (required)", _world_id, example="lamp", shown=True)
    kind: str | None = setting(None, '"area" (a square emitting along forward), "point", "spot", "sky" (required)',
                               Choice(LIGHT_KINDS), example="area", shown=True)
    position_m: tuple[float, float, float] = setting((0.0, 0.0, 1.0), "its centre", Vector(3))
    forward: tuple[float, float, float] = setting((0.0, 0.0, -1.0), "area and spot lights: where they shine",
                                                  Vector(3))
    size_m: tuple[float, float] = setting((0.3, 0.3), "area lights: width, height", _positive_pair)
    # at most what a 32-bit float (Mitsuba's) holds: 1e300 became inf, refused under its internal parameter name
    radiance_w_m2_sr: float = setting(10.0, "area lights and sky", Number(minimum=0.0, maximum=1e30))
    intensity_w_sr: float = setting(1.0, "point and spot lights", Number(minimum=0.0, maximum=1e30))
    cutoff_deg: float = setting(20.0, "spot lights: half-angle of the cone (below 90)", _below(90.0))


@dataclass(frozen=True)
class MoverTable:
    """One ``[[world.mover]]``: a moving shape and its trajectory (one of offsets_m, keyframes_m with times_s, or
    csv)."""

    id: str | None = setting(None, "a shape of the XML scene or an object above (required)", _world_id,
                             example="toy", shown=True)
    offsets_m: Any = setting(None, "each frame's displacement from where the scene places it", _rows_check(3),
                             example=((-0.1, 0.0, 0.0), (0.0, 0.0, 0.0), (0.1, 0.0, 0.0)), shown=True)
    rotations_deg: Any = setting(None, "optional: each frame's rotation about the shape's centre (x, y, z)",
                                 _rows_check(3), example=((0, 0, 0), (0, 0, 45), (0, 0, 90)))
    times_s: Any = setting(None, "keyframe times, increasing, instead of offsets_m ...", _times,
                           example=(0.0, 1.0))
    keyframes_m: Any = setting(None, "... the displacement at each, sampled at frame_rate_hz", _rows_check(3),
                               example=((-0.1, 0, 0), (0.1, 0, 0)))
    csv: str | None = setting(None, "or a file of t_s,x_m,y_m,z_m rows (relative to this file)", Text(),
                              example="path.csv")


@dataclass(frozen=True)
class CameraTable:
    """``[world.camera]``: the optional ground-truth pinhole camera."""

    position_m: tuple[float, float, float] | None = setting(None, "its centre (required)", Vector(3),
                                                            example=(0.0, 0.0, 0.5), shown=True)
    look_at_m: tuple[float, float, float] | None = setting(None, "the point it looks at (required)", Vector(3),
                                                           example=(0.0, 0.0, 0.0), shown=True)
    up: tuple[float, float, float] = setting((0.0, 1.0, 0.0), "the image's up", Vector(3))
    fov_deg: float = setting(60.0, "field of view (below 180)", _below(180.0))
    width_px: int = setting(160, "image width", Integer(maximum=8192))
    height_px: int = setting(120, "image height", Integer(maximum=8192))
    spp: int = setting(64, "samples per pixel", Integer(maximum=1 << 20))
    threshold: float = setting(0.05, "change detected where |image - background| > threshold x background max",
                               Number(positive=True))


#: The world render file: its sections, in the order the documented example shows them.
WORLD_SCHEMA = Schema(
    "mincam-sim render configuration of a world scene (mincam-sim render world.toml).\n"
    "Units are in the key names: _m metres, _deg degrees, _s seconds, _hz per second, _w_m2_sr radiance.",
    (Part("run", WorldRunSection), Part("mincam", WorldMincamSection),
     Part("mixel", MixelTable, array=True, commented=True,
          intro='For layout = "custom", one table per mixel (poses in world coordinates), as in display configs:'),
     Part("world", WorldSection),
     Part("world.object", ObjectTable, array=True,
          intro="Objects and lights declared here (in addition to, or instead of, the XML scene):"),
     Part("world.light", LightTable, array=True),
     Part("world.mover", MoverTable, array=True,
          intro="One per moving shape (a shape of the XML scene or an object above), each frame's displacement "
                "from where\nthe scene places it (one of: offsets_m, or keyframes_m at times_s, or a csv of "
                "t_s,x_m,y_m,z_m rows):"),
     Part("world.camera", CameraTable, commented=True,
          intro="Optional ground-truth pinhole camera: images of every frame and the centroid of each frame's "
                "change")),
)


def world_example_toml() -> str:
    """The documented world config, every key with its default (written from :data:`WORLD_SCHEMA`)."""
    return WORLD_SCHEMA.example()


@dataclass(frozen=True)
class WorldObject:
    id: str
    mesh: Path
    albedo: float
    position_m: tuple[float, float, float]
    rotation_deg: tuple[float, float, float]
    scale: float


@dataclass(frozen=True)
class WorldLight:
    id: str
    kind: str
    position_m: tuple[float, float, float]
    forward: tuple[float, float, float]
    size_m: tuple[float, float]
    radiance_w_m2_sr: float
    intensity_w_sr: float
    cutoff_deg: float


@dataclass(frozen=True)
class Mover:
    """One moving shape: per frame, its displacement [m] (and rotation [deg] about its centre) from where the
    scene places it."""

    id: str
    offsets_m: np.ndarray  # (n_frames, 3)
    rotations_deg: np.ndarray | None  # (n_frames, 3) or None


@dataclass(frozen=True)
class CameraSpec:
    position_m: tuple[float, float, float]
    look_at_m: tuple[float, float, float]
    up: tuple[float, float, float]
    fov_deg: float
    width_px: int
    height_px: int
    spp: int
    threshold: float


@dataclass
class WorldRunConfig:
    """[run] of a world render: the solver object and its budget; ``out_dir`` resolved against the file's folder."""

    solver: Solver
    budget: Budget
    max_depth: int | None  # None: the scene file's <integrator>, else 3
    variant: str | None
    out_dir: Path


@dataclass
class WorldConfig:
    """A validated world config: run settings, the mincam (world coordinates), the scene's sources, the movers
    and the optional ground-truth camera."""

    run: WorldRunConfig
    mincam: Mincam
    scene_file: Path | None
    up: str
    frame_rate_hz: float
    background: str
    objects: list[WorldObject]
    lights: list[WorldLight]
    movers: list[Mover]
    camera: CameraSpec | None
    source: Path | None = None
    files: list[Path] = field(default_factory=list)  # every file the numbers depend on (XML, meshes, CSVs)
    parameters: dict[str, str] = field(default_factory=dict)  # the scene file's <default> values
    unit_m: float = 1.0  # the scene file's unit [m]
    emission_w_m2_sr: float = 1.0  # a glTF file's emission scale [W m^-2 sr^-1]

    @property
    def n_frames(self) -> int:
        return len(self.movers[0].offsets_m)


def is_world_config(source: str | Path | dict) -> bool:
    """True when a TOML document describes a world scene (it has a ``[world]`` section)."""
    raw, _, _ = read_document(source, None)
    return isinstance(raw, dict) and "world" in raw


def load_world_config(source: str | Path | dict, base_dir: str | Path | None = None) -> WorldConfig:
    """Parse and validate a world render config (a ``.toml`` path, TOML text or a parsed dict).

    Raises
    ------
    ConfigError
        For every problem with the document: the message names the field and the fix.
    """
    raw, base, path = read_document(source, base_dir)
    tables = WORLD_SCHEMA.tables(raw)
    refuse_old_solver_keys(tables["run"], "world")
    run: WorldRunSection = WORLD_SCHEMA.read("run", tables["run"])
    solver = make_solver(run.solver)
    budget = make_budget(solver, "world", run.spp, None, run.target_rel_stderr, run.replicates, run.seed)
    run_cfg = WorldRunConfig(solver, budget, run.max_depth or None, run.variant or None,
                             _path("run", "out_dir", run.out_dir, base))
    mincam = _world_mincam(WORLD_SCHEMA.read("mincam", tables["mincam"]), tables["mixel"], base)
    w: WorldSection = WORLD_SCHEMA.read("world", tables["world"])
    files: list[Path] = []
    scene_file = None
    if w.scene:
        scene_file = _path("world", "scene", w.scene, base)
        if not scene_file.is_file():
            raise ConfigError(f"[world] scene: {scene_file} {_not_a_file(scene_file)} (relative paths are taken "
                              "from the config's folder)")
        files.append(scene_file)
        files.extend(gltf_referenced_files(scene_file) if is_gltf(scene_file) else referenced_files(scene_file))
        if is_gltf(scene_file) and w.parameters:
            raise ConfigError("[world] parameters set an XML scene file's <default> values; a glTF file has none: "
                              "remove them")
    objects = [_object(i, t, base, files) for i, t in enumerate(tables["world.object"])]
    lights = [_light(i, t) for i, t in enumerate(tables["world.light"])]
    if scene_file is None and not objects:
        raise ConfigError("[world] needs a scene = \"file.xml\" or at least one [[world.object]]")
    if scene_file is None and (w.parameters or w.unit_m != 1.0):
        raise ConfigError("[world] parameters and unit_m apply to a scene file: give [world] scene = \"file.xml\" "
                          "or remove them")
    ids = [o.id for o in objects] + [light.id for light in lights]
    dupes = sorted({i for i in ids if ids.count(i) > 1})
    if dupes:
        raise ConfigError(f"[world] ids {dupes} are used twice; every object and light needs its own id")
    movers = [_mover(i, t, base, w.frame_rate_hz, files) for i, t in enumerate(tables["world.mover"])]
    if not movers:
        raise ConfigError("[world] needs at least one [[world.mover]] (id = a shape, offsets_m = one per frame)")
    counts = {m.id: len(m.offsets_m) for m in movers}
    if len(set(counts.values())) != 1:
        raise ConfigError(f"[[world.mover]] frame counts differ: {counts}; every mover needs one offset per frame")
    names = [m.id for m in movers]
    if len(set(names)) != len(names):
        raise ConfigError(f"[[world.mover]] ids {names}: each shape can move in one mover table only")
    camera = _camera(tables["world.camera"]) if "camera" in (raw.get("world") or {}) else None
    warn_ignored_mincam(tables["mincam"], tables["mixel"], mincam, WorldMincamSection,
                        placed=("spacing_m", "position_m", "forward", "up"))
    if scene_file is None:
        warn_ignored("world", tables["world"], ("up",), "it turns the XML scene, and [world] names no scene",
                     WorldSection)
    if scene_file is None or not is_gltf(scene_file):
        warn_ignored("world", tables["world"], ("emission_w_m2_sr",), "it scales a glTF file's emission, and "
                     "[world] scene is no glTF file", WorldSection)
    up = "y" if scene_file is not None and is_gltf(scene_file) and "up" not in tables["world"] else w.up
    return WorldConfig(run_cfg, mincam, scene_file, up, w.frame_rate_hz, w.background, objects, lights, movers,
                       camera, path, files, w.parameters or {}, w.unit_m, w.emission_w_m2_sr)


def is_gltf(path: Path) -> bool:
    """Whether a scene file is glTF / GLB (by its suffix)."""
    return path.suffix.lower() in (".gltf", ".glb")


def referenced_files(xml_path: Path) -> list[Path]:
    """Files a Mitsuba XML scene names (``<string name="filename" value=...>``, e.g. meshes and textures,
    relative to the XML's folder) that exist: their content determines the numbers too. Unreadable XML gives
    none here (the loader reports it with its line)."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(xml_path).getroot()
    except (ET.ParseError, OSError):
        return []
    found = []
    for node in root.iter("string"):
        if node.get("name") == "filename" and node.get("value"):
            path = Path(node.get("value")).expanduser()
            path = path if path.is_absolute() else xml_path.parent / path
            if path.is_file() and path not in found:
                found.append(path)
    return found


def _required(where: str, key: str, value: Any, what: str) -> Any:
    if value is None:
        raise ConfigError(f"{where}: {key} is required ({what})")
    return value


def _world_mincam(m: WorldMincamSection, tables: list, base: Path) -> Mincam:
    mincam = _build_mincam(m, tables, base)
    if m.layout == "custom":
        return mincam
    position, forward, up = np.array(m.position_m), np.array(m.forward), np.array(m.up)
    if np.linalg.norm(forward) == 0 or np.linalg.norm(np.cross(forward, up)) < 1e-9:
        raise ConfigError("[mincam] forward must be non-zero and up must not be parallel to it")
    target = Pose(tuple(position), tuple(forward), tuple(up)).matrix()
    default = Pose((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)).matrix()
    rot = target[:3, :3] @ default[:3, :3].T
    mixels = tuple(mx.with_pose(Pose(tuple(rot @ np.asarray(mx.pose.position_m) + position),
                                     tuple(rot @ np.asarray(mx.pose.forward)), tuple(rot @ np.asarray(mx.pose.up))))
                   for mx in mincam)
    return Mincam(mixels, allow_overlap=mincam.allow_overlap)


def _object(i: int, given: dict, base: Path, files: list[Path]) -> WorldObject:
    where = f"[[world.object]] #{i + 1}"
    t: ObjectTable = read_section(where, given, ObjectTable)
    oid = _required(where, "id", t.id, "the name movers and parameters use")
    _required(f"{where} ({oid})", "mesh", t.mesh, "a mesh file: OBJ, PLY, STL, glTF/GLB")
    mesh = _path(where, "mesh", t.mesh, base)
    if not mesh.is_file():
        raise ConfigError(f"{where} ({oid}): mesh file {mesh} {_not_a_file(mesh)} (relative to the config's folder)")
    files.append(mesh)
    return WorldObject(oid, mesh, t.albedo, t.position_m, t.rotation_deg, t.scale)


def _light(i: int, given: dict) -> WorldLight:
    where = f"[[world.light]] #{i + 1}"
    t: LightTable = read_section(where, given, LightTable)
    lid = _required(where, "id", t.id, "its name")
    kind = _required(f"{where} ({lid})", "kind", t.kind, f"one of {', '.join(LIGHT_KINDS)}")
    if np.linalg.norm(t.forward) == 0:
        raise ConfigError(f"{where} ({lid}): forward must be a non-zero direction")
    unused = [k for keys in LIGHT_KEYS.values() for k in keys if k not in LIGHT_KEYS[kind]]
    warn_ignored(f"{where} ({lid})", given, list(dict.fromkeys(unused)), f'a {kind} light uses only '
                 f"{', '.join(LIGHT_KEYS[kind])}")
    return WorldLight(lid, kind, t.position_m, t.forward, t.size_m, t.radiance_w_m2_sr, t.intensity_w_sr,
                      t.cutoff_deg)


def _rows(where: str, key: str, value: Any, width: int) -> np.ndarray:
    if not isinstance(value, list) or not value:
        raise ConfigError(f"{where}: {key} must be a non-empty list of [x, y, z] rows, got {describe(value)}")
    rows = [_vector(where, f"{key}[{j}]", row, width) for j, row in enumerate(value)]
    arr = np.array(rows, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"{where}: {key} holds NaN or infinite values; give finite numbers")
    return arr


def _mover(i: int, given: dict, base: Path, rate: float, files: list[Path]) -> Mover:
    where = f"[[world.mover]] #{i + 1}"
    t: MoverTable = read_section(where, given, MoverTable)
    mid = _required(where, "id", t.id, "a shape of the scene or an object")
    where = f"{where} ({mid})"
    trajectories = {"offsets_m": t.offsets_m, "keyframes_m": t.keyframes_m, "csv": t.csv}
    chosen = [k for k, v in trajectories.items() if v is not None]
    if len(chosen) != 1:
        raise ConfigError(f"{where}: give exactly one of offsets_m, keyframes_m (with times_s) or csv; got "
                          f"{chosen or 'none'}")
    if t.keyframes_m is None:
        warn_ignored(where, given, ("times_s",), f"it times keyframes_m, and this mover gives {chosen[0]}")
    if t.offsets_m is not None:
        offsets = t.offsets_m
    elif t.keyframes_m is not None:
        offsets = _sample_keyframes(where, t.times_s, t.keyframes_m, rate)
    else:
        csv_path = _path(where, "csv", t.csv, base)
        files.append(csv_path)
        times, keys = _read_trajectory_csv(where, csv_path)
        offsets = _sample_keyframes(where, times, keys, rate)
    if len(offsets) > MAX_WORLD_FRAMES:
        raise ConfigError(f"{where}: {len(offsets)} frames is more than {MAX_WORLD_FRAMES}")
    rotations = t.rotations_deg
    if rotations is not None and len(rotations) != len(offsets):
        raise ConfigError(f"{where}: rotations_deg has {len(rotations)} rows but there are {len(offsets)} frames")
    return Mover(mid, offsets, rotations)


def _sample_keyframes(where: str, times: Any, keys: np.ndarray, rate: float) -> np.ndarray:
    if times is None:
        raise ConfigError(f"{where}: keyframes_m needs times_s (one time per keyframe, seconds, increasing)")
    if not isinstance(times, (list, np.ndarray)) or len(times) != len(keys):
        raise ConfigError(f"{where}: times_s must list one time per keyframe ({len(keys)}), got {describe(times)}")
    t = np.array([_number(where, f"times_s[{j}]", v) for j, v in enumerate(times)], dtype=float)
    if len(t) < 2 or np.any(np.diff(t) <= 0):
        raise ConfigError(f"{where}: times_s must hold at least two increasing times, got {t.tolist()}")
    count = int(np.floor((t[-1] - t[0]) * rate + 0.5)) + 1  # counted before anything is allocated
    if count > MAX_WORLD_FRAMES:
        raise ConfigError(f"{where}: keyframes from {t[0]:g} s to {t[-1]:g} s at [world] frame_rate_hz = {rate:g} "
                          f"make {count} frames, more than {MAX_WORLD_FRAMES}: lower frame_rate_hz or shorten "
                          "times_s")
    frames = np.arange(t[0], t[-1] + 0.5 / rate, 1.0 / rate)
    frames = frames[frames <= t[-1] + 1e-12]
    return np.stack([np.interp(frames, t, keys[:, k]) for k in range(3)], axis=1)


def _not_a_file(path: Path) -> str:
    """Why ``path`` is no file to read, in words."""
    return "is a directory, not a file" if path.is_dir() else "does not exist"


def _read_trajectory_csv(where: str, path: Path) -> tuple[np.ndarray, np.ndarray]:
    if not path.is_file():
        raise ConfigError(f"{where}: csv file {path} {_not_a_file(path)}")
    try:
        with path.open(newline="") as fh:
            rows = [r for r in csv.reader(fh) if r and not r[0].lstrip().startswith("#")]
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(f"{where}: cannot read {path}: {err}") from None
    if rows and not _numeric(rows[0]):
        rows = rows[1:]  # a header line
    try:
        data = np.array([[float(x) for x in r] for r in rows], dtype=float)
    except ValueError:
        raise ConfigError(f"{where}: {path} must hold rows t_s, x_m, y_m, z_m of numbers") from None
    if data.ndim != 2 or data.shape[1] != 4 or len(data) < 2:
        raise ConfigError(f"{where}: {path} must hold at least two rows of 4 numbers (t_s, x_m, y_m, z_m)")
    if not np.all(np.isfinite(data)):
        raise ConfigError(f"{where}: {path} holds NaN or infinite values")
    return data[:, 0].tolist(), data[:, 1:]


def _numeric(row: list[str]) -> bool:
    try:
        [float(x) for x in row]
    except ValueError:
        return False
    return True


def _camera(given: dict) -> CameraSpec:
    where = "[world.camera]"
    t: CameraTable = read_section(where, given, CameraTable)
    position = _required(where, "position_m", t.position_m, "the camera's centre [m]")
    look = _required(where, "look_at_m", t.look_at_m, "the point it looks at [m]")
    if np.allclose(position, look):
        raise ConfigError(f"{where}: look_at_m must differ from position_m")
    forward = np.asarray(look, dtype=float) - np.asarray(position, dtype=float)
    up = np.asarray(t.up, dtype=float)
    if np.linalg.norm(np.cross(forward, up)) < 1e-9 * np.linalg.norm(forward) * max(np.linalg.norm(up), 1e-300):
        raise ConfigError(f"{where}: up = {up.tolist()} is parallel to the view from position_m to look_at_m "
                          f"({np.round(forward / np.linalg.norm(forward), 6).tolist()}); give an up across the view")
    return CameraSpec(position, look, t.up, t.fov_deg, t.width_px, t.height_px, t.spp, t.threshold)
