"""TOML configuration of a world render: your own scene (a Mitsuba XML file and/or meshes and lights), movers on
trajectories, the mincam in the scene's world coordinates (pure Python/numpy; validated field by field).

The schema and its documented example come from one table, :data:`WORLD_SCHEMA` (``mincam-sim
config-example --world`` prints :func:`world_example_toml`). Every problem raises
:class:`~mincam_sim.errors.ConfigError` naming the field and the fix. Relative paths resolve against the
config file's directory.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .config import (
    _SCHEMA,
    ConfigError,
    _build_mincam,
    _check_keys,
    _choice,
    _describe,
    _integer,
    _number,
    _path,
    _read_source,
    _string,
    _table,
    _vector,
)
from .geometry import Pose
from .optics import Mincam

ESTIMATORS = ("stratified", "plain")
UP_AXES = ("z", "y")
LIGHT_KINDS = ("area", "point", "spot", "sky")
MAX_WORLD_FRAMES = 1_000_000

# (section, key, default, comment): the one source of the defaults and of the documented example
WORLD_SCHEMA: list[tuple[str, str, Any, str]] = [
    ("run", "estimator", "stratified", '"stratified" (rays where the change is) or "plain" (the reference)'),
    ("run", "spp", 16384, "rays per mixel per frame and pass"),
    ("run", "target_rel_stderr", 0.0, "> 0: raise spp until the worst significant dP reaches this"),
    ("run", "replicates", 8, "independent estimates per value, for the standard error"),
    ("run", "seed", 0, "same seed, same numbers"),
    ("run", "max_depth", 3, "path length from the mask: 2 = direct light, 3 = one inter-reflection"),
    ("run", "variant", "", '"" = automatic (cuda_ad_mono > llvm_ad_mono)'),
    ("run", "out_dir", "out/world", "measurements.npz / .csv and a plot of dP; relative to this file"),
    ("mincam", "layout", "cross", '"pair", "cross" or "custom" ([[mixel]] tables, poses in world coordinates)'),
    ("mincam", "position_m", [0.0, 0.0, 0.5], "pair / cross: the centre of the layout, world coordinates"),
    ("mincam", "forward", [0.0, 0.0, -1.0], "pair / cross: viewing direction"),
    ("mincam", "up", [0.0, 1.0, 0.0], "pair / cross: the layout's up (its +y)"),
    ("world", "scene", "", "a Mitsuba 3 XML scene (relative to this file); shapes addressed by their id"),
    ("world", "up", "z", '"z", or "y" for a scene authored y-up (turned so that its +y is the world +z)'),
    ("world", "frame_rate_hz", 30.0, "frames per second: the time column, and keyframe sampling"),
    ("world", "background", "without_movers", '"without_movers" (movers removed), "as_built", or "first_frame"'),
]
_OBJECT_KEYS = {"id": None, "mesh": None, "albedo": 0.8, "position_m": [0.0, 0.0, 0.0],
                "rotation_deg": [0.0, 0.0, 0.0], "scale": 1.0}
_LIGHT_KEYS = {"id": None, "kind": None, "position_m": [0.0, 0.0, 1.0], "forward": [0.0, 0.0, -1.0],
               "size_m": [0.3, 0.3], "radiance_w_m2_sr": 10.0, "intensity_w_sr": 1.0, "cutoff_deg": 20.0}
_MOVER_KEYS = {"id": None, "offsets_m": None, "rotations_deg": None, "times_s": None, "keyframes_m": None,
               "csv": None}
_CAMERA_KEYS = {"position_m": None, "look_at_m": None, "up": [0.0, 1.0, 0.0], "fov_deg": 60.0, "width_px": 160,
                "height_px": 120, "spp": 64, "threshold": 0.05}


def _defaults(section: str) -> dict:
    return {key: default for s, key, default, _ in WORLD_SCHEMA if s == section}


def _mincam_defaults() -> dict:
    return {**_SCHEMA["mincam"], **_defaults("mincam")}


def world_example_toml() -> str:
    """The documented world config, every key with its default (generated from :data:`WORLD_SCHEMA`)."""
    lines = ["# mincam-sim render configuration of a world scene (mincam-sim render world.toml).",
             "# Units are in the key names: _m metres, _deg degrees, _s seconds, _hz per second, _w_m2_sr radiance.",
             ""]
    for section in ("run", "mincam", "world"):
        lines.append(f"[{section}]")
        for s, key, default, comment in WORLD_SCHEMA:
            if s == section:
                lines.append(f"{key} = {_toml(default):<18} # {comment}")
        if section == "mincam":
            lines += [f"{k} = {_toml(v):<18} # as in display configs" for k, v in _SCHEMA["mincam"].items()
                      if k not in ("layout",)]
        lines.append("")
    lines += [
        "# Objects and lights declared here (in addition to, or instead of, the XML scene):",
        "[[world.object]]",
        'id = "toy"                 # the name movers and parameters use',
        'mesh = "toy.obj"           # OBJ, PLY, STL, glTF/GLB (read by trimesh; relative to this file)',
        "albedo = 0.8               # diffuse grey reflectance in [0, 1]",
        "position_m = [0.0, 0.0, 0.0]",
        "rotation_deg = [0.0, 0.0, 0.0]   # about x, then y, then z (degrees)",
        "scale = 1.0                # file units to metres",
        "",
        "[[world.light]]",
        'id = "lamp"',
        'kind = "area"              # "area" (a square emitting along forward), "point", "spot", "sky"',
        "position_m = [0.0, 0.0, 1.2]",
        "forward = [0.0, 0.0, -1.0]",
        "size_m = [0.3, 0.3]        # area lights",
        "radiance_w_m2_sr = 10.0    # area lights and sky",
        "intensity_w_sr = 1.0       # point and spot lights",
        "cutoff_deg = 20.0          # spot lights",
        "",
        "# One per moving shape (a shape of the XML scene or an object above), each frame's displacement from where",
        "# the scene places it (one of: offsets_m, or keyframes_m at times_s, or a csv of t_s,x_m,y_m,z_m rows):",
        "[[world.mover]]",
        'id = "toy"',
        "offsets_m = [[-0.1, 0.0, 0.0], [0.0, 0.0, 0.0], [0.1, 0.0, 0.0]]",
        "# rotations_deg = [[0, 0, 0], [0, 0, 45], [0, 0, 90]]   # optional, about the shape's centre",
        "# times_s = [0.0, 1.0]                          # keyframes instead of offsets_m ...",
        "# keyframes_m = [[-0.1, 0, 0], [0.1, 0, 0]]     # ... sampled at frame_rate_hz",
        '# csv = "path.csv"',
        "",
        "# Optional ground-truth pinhole camera: images of every frame and the centroid of each frame's change",
        "# [world.camera]",
        "# position_m = [0.0, 0.0, 0.5]",
        "# look_at_m = [0.0, 0.0, 0.0]",
        "# up = [0.0, 1.0, 0.0]",
        "# fov_deg = 60.0",
        "# width_px = 160",
        "# height_px = 120",
        "# spp = 64",
        "# threshold = 0.05        # change detected where |image - background| > threshold x background max",
    ]
    return "\n".join(lines) + "\n"


def _toml(value: Any) -> str:
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return repr(value)


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
    estimator: str
    spp: int
    target_rel_stderr: float
    replicates: int
    seed: int
    max_depth: int
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
    raw: dict
    source: Path | None = None
    files: list[Path] = field(default_factory=list)  # every file the numbers depend on (XML, meshes, CSVs)

    @property
    def n_frames(self) -> int:
        return len(self.movers[0].offsets_m)


def is_world_config(source: str | Path | dict) -> bool:
    """True when a TOML document describes a world scene (it has a ``[world]`` section)."""
    raw, _, _ = _read_source(source, None)
    return isinstance(raw, dict) and "world" in raw


def load_world_config(source: str | Path | dict, base_dir: str | Path | None = None) -> WorldConfig:
    """Parse and validate a world render config (a ``.toml`` path, TOML text or a parsed dict).

    Raises
    ------
    ConfigError
        For every problem with the document: the message names the field and the fix.
    """
    raw, base, path = _read_source(source, base_dir)
    unknown = sorted(set(raw) - {"run", "mincam", "mixel", "world"})
    if unknown:
        raise ConfigError(f"unknown section(s) {unknown} in a world config; allowed: [run], [mincam], [[mixel]], "
                          "[world] (with [[world.object]], [[world.light]], [[world.mover]], [world.camera])")
    run = _check_keys("run", raw.get("run", {}), _defaults("run"))
    estimator = _choice("run", "estimator", run["estimator"], ESTIMATORS)
    spp = _integer("run", "spp", run["spp"])
    replicates = _integer("run", "replicates", run["replicates"], minimum=2, maximum=4096)
    if spp < replicates:
        raise ConfigError(f"[run] spp = {spp} is fewer than replicates = {replicates}; each replicate needs rays")
    target = _number("run", "target_rel_stderr", run["target_rel_stderr"], minimum=0.0)
    seed = _integer("run", "seed", run["seed"], minimum=0)
    max_depth = _integer("run", "max_depth", run["max_depth"], minimum=2, maximum=16)
    variant = run["variant"]
    if variant not in ("", "cuda_ad_mono", "llvm_ad_mono"):
        raise ConfigError(f"[run] variant {variant!r}: world scenes need '', 'cuda_ad_mono' or 'llvm_ad_mono'")
    out_dir = _path("run", "out_dir", run["out_dir"], base)
    run_cfg = WorldRunConfig(estimator, spp, target, replicates, seed, max_depth, variant or None, out_dir)

    mincam = _world_mincam(raw, base)
    world = _table("[world]", raw["world"])
    sub = {k: world.pop(k) for k in ("object", "light", "mover", "camera") if k in world}
    w = _check_keys("world", world, _defaults("world"))
    files: list[Path] = []
    scene_file = None
    if w["scene"]:
        scene_file = _path("world", "scene", w["scene"], base)
        if not scene_file.is_file():
            raise ConfigError(f"[world] scene: {scene_file} does not exist (relative paths are taken from the "
                              "config's folder)")
        files.append(scene_file)
        files.extend(referenced_files(scene_file))
    up = _choice("world", "up", w["up"], UP_AXES)
    rate = _number("world", "frame_rate_hz", w["frame_rate_hz"], positive=True)
    background = _choice("world", "background", w["background"], ("without_movers", "as_built", "first_frame"))
    objects = [_object(i, t, base, files) for i, t in enumerate(_array("world.object", sub.get("object", [])))]
    lights = [_light(i, t) for i, t in enumerate(_array("world.light", sub.get("light", [])))]
    if scene_file is None and not objects:
        raise ConfigError("[world] needs a scene = \"file.xml\" or at least one [[world.object]]")
    ids = [o.id for o in objects] + [light.id for light in lights]
    dupes = sorted({i for i in ids if ids.count(i) > 1})
    if dupes:
        raise ConfigError(f"[world] ids {dupes} are used twice; every object and light needs its own id")
    movers = [_mover(i, t, base, rate, files) for i, t in enumerate(_array("world.mover", sub.get("mover", [])))]
    if not movers:
        raise ConfigError("[world] needs at least one [[world.mover]] (id = a shape, offsets_m = one per frame)")
    counts = {m.id: len(m.offsets_m) for m in movers}
    if len(set(counts.values())) != 1:
        raise ConfigError(f"[[world.mover]] frame counts differ: {counts}; every mover needs one offset per frame")
    names = [m.id for m in movers]
    if len(set(names)) != len(names):
        raise ConfigError(f"[[world.mover]] ids {names}: each shape can move in one mover table only")
    camera = _camera(sub["camera"]) if "camera" in sub else None
    return WorldConfig(run_cfg, mincam, scene_file, up, rate, background, objects, lights, movers, camera,
                       raw, path, files)


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


def _array(where: str, value: Any) -> list:
    if isinstance(value, dict):
        raise ConfigError(f"[[{where}]] entries are an array of tables (double brackets), not a single [{where}]")
    if not isinstance(value, list):
        raise ConfigError(f"[[{where}]] must be an array of tables, got {_describe(value)}")
    return [_table(f"[[{where}]] #{i + 1}", t) for i, t in enumerate(value)]


def _id(where: str, value: Any) -> str:
    if value is None:
        raise ConfigError(f"{where}: id is required (the name movers and parameters use)")
    text = _string(where, "id", value)
    if not text or "." in text or text.strip() != text:
        raise ConfigError(f"{where}: id {text!r} must be a non-empty name without '.' or surrounding spaces")
    return text


def _world_mincam(raw: dict, base: Path) -> Mincam:
    tables = raw.get("mixel", [])
    if isinstance(tables, dict) or not isinstance(tables, list):
        raise ConfigError("mixels are given as [[mixel]] tables (an array of tables, double brackets)")
    for i, table in enumerate(tables):
        _table(f"[[mixel]] #{i + 1}", table)
    m = _check_keys("mincam", raw.get("mincam", {}), _mincam_defaults())
    centre = {k: m.pop(k) for k in ("position_m", "forward", "up")}
    mincam = _build_mincam(m, tables, base)
    if m["layout"] == "custom":
        return mincam
    position = np.array(_vector("mincam", "position_m", centre["position_m"], 3))
    forward = np.array(_vector("mincam", "forward", centre["forward"], 3))
    up = np.array(_vector("mincam", "up", centre["up"], 3))
    if np.linalg.norm(forward) == 0 or np.linalg.norm(np.cross(forward, up)) < 1e-9:
        raise ConfigError("[mincam] forward must be non-zero and up must not be parallel to it")
    target = Pose(tuple(position), tuple(forward), tuple(up)).matrix()
    default = Pose((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)).matrix()
    rot = target[:3, :3] @ default[:3, :3].T
    mixels = tuple(mx.with_pose(Pose(tuple(rot @ np.asarray(mx.pose.position_m) + position),
                                     tuple(rot @ np.asarray(mx.pose.forward)), tuple(rot @ np.asarray(mx.pose.up))))
                   for mx in mincam)
    return Mincam(mixels, allow_overlap=mincam.allow_overlap)


def _object(i: int, table: dict, base: Path, files: list[Path]) -> WorldObject:
    where = f"[[world.object]] #{i + 1}"
    t = _check_keys(where, table, _OBJECT_KEYS)
    oid = _id(where, t["id"])
    if t["mesh"] is None:
        raise ConfigError(f"{where} ({oid}): mesh is required (a mesh file: OBJ, PLY, STL, glTF/GLB)")
    mesh = _path(where, "mesh", t["mesh"], base)
    if not mesh.is_file():
        raise ConfigError(f"{where} ({oid}): mesh file {mesh} does not exist (relative to the config's folder)")
    files.append(mesh)
    albedo = _number(where, "albedo", t["albedo"], minimum=0.0)
    if albedo > 1:
        raise ConfigError(f"{where} ({oid}): albedo must lie in [0, 1], got {albedo}")
    return WorldObject(oid, mesh, albedo, _vector(where, "position_m", t["position_m"], 3),
                       _vector(where, "rotation_deg", t["rotation_deg"], 3),
                       _number(where, "scale", t["scale"], positive=True))


def _light(i: int, table: dict) -> WorldLight:
    where = f"[[world.light]] #{i + 1}"
    t = _check_keys(where, table, _LIGHT_KEYS)
    lid = _id(where, t["id"])
    if t["kind"] is None:
        raise ConfigError(f"{where} ({lid}): kind is required: one of {', '.join(LIGHT_KINDS)}")
    kind = _choice(where, "kind", t["kind"], LIGHT_KINDS)
    forward = _vector(where, "forward", t["forward"], 3)
    if np.linalg.norm(forward) == 0:
        raise ConfigError(f"{where} ({lid}): forward must be a non-zero direction")
    size = _vector(where, "size_m", t["size_m"], 2)
    if min(size) <= 0:
        raise ConfigError(f"{where} ({lid}): size_m must be two positive lengths, got {list(size)}")
    cutoff = _number(where, "cutoff_deg", t["cutoff_deg"], positive=True)
    if cutoff >= 90:
        raise ConfigError(f"{where} ({lid}): cutoff_deg must be below 90, got {cutoff}")
    return WorldLight(lid, kind, _vector(where, "position_m", t["position_m"], 3), forward, size,
                      _number(where, "radiance_w_m2_sr", t["radiance_w_m2_sr"], minimum=0.0),
                      _number(where, "intensity_w_sr", t["intensity_w_sr"], minimum=0.0), cutoff)


def _rows(where: str, key: str, value: Any, width: int) -> np.ndarray:
    if not isinstance(value, list) or not value:
        raise ConfigError(f"{where}: {key} must be a non-empty list of [x, y, z] rows, got {_describe(value)}")
    rows = [_vector(where, f"{key}[{j}]", row, width) for j, row in enumerate(value)]
    arr = np.array(rows, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"{where}: {key} holds NaN or infinite values; give finite numbers")
    return arr


def _mover(i: int, table: dict, base: Path, rate: float, files: list[Path]) -> Mover:
    where = f"[[world.mover]] #{i + 1}"
    t = _check_keys(where, table, _MOVER_KEYS)
    mid = _id(where, t["id"])
    where = f"{where} ({mid})"
    given = [k for k in ("offsets_m", "keyframes_m", "csv") if t[k] is not None]
    if len(given) != 1:
        raise ConfigError(f"{where}: give exactly one of offsets_m, keyframes_m (with times_s) or csv; got "
                          f"{given or 'none'}")
    if t["offsets_m"] is not None:
        offsets = _rows(where, "offsets_m", t["offsets_m"], 3)
    elif t["keyframes_m"] is not None:
        keys = _rows(where, "keyframes_m", t["keyframes_m"], 3)
        offsets = _sample_keyframes(where, t["times_s"], keys, rate)
    else:
        csv_path = _path(where, "csv", t["csv"], base)
        files.append(csv_path)
        times, keys = _read_trajectory_csv(where, csv_path)
        offsets = _sample_keyframes(where, times, keys, rate)
    if len(offsets) > MAX_WORLD_FRAMES:
        raise ConfigError(f"{where}: {len(offsets)} frames is more than {MAX_WORLD_FRAMES}")
    rotations = None
    if t["rotations_deg"] is not None:
        rotations = _rows(where, "rotations_deg", t["rotations_deg"], 3)
        if len(rotations) != len(offsets):
            raise ConfigError(f"{where}: rotations_deg has {len(rotations)} rows but there are {len(offsets)} frames")
    return Mover(mid, offsets, rotations)


def _sample_keyframes(where: str, times: Any, keys: np.ndarray, rate: float) -> np.ndarray:
    if times is None:
        raise ConfigError(f"{where}: keyframes_m needs times_s (one time per keyframe, seconds, increasing)")
    if not isinstance(times, (list, np.ndarray)) or len(times) != len(keys):
        raise ConfigError(f"{where}: times_s must list one time per keyframe ({len(keys)}), got {_describe(times)}")
    t = np.array([_number(where, f"times_s[{j}]", v) for j, v in enumerate(times)], dtype=float)
    if len(t) < 2 or np.any(np.diff(t) <= 0):
        raise ConfigError(f"{where}: times_s must hold at least two increasing times, got {t.tolist()}")
    frames = np.arange(t[0], t[-1] + 0.5 / rate, 1.0 / rate)
    frames = frames[frames <= t[-1] + 1e-12]
    return np.stack([np.interp(frames, t, keys[:, k]) for k in range(3)], axis=1)


def _read_trajectory_csv(where: str, path: Path) -> tuple[np.ndarray, np.ndarray]:
    if not path.is_file():
        raise ConfigError(f"{where}: csv file {path} does not exist")
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


def _camera(table: Any) -> CameraSpec:
    where = "[world.camera]"
    t = _check_keys("world.camera", _table(where, table), _CAMERA_KEYS)
    for key in ("position_m", "look_at_m"):
        if t[key] is None:
            raise ConfigError(f"{where}: {key} is required")
    position = _vector(where, "position_m", t["position_m"], 3)
    look = _vector(where, "look_at_m", t["look_at_m"], 3)
    if np.allclose(position, look):
        raise ConfigError(f"{where}: look_at_m must differ from position_m")
    fov = _number(where, "fov_deg", t["fov_deg"], positive=True)
    if fov >= 180:
        raise ConfigError(f"{where}: fov_deg must be below 180, got {fov}")
    threshold = _number(where, "threshold", t["threshold"], positive=True)
    return CameraSpec(position, look, _vector(where, "up", t["up"], 3), fov,
                      _integer(where, "width_px", t["width_px"], maximum=8192),
                      _integer(where, "height_px", t["height_px"], maximum=8192),
                      _integer(where, "spp", t["spp"], maximum=1 << 20), threshold)
