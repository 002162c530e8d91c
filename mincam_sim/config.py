"""TOML configuration of a render: schema, defaults, validation (pure Python/numpy).

Every key carries its unit in its name (``_m`` metres, ``_rad`` radians, ``_w_m2_sr`` radiance ...). Unknown
keys or names are errors that list what is allowed. The documented schema with every default is
:data:`EXAMPLE_TOML` (also printed by ``mincam-sim config-example``).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from . import masks as masks_mod
from .geometry import Pose
from .masks import Mask
from .optics import DEFAULT_D_F_M, DEFAULT_DETECTOR_SIZE_M, PAPER_SPACING_M, Mincam, Mixel, layout
from .screen import Screen, Sweep, diagonal_to_size, grid_sweep, line_sweep

EXAMPLE_TOML = """\
# mincam-sim render configuration. Units are in the key names: _m metres, _in inches, _deg degrees,
# _rad_per_m radians per metre, _w_m2_sr radiance (W m^-2 sr^-1).

[run]
form = "response_map"      # "response_map" (fast, display scenes), "fast" (mixel-sensor plugin), "reference"
spp = 65536                # samples per mixel per frame ("fast"/"reference")
samples_per_texel = 64     # samples per display texel per mixel ("response_map")
target_rel_stderr = 0.0    # > 0: pick samples automatically to reach this relative standard error
replicates = 8             # independent estimates per value, for the standard error
seed = 0                   # same seed, same numbers
variant = ""               # "" = automatic (cuda_ad_mono > llvm_ad_mono > scalar_rgb)
out_dir = "out/render"     # measurements.npz / .csv (+ response maps as OpenEXR) are written here

[mincam]
layout = "pair"            # "pair" (x | 1-x), "cross" (x, 1-x, y, 1-y around a centre), "custom" ([[mixel]] below)
spacing_m = 0.033          # distance between neighbouring mixels (paper: 3.3 cm)
d_f_m = 0.002              # mask-to-detector distance
detector_size_m = 0.0001   # side of the square detector (paper: 48x48 pixels ~ 0.1 mm)
mask_size_m = 0.002        # side of the square mask (aperture)
mask_resolution = 256      # texels per side of generated masks

# For layout = "custom", one table per mixel:
# [[mixel]]
# name = "left"
# mask = "ramp:x"          # "ramp:x|1-x|y|1-y", "constant:<t>", "file:<path.png|.exr>", or a table:
#                          # {kind = "sinusoid", omega_rad_per_m = 15708.0, a0 = 0.5, a1 = 0.5, phase_rad = 0.0,
#                          #  direction_deg = 0.0}
# position_m = [-0.0165, 0.0, 0.0]
# forward = [0.0, 0.0, -1.0]
# up = [0.0, 1.0, 0.0]

[screen]
diagonal_in = 50.0         # display diagonal (paper: 50")
aspect = [16, 9]
resolution = [256, 144]    # display texels (columns, rows)
distance_m = 0.5           # from the mincam plane (z = 0) to the screen, which faces the mincam

[frames]
kind = "line_sweep"        # "line_sweep", "grid_sweep" or "npy" (a (n, rows, cols) radiance array file)
start_m = [-0.25, 0.0]     # line_sweep: first square centre, screen coordinates (x right, y up)
end_m = [0.25, 0.0]        # line_sweep: last square centre
n = 26                     # line_sweep: number of positions
x_range_m = [-0.2, 0.2]    # grid_sweep
y_range_m = [-0.2, 0.2]    # grid_sweep
nx = 9                     # grid_sweep
ny = 9                     # grid_sweep
square_m = 0.03            # side of the white square
radiance_w_m2_sr = 1.0     # radiance of the white square (black elsewhere)
background_w_m2_sr = 0.0   # radiance of the rest of the screen
path = ""                  # npy: path of the frame stack
"""

_SCHEMA: dict[str, dict[str, Any]] = {
    "run": {
        "form": "response_map", "spp": 65536, "samples_per_texel": 64, "target_rel_stderr": 0.0,
        "replicates": 8, "seed": 0, "variant": "", "out_dir": "out/render",
    },
    "mincam": {
        "layout": "pair", "spacing_m": PAPER_SPACING_M, "d_f_m": DEFAULT_D_F_M,
        "detector_size_m": DEFAULT_DETECTOR_SIZE_M, "mask_size_m": masks_mod.DEFAULT_MASK_SIZE_M,
        "mask_resolution": masks_mod.DEFAULT_RESOLUTION,
    },
    "screen": {"diagonal_in": 50.0, "aspect": [16, 9], "resolution": [256, 144], "distance_m": 0.5},
    "frames": {
        "kind": "line_sweep", "start_m": [-0.25, 0.0], "end_m": [0.25, 0.0], "n": 26,
        "x_range_m": [-0.2, 0.2], "y_range_m": [-0.2, 0.2], "nx": 9, "ny": 9, "square_m": 0.03,
        "radiance_w_m2_sr": 1.0, "background_w_m2_sr": 0.0, "path": "",
    },
}
_MIXEL_KEYS = {"name": None, "mask": None, "position_m": [0.0, 0.0, 0.0], "forward": [0.0, 0.0, -1.0],
               "up": [0.0, 1.0, 0.0], "d_f_m": None, "detector_size_m": None}
_FORMS = ("response_map", "fast", "reference")
_LAYOUTS = ("pair", "cross", "custom")
_FRAME_KINDS = ("line_sweep", "grid_sweep", "npy")


class ConfigError(ValueError):
    """A configuration value is missing, unknown or out of range; the message says which and how to fix it."""


def _check_keys(section: str, given: dict, allowed: dict) -> dict:
    unknown = sorted(set(given) - set(allowed))
    if unknown:
        raise ConfigError(
            f"[{section}]: unknown key(s) {', '.join(unknown)}; allowed keys are {', '.join(sorted(allowed))}"
        )
    return {**allowed, **given}


def _positive(section: str, key: str, value, integer: bool = False, allow_zero: bool = False):
    ok_type = isinstance(value, int) if integer else isinstance(value, int | float)
    if isinstance(value, bool) or not ok_type or not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        kind = "an integer" if integer else "a number"
        bound = ">= 0" if allow_zero else "> 0"
        raise ConfigError(f"[{section}] {key} must be {kind} {bound}, got {value!r}")
    return value


def _choice(section: str, key: str, value, choices) -> str:
    if value not in choices:
        raise ConfigError(f"[{section}] {key} = {value!r} is not one of {', '.join(map(repr, choices))}")
    return value


def _vector(section: str, key: str, value, n: int) -> tuple[float, ...]:
    if not isinstance(value, list | tuple) or len(value) != n or not all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in value
    ):
        raise ConfigError(f"[{section}] {key} must be a list of {n} numbers, got {value!r}")
    return tuple(float(v) for v in value)


@dataclass
class RunConfig:
    form: str
    spp: int
    samples_per_texel: int
    target_rel_stderr: float
    replicates: int
    seed: int
    variant: str | None
    out_dir: Path


@dataclass
class RenderConfig:
    """A validated configuration: run settings, the mincam, the screen and the frames."""

    run: RunConfig
    mincam: Mincam
    screen: Screen
    frames: np.ndarray
    frame_positions_m: np.ndarray | None
    raw: dict


def parse_mask(spec, size_m: float, resolution: int, where: str) -> Mask:
    """A mask from a config value: ``"ramp:x"``, ``"constant:0.5"``, ``"file:path"`` or a table."""
    if isinstance(spec, str):
        kind, _, arg = spec.partition(":")
        if kind == "ramp":
            try:
                return masks_mod.ramp(arg, resolution, size_m)
            except ValueError as err:
                raise ConfigError(f"{where}: {err}") from None
        if kind == "constant":
            try:
                return masks_mod.constant(float(arg or 1.0), 1, size_m)
            except ValueError as err:
                raise ConfigError(f"{where}: constant mask needs a transmission in [0, 1]: {err}") from None
        if kind == "file":
            try:
                return masks_mod.load(arg, size_m, size_m)
            except (OSError, ValueError) as err:
                raise ConfigError(f"{where}: {err}") from None
        raise ConfigError(
            f"{where}: mask {spec!r} not understood; use 'ramp:x|1-x|y|1-y', 'constant:<t>', 'file:<path>' or a "
            "table {kind = \"sinusoid\", omega_rad_per_m = ...}"
        )
    if isinstance(spec, dict):
        spec = dict(spec)
        kind = spec.pop("kind", None)
        if kind != "sinusoid":
            raise ConfigError(f"{where}: mask tables support kind = \"sinusoid\" (got {kind!r})")
        allowed = {"omega_rad_per_m", "a0", "a1", "phase_rad", "direction_deg"}
        unknown = sorted(set(spec) - allowed)
        if unknown:
            raise ConfigError(f"{where}: unknown sinusoid key(s) {unknown}; allowed: {sorted(allowed)}")
        if "omega_rad_per_m" not in spec:
            raise ConfigError(f"{where}: a sinusoid mask needs omega_rad_per_m (angular frequency on the mask)")
        try:
            return masks_mod.sinusoid(resolution=resolution, width_m=size_m, **spec)
        except (TypeError, ValueError) as err:
            raise ConfigError(f"{where}: {err}") from None
    raise ConfigError(f"{where}: mask must be a string or a table, got {spec!r}")


def _build_mincam(cfg: dict, mixel_tables: list[dict]) -> Mincam:
    m = cfg
    for key in ("spacing_m",):
        _positive("mincam", key, m[key], allow_zero=True)
    for key in ("d_f_m", "detector_size_m", "mask_size_m"):
        _positive("mincam", key, m[key])
    _positive("mincam", "mask_resolution", m["mask_resolution"], integer=True)
    kind = _choice("mincam", "layout", m["layout"], _LAYOUTS)
    common = {"d_f_m": m["d_f_m"], "detector_size_m": m["detector_size_m"]}
    res, size, s = m["mask_resolution"], m["mask_size_m"], m["spacing_m"]
    if kind != "custom" and mixel_tables:
        raise ConfigError("[[mixel]] tables are only used with [mincam] layout = \"custom\"")
    try:
        if kind == "pair":
            return layout([masks_mod.ramp("x", res, size), masks_mod.ramp("1-x", res, size)],
                          [(-s / 2, 0.0), (s / 2, 0.0)], ["x", "1-x"], **common)
        if kind == "cross":
            return layout([masks_mod.ramp(k, res, size) for k in ("x", "1-x", "y", "1-y")],
                          [(-s, 0.0), (s, 0.0), (0.0, s), (0.0, -s)], ["x", "1-x", "y", "1-y"], **common)
    except ValueError as err:
        raise ConfigError(f"[mincam]: {err}") from None
    if not mixel_tables:
        raise ConfigError("[mincam] layout = \"custom\" needs at least one [[mixel]] table")
    mixels = []
    for i, table in enumerate(mixel_tables):
        where = f"[[mixel]] #{i + 1}"
        t = _check_keys(where, table, _MIXEL_KEYS)
        if t["mask"] is None:
            raise ConfigError(f"{where}: mask is required (e.g. mask = \"ramp:x\")")
        mask = parse_mask(t["mask"], size, res, where)
        try:
            pose = Pose(_vector(where, "position_m", t["position_m"], 3), _vector(where, "forward", t["forward"], 3),
                        _vector(where, "up", t["up"], 3))
            mixels.append(Mixel(
                mask,
                t["d_f_m"] if t["d_f_m"] is not None else m["d_f_m"],
                t["detector_size_m"] if t["detector_size_m"] is not None else m["detector_size_m"],
                pose,
                t["name"] or f"m{i}",
            ))
        except ValueError as err:
            raise ConfigError(f"{where}: {err}") from None
    try:
        return Mincam(tuple(mixels))
    except ValueError as err:
        raise ConfigError(f"[[mixel]]: {err}") from None


def _build_screen(cfg: dict) -> Screen:
    _positive("screen", "diagonal_in", cfg["diagonal_in"])
    _positive("screen", "distance_m", cfg["distance_m"])
    aspect = _vector("screen", "aspect", cfg["aspect"], 2)
    res = _vector("screen", "resolution", cfg["resolution"], 2)
    if any(a <= 0 for a in aspect):
        raise ConfigError(f"[screen] aspect must be two positive numbers, got {cfg['aspect']!r}")
    width, height = diagonal_to_size(cfg["diagonal_in"], aspect)
    try:
        return Screen(width, height, (int(res[0]), int(res[1])),
                      Pose((0.0, 0.0, -cfg["distance_m"]), (0.0, 0.0, 1.0)))
    except ValueError as err:
        raise ConfigError(f"[screen]: {err}") from None


def _build_frames(cfg: dict, screen: Screen, base: Path) -> tuple[np.ndarray, np.ndarray | None]:
    kind = _choice("frames", "kind", cfg["kind"], _FRAME_KINDS)
    if kind == "npy":
        path = Path(cfg["path"])
        path = path if path.is_absolute() else base / path
        if not cfg["path"] or not path.is_file():
            raise ConfigError(f"[frames] path {str(path)!r} is not a file; give a .npy of shape (n, rows, cols)")
        frames = np.load(path)
        if frames.ndim == 2:
            frames = frames[None]
        for i, f in enumerate(frames):
            try:
                screen.check_frame(f, f"frame {i} of {path}")
            except ValueError as err:
                raise ConfigError(f"[frames]: {err}") from None
        return frames.astype(np.float64), None
    _positive("frames", "square_m", cfg["square_m"])
    _positive("frames", "radiance_w_m2_sr", cfg["radiance_w_m2_sr"])
    _positive("frames", "background_w_m2_sr", cfg["background_w_m2_sr"], allow_zero=True)
    sweep: Sweep
    if kind == "line_sweep":
        _positive("frames", "n", cfg["n"], integer=True)
        sweep = line_sweep(_vector("frames", "start_m", cfg["start_m"], 2), _vector("frames", "end_m", cfg["end_m"], 2),
                           cfg["n"], cfg["square_m"], cfg["radiance_w_m2_sr"])
    else:
        _positive("frames", "nx", cfg["nx"], integer=True)
        _positive("frames", "ny", cfg["ny"], integer=True)
        sweep = grid_sweep(_vector("frames", "x_range_m", cfg["x_range_m"], 2),
                           _vector("frames", "y_range_m", cfg["y_range_m"], 2), cfg["nx"], cfg["ny"],
                           cfg["square_m"], cfg["radiance_w_m2_sr"])
    return sweep.frame_stack(screen) + cfg["background_w_m2_sr"], sweep.positions_m


def load_config(source: str | Path | dict, base_dir: str | Path | None = None) -> RenderConfig:
    """Parse and validate a TOML file (path), TOML text, or an already-parsed dict."""
    if isinstance(source, dict):
        raw, base = source, Path(base_dir or ".")
    else:
        text_or_path = str(source)
        path = Path(text_or_path)
        if "\n" not in text_or_path and path.suffix == ".toml":
            if not path.is_file():
                raise ConfigError(f"config file {path} does not exist")
            text, base = path.read_text(), path.parent
        else:
            text, base = text_or_path, Path(base_dir or ".")
        try:
            raw = tomllib.loads(text)
        except tomllib.TOMLDecodeError as err:
            raise ConfigError(f"config is not valid TOML: {err}") from None
    unknown = sorted(set(raw) - set(_SCHEMA) - {"mixel"})
    if unknown:
        raise ConfigError(f"unknown section(s) {unknown}; allowed: {sorted(_SCHEMA)} and [[mixel]]")
    sections = {name: _check_keys(name, raw.get(name, {}), defaults) for name, defaults in _SCHEMA.items()}
    run = sections["run"]
    _choice("run", "form", run["form"], _FORMS)
    _positive("run", "spp", run["spp"], integer=True)
    _positive("run", "samples_per_texel", run["samples_per_texel"], integer=True)
    _positive("run", "target_rel_stderr", run["target_rel_stderr"], allow_zero=True)
    _positive("run", "replicates", run["replicates"], integer=True)
    if run["replicates"] < 2:
        raise ConfigError("[run] replicates must be >= 2 (the standard error needs two estimates)")
    if not isinstance(run["seed"], int) or run["seed"] < 0:
        raise ConfigError(f"[run] seed must be an integer >= 0, got {run['seed']!r}")
    if run["variant"] not in ("", "cuda_ad_mono", "llvm_ad_mono", "scalar_rgb"):
        raise ConfigError(f"[run] variant {run['variant']!r}: use '', 'cuda_ad_mono', 'llvm_ad_mono' or 'scalar_rgb'")
    tables = raw.get("mixel", [])
    if not isinstance(tables, list):
        raise ConfigError("mixels are given as [[mixel]] tables (an array of tables)")
    mincam = _build_mincam(sections["mincam"], tables)
    screen = _build_screen(sections["screen"])
    frames, positions = _build_frames(sections["frames"], screen, base)
    out_dir = Path(run["out_dir"])
    run_cfg = RunConfig(run["form"], run["spp"], run["samples_per_texel"], float(run["target_rel_stderr"]),
                        run["replicates"], run["seed"], run["variant"] or None,
                        out_dir if out_dir.is_absolute() else base / out_dir)
    return RenderConfig(run_cfg, mincam, screen, frames, positions, {**sections, "mixel": tables})
