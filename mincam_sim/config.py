"""TOML configuration of a render: schema, defaults, validation (pure Python/numpy).

Every key carries its unit in its name (``_m`` metres, ``_rad`` radians, ``_w_m2_sr`` radiance ...). Unknown
keys or names are errors that list what is allowed. The documented schema with every default is
:data:`EXAMPLE_TOML` (also printed by ``mincam-sim config-example``).

Every problem with a document raises :class:`~mincam_sim.errors.ConfigError` (a ``ValueError``) naming the
field and the fix -- never a ``TypeError`` or ``KeyError``. Relative paths (``[run] out_dir``, ``[frames] path``
and ``file:`` masks) resolve against the config file's directory.
"""

from __future__ import annotations

import dataclasses
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from . import masks as masks_mod
from .errors import ConfigError
from .geometry import Pose
from .masks import Mask
from .optics import (
    DEFAULT_D_F_M,
    DEFAULT_DETECTOR_SIZE_M,
    PAPER_SPACING_M,
    Mincam,
    Mixel,
    cross_layout,
    pair_layout,
)
from .scene.display import (
    DEFAULT_SCREEN_RESOLUTION,
    FrameSource,
    Screen,
    Sweep,
    check_visible,
    diagonal_to_size,
    grid_sweep,
    line_sweep,
)

EXAMPLE_TOML = """\
# mincam-sim render configuration. Units are in the key names: _m metres, _in inches, _deg degrees,
# _rad_per_m radians per metre, _w_m2_sr radiance (W m^-2 sr^-1).

[run]
form = "response_map"      # "response_map" (fast, display scenes), "fast" (mixel-sensor plugin), "reference"
spp = 65536                # samples per mixel per frame ("fast"/"reference"); rounded UP to a multiple of
                           # replicates (65536 with 8 replicates runs exactly)
samples_per_texel = 64     # samples per display texel per mixel ("response_map"): traced as replicates x k^2
                           # stratified samples, k = floor(sqrt(samples_per_texel / replicates)), i.e. rounded
                           # DOWN: 64 with 8 replicates traces 32 (8 x 2^2); 72 (8 x 3^2) and 128 (8 x 4^2) run
                           # exactly. `render` prints the count it traces when it differs from the one asked.
target_rel_stderr = 0.0    # > 0: pick samples automatically to reach this relative standard error
replicates = 8             # independent estimates per value, for the standard error
seed = 0                   # same seed, same numbers
variant = ""               # "" = automatic (cuda_ad_mono > llvm_ad_mono > scalar_rgb)
out_dir = "out/render"     # measurements.npz / .csv (+ response maps as OpenEXR); relative to this file

[mincam]
layout = "pair"            # "pair" (x | 1-x), "cross" (x, 1-x, y, 1-y around a centre), "custom" ([[mixel]] below)
spacing_m = 0.033          # distance between neighbouring mixels (paper: 3.3 cm)
d_f_m = 0.002              # mask-to-detector distance
detector_size_m = 0.0001   # side of the square detector (paper: 48x48 pixels ~ 0.1 mm)
mask_size_m = 0.002        # side of the square mask (aperture)
mask_resolution = 256      # texels per side of generated masks
mask_encoding = "linear"   # how file: PNG values map to transmission: "linear" (value/255 is the transmission;
                           # 128 passes 50 %) or "srgb" (sRGB-encoded, as image editors save; 128 passes 22 %)
optics = "geometric"       # "geometric" (rays) or "wave" (each mixel's scalar-wave angular response, see README)
wavelengths_m = [550e-9]   # wavelengths of the wave response, weighted by a silicon QE curve ("wave" only)

# For layout = "custom", one table per mixel:
# [[mixel]]
# name = "left"
# mask = "ramp:x"          # "ramp:x|1-x|y|1-y", "constant:<t>", "file:<path.png|.exr>" (relative to this
#                          # file), or a table:
#                          # {kind = "sinusoid", omega_rad_per_m = 15708.0, a0 = 0.5, a1 = 0.5, phase_rad = 0.0,
#                          #  direction_deg = 0.0}
# optics = "wave"          # optional: overrides [mincam] optics for this mixel
# mask_size_m = 0.002      # optional: this mixel's mask, one side (square) or [width, height] in metres; a
#                          # file: image must have the mask's aspect ratio (a non-square image needs
#                          # [width, height]; nothing is stretched)
# mask_encoding = "srgb"   # optional: overrides [mincam] mask_encoding for this mixel's file: PNG
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
path = ""                  # npy: path of the frame stack (relative to this file)
"""

_SCHEMA: dict[str, dict[str, Any]] = {
    "run": {
        "form": "response_map", "spp": 65536, "samples_per_texel": 64, "target_rel_stderr": 0.0,
        "replicates": 8, "seed": 0, "variant": "", "out_dir": "out/render",
    },
    "mincam": {
        "layout": "pair", "spacing_m": PAPER_SPACING_M, "d_f_m": DEFAULT_D_F_M,
        "detector_size_m": DEFAULT_DETECTOR_SIZE_M, "mask_size_m": masks_mod.DEFAULT_MASK_SIZE_M,
        "mask_resolution": masks_mod.DEFAULT_RESOLUTION, "mask_encoding": "linear", "optics": "geometric",
        "wavelengths_m": [550e-9],
    },
    "screen": {"diagonal_in": 50.0, "aspect": [16, 9], "resolution": list(DEFAULT_SCREEN_RESOLUTION),
               "distance_m": 0.5},
    "frames": {
        "kind": "line_sweep", "start_m": [-0.25, 0.0], "end_m": [0.25, 0.0], "n": 26,
        "x_range_m": [-0.2, 0.2], "y_range_m": [-0.2, 0.2], "nx": 9, "ny": 9, "square_m": 0.03,
        "radiance_w_m2_sr": 1.0, "background_w_m2_sr": 0.0, "path": "",
    },
}
_MIXEL_KEYS = {"name": None, "mask": None, "position_m": [0.0, 0.0, 0.0], "forward": [0.0, 0.0, -1.0],
               "up": [0.0, 1.0, 0.0], "d_f_m": None, "detector_size_m": None, "optics": None, "mask_size_m": None,
               "mask_encoding": None}
_SINUSOID_KEYS = {"omega_rad_per_m": None, "a0": 0.5, "a1": 0.5, "phase_rad": 0.0, "direction_deg": 0.0}
MAX_FRAMES = 10_000_000  # frames stream through the renderer; this bounds run time and the result files
_FORMS = ("response_map", "fast", "reference")
_OPTICS = ("geometric", "wave")
_ENCODINGS = ("linear", "srgb")
_LAYOUTS = ("pair", "cross", "custom")
_FRAME_KINDS = ("line_sweep", "grid_sweep", "npy")
_VARIANTS = ("", "cuda_ad_mono", "llvm_ad_mono", "scalar_rgb")

MAX_MASK_RESOLUTION = 8192  # texels per side (masks.MAX_TEXELS = 8192^2)
MAX_SCREEN_TEXELS = 4096 * 4096  # Screen's own limit
MAX_REPLICATES = 4096
MAX_INT = 2**63 - 1


def _describe(value: Any) -> str:
    """Short repr of a config value for messages (with its TOML type)."""
    kind = {bool: "boolean", int: "integer", float: "number", str: "string", list: "array", dict: "table",
            tuple: "array"}.get(type(value), type(value).__name__)
    text = repr(value)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{text} ({kind})"


def _table(where: str, value: Any) -> dict:
    if not isinstance(value, dict):
        raise ConfigError(f"{where} must be a table (a [section] with key = value lines), got {_describe(value)}")
    bad = [k for k in value if not isinstance(k, str)]
    if bad:
        raise ConfigError(f"{where}: keys must be strings, got {bad[0]!r}")
    return value


def _check_keys(section: str, given: Any, allowed: dict) -> dict:
    given = _table(f"[{section}]" if not section.startswith("[") else section, given)
    unknown = sorted(set(given) - set(allowed))
    if unknown:
        where = section if section.startswith("[") else f"[{section}]"
        raise ConfigError(
            f"{where}: unknown key(s) {', '.join(unknown)}; allowed keys are {', '.join(sorted(allowed))}"
        )
    return {**allowed, **given}


def _where(section: str, key: str) -> str:
    return f"{section} {key}" if section.startswith("[") else f"[{section}] {key}"


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _number(section: str, key: str, value: Any, *, minimum: float | None = None, positive: bool = False) -> float:
    """A finite real number (not a boolean, not a string); ``positive``: > 0; ``minimum``: >= minimum."""
    if not _is_number(value) or (isinstance(value, float) and not np.isfinite(value)):
        bound = " > 0" if positive else (f" >= {minimum:g}" if minimum is not None else "")
        raise ConfigError(f"{_where(section, key)} must be a number{bound} (no quotes, no units), got "
                          f"{_describe(value)}")
    if positive and not value > 0:
        raise ConfigError(f"{_where(section, key)} must be a number > 0, got {value!r}")
    if minimum is not None and not value >= minimum:
        raise ConfigError(f"{_where(section, key)} must be a number >= {minimum:g}, got {value!r}")
    return float(value)


def _integer(section: str, key: str, value: Any, *, minimum: int = 1, maximum: int = MAX_INT) -> int:
    """An integer in [minimum, maximum]; booleans and fractional numbers are refused, not converted."""
    if isinstance(value, bool) or not isinstance(value, int):
        hint = " (a whole number, no decimal point)" if isinstance(value, float) else ""
        bound = "> 0" if minimum == 1 else f">= {minimum}"
        raise ConfigError(f"{_where(section, key)} must be an integer {bound}{hint}, got {_describe(value)}")
    if value < minimum:
        bound = "> 0" if minimum == 1 else f">= {minimum}"
        raise ConfigError(f"{_where(section, key)} must be an integer {bound}, got {value!r}")
    if value > maximum:
        raise ConfigError(f"{_where(section, key)} must be at most {maximum}, got {value!r}")
    return int(value)


def _positive(section: str, key: str, value: Any, integer: bool = False, allow_zero: bool = False):
    """Backward-compatible helper: a positive (or >= 0) number or integer."""
    if integer:
        return _integer(section, key, value, minimum=0 if allow_zero else 1)
    return _number(section, key, value, minimum=0.0) if allow_zero else _number(section, key, value, positive=True)


def _string(section: str, key: str, value: Any) -> str:
    if not isinstance(value, str):
        raise ConfigError(f"{_where(section, key)} must be a string (in quotes), got {_describe(value)}")
    return value


def _choice(section: str, key: str, value: Any, choices: Sequence[str]) -> str:
    if not isinstance(value, str) or value not in choices:
        raise ConfigError(f"{_where(section, key)} = {value!r} is not one of {', '.join(map(repr, choices))}")
    return value


def _vector(section: str, key: str, value: Any, n: int) -> tuple[float, ...]:
    if not isinstance(value, list | tuple) or len(value) != n or not all(
        _is_number(v) and np.isfinite(v) for v in value
    ):
        raise ConfigError(f"{_where(section, key)} must be a list of {n} finite numbers, got {_describe(value)}")
    return tuple(float(v) for v in value)


def _int_pair(section: str, key: str, value: Any, maximum: int) -> tuple[int, int]:
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise ConfigError(f"{_where(section, key)} must be a list of two integers, got {_describe(value)}")
    return tuple(_integer(section, f"{key}[{i}]", v, maximum=maximum) for i, v in enumerate(value))  # type: ignore


def _path(section: str, key: str, value: Any, base: Path) -> Path:
    """A path string resolved against ``base`` (the config file's directory) unless absolute."""
    text = _string(section, key, value)
    if "\x00" in text:
        raise ConfigError(f"{_where(section, key)} contains a NUL character; give a plain file path")
    path = Path(text).expanduser()
    return path if path.is_absolute() else base / path


@dataclass
class RunConfig:
    """[run]: how to render. ``out_dir`` is resolved against the config file's directory."""

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
    source: Path | None = None
    frames_kind: str = "line_sweep"


def traced_samples(run: RunConfig) -> tuple[int, str | None]:
    """The sample count a fixed-budget run traces, and one line saying so when it is not the count asked.

    ``response_map`` traces ``replicates x k^2`` samples per texel with ``k = floor(sqrt(samples_per_texel /
    replicates))`` (stratified, rounded down); ``fast`` / ``reference`` trace ``replicates x ceil(spp /
    replicates)`` samples per mixel per frame (rounded up). With ``target_rel_stderr > 0`` the counts are chosen
    automatically and this returns the starting count and None.
    """
    if run.form == "response_map":
        k = max(1, int(np.sqrt(run.samples_per_texel / run.replicates)))
        traced = run.replicates * k * k
        if traced == run.samples_per_texel or run.target_rel_stderr > 0:
            return traced, None
        up = run.replicates * (k + 1) ** 2
        return traced, (f"[run] samples_per_texel = {run.samples_per_texel} traces {traced} samples per texel "
                        f"({run.replicates} replicates x {k}x{k} strata, rounded down); ask {traced} or {up} to "
                        "get exactly what runs")
    per = -(-run.spp // run.replicates)
    traced = run.replicates * per
    if traced == run.spp or run.target_rel_stderr > 0:
        return traced, None
    return traced, (f"[run] spp = {run.spp} traces {traced} samples per mixel per frame ({run.replicates} "
                    f"replicates x {per}, rounded up); give a multiple of replicates to get exactly what runs")


def parse_mask(spec: Any, size_m: float, resolution: int, where: str, base_dir: str | Path | None = None,
               height_m: float | None = None, encoding: str = "linear") -> Mask:
    """A mask from a config value: ``"ramp:x"``, ``"constant:0.5"``, ``"file:path"`` or a sinusoid table.

    Parameters
    ----------
    spec : str or dict
        The mask description.
    size_m : float
        Width of the mask [m] (its side, for a square mask).
    resolution : int
        Texels across the width of generated masks (rows follow the aspect ratio).
    where : str
        Named in error messages (``"[[mixel]] #2"``).
    base_dir : str or Path, optional
        Relative ``file:`` paths resolve against it (the config file's directory); default: the working
        directory.
    height_m : float, optional
        Height of the mask [m]; default ``size_m`` (square). A ``file:`` image must have the mask's aspect
        ratio (within 1 %): a non-square image with a square size, or any other mismatch, is refused rather than
        stretched.
    encoding : {"linear", "srgb"}
        How ``file:`` PNG values map to transmission: ``"linear"`` (value / 255 or / 65535 is the transmission)
        or ``"srgb"`` (values are sRGB-encoded, as image editors save them, and are decoded first).

    Raises
    ------
    ConfigError
        Naming ``where`` and how to fix the value.
    """
    width_m = size_m
    height = size_m if height_m is None else height_m
    res = (max(1, round(resolution * height / width_m)), resolution)
    if isinstance(spec, str):
        kind, _, arg = spec.partition(":")
        if kind == "ramp":
            try:
                return masks_mod.ramp(arg, res, width_m, height)
            except ValueError as err:
                raise ConfigError(f"{where}: {err}") from None
        if kind == "constant":
            try:
                value = float(arg) if arg.strip() else 1.0
            except ValueError:
                raise ConfigError(f"{where}: constant mask needs a transmission in [0, 1] like 'constant:0.5', "
                                  f"got {spec!r}") from None
            if not 0.0 <= value <= 1.0:
                raise ConfigError(f"{where}: constant mask needs a transmission in [0, 1], got {spec!r}")
            try:
                return masks_mod.constant(value, 1, width_m, height)
            except ValueError as err:
                raise ConfigError(f"{where}: {err}") from None
        if kind == "file":
            if not arg.strip():
                raise ConfigError(f"{where}: 'file:' needs a path, e.g. mask = \"file:masks/ramp_x.exr\"")
            if "\x00" in arg:
                raise ConfigError(f"{where}: mask file path contains a NUL character")
            path = Path(arg).expanduser()
            if not path.is_absolute() and base_dir is not None:
                path = Path(base_dir) / path
            if not path.is_file():
                rel = " (relative paths are relative to the config file)" if base_dir is not None else ""
                raise ConfigError(f"{where}: mask file {str(path)!r} does not exist or is not a file{rel}")
            try:
                mask = masks_mod.load(path, width_m, height, encoding=encoding)
            except Exception as err:  # a user's file: any failure to read it is a config error
                raise ConfigError(f"{where}: cannot use mask file {str(path)!r}: {err}") from None
            rows, cols = mask.shape
            if abs((cols / rows) / (width_m / height) - 1) > 0.01:
                fix = (f"give mask_size_m = [{width_m:g}, {width_m * rows / cols:.6g}] (width, height in metres) "
                       "in its [[mixel]] table" if height_m is None else "give mask_size_m with the image's aspect "
                       "ratio")
                raise ConfigError(f"{where}: mask file {str(path)!r} is {cols} x {rows} texels but the mask is "
                                  f"{1e3 * width_m:g} x {1e3 * height:g} mm; it would be stretched: {fix}, or "
                                  "use an image of the mask's shape")
            return mask
        raise ConfigError(
            f"{where}: mask {spec!r} not understood; use 'ramp:x|1-x|y|1-y', 'constant:<t>', 'file:<path>' or a "
            "table {kind = \"sinusoid\", omega_rad_per_m = ...}"
        )
    if isinstance(spec, dict):
        spec = dict(spec)
        kind = spec.pop("kind", None)
        if kind != "sinusoid":
            raise ConfigError(f"{where}: mask tables support kind = \"sinusoid\" (got {kind!r})")
        bad_keys = [k for k in spec if not isinstance(k, str)]
        unknown = sorted(str(k) for k in set(spec) - set(_SINUSOID_KEYS)) if not bad_keys else [repr(bad_keys[0])]
        if unknown:
            raise ConfigError(f"{where}: unknown sinusoid key(s) {unknown}; allowed: {sorted(_SINUSOID_KEYS)}")
        if "omega_rad_per_m" not in spec:
            raise ConfigError(f"{where}: a sinusoid mask needs omega_rad_per_m (angular frequency on the mask)")
        params = {**_SINUSOID_KEYS, **spec}
        section = f"{where} mask"
        values = {k: _number(section, k, v) for k, v in params.items()}
        _number(section, "omega_rad_per_m", params["omega_rad_per_m"], minimum=0.0)
        try:
            return masks_mod.sinusoid(resolution=res, width_m=width_m, height_m=height, **values)
        except (TypeError, ValueError) as err:
            raise ConfigError(f"{where}: {err}") from None
    raise ConfigError(f"{where}: mask must be a string like \"ramp:x\" or a sinusoid table, got {_describe(spec)}")


def _build_mincam(cfg: dict, mixel_tables: list, base: Path) -> Mincam:
    m = cfg
    spacing = _number("mincam", "spacing_m", m["spacing_m"], minimum=0.0)
    d_f = _number("mincam", "d_f_m", m["d_f_m"], positive=True)
    det = _number("mincam", "detector_size_m", m["detector_size_m"], positive=True)
    size = _number("mincam", "mask_size_m", m["mask_size_m"], positive=True)
    res = _integer("mincam", "mask_resolution", m["mask_resolution"], maximum=MAX_MASK_RESOLUTION)
    kind = _choice("mincam", "layout", m["layout"], _LAYOUTS)
    optics = _choice("mincam", "optics", m["optics"], _OPTICS)
    encoding = _choice("mincam", "mask_encoding", m["mask_encoding"], _ENCODINGS)
    wavelengths = _wavelengths(m["wavelengths_m"])
    common = {"d_f_m": d_f, "detector_size_m": det, "mask_encoding": encoding}
    if kind != "custom" and mixel_tables:
        raise ConfigError("[[mixel]] tables are only used with [mincam] layout = \"custom\"; remove them or set "
                          "layout = \"custom\"")
    mincam = _build_layout(kind, spacing, res, size, common, mixel_tables, base, optics, wavelengths)
    if kind == "custom":
        return mincam
    mixels = tuple(mx.with_optics(optics, wavelengths) for mx in mincam)
    return Mincam(mixels, allow_overlap=mincam.allow_overlap)


def _wavelengths(value: Any) -> tuple[float, ...]:
    where = "[mincam] wavelengths_m"
    if not isinstance(value, list) or not value or not all(_is_number(v) for v in value):
        raise ConfigError(f"{where} must be a non-empty list of wavelengths in metres like [550e-9], got "
                          f"{_describe(value)}")
    if not all(np.isfinite(v) and 400e-9 <= v <= 1100e-9 for v in value):
        raise ConfigError(f"{where} = {value!r}: give wavelengths in metres between 400e-9 and 1100e-9 "
                          "(550e-9 for 550 nm; the silicon QE curve spans 400-1100 nm)")
    return tuple(float(v) for v in value)


def _mask_size(where: str, value: Any, default: float) -> tuple[float, float | None]:
    """(width, height or None for square) [m] from a [[mixel]] mask_size_m: a side, or [width, height]."""
    if value is None:
        return default, None
    if isinstance(value, list | tuple):
        if len(value) != 2:
            raise ConfigError(f"{where} mask_size_m must be one side or [width, height] in metres, got "
                              f"{_describe(value)}")
        w = _number(where, "mask_size_m[0]", value[0], positive=True)
        h = _number(where, "mask_size_m[1]", value[1], positive=True)
        return w, h
    return _number(where, "mask_size_m", value, positive=True), None


def _build_layout(kind, spacing, res, size, common, mixel_tables, base, optics, wavelengths) -> Mincam:
    d_f, det, encoding = common["d_f_m"], common["detector_size_m"], common["mask_encoding"]
    try:
        if kind == "pair":
            return pair_layout(spacing, res, size, d_f_m=d_f, detector_size_m=det)
        if kind == "cross":
            return cross_layout(spacing, res, size, d_f_m=d_f, detector_size_m=det)
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
        name = f"m{i}" if t["name"] is None else _string(where, "name", t["name"])
        if not name.strip():
            raise ConfigError(f"{where} name must not be empty")
        width, height = _mask_size(where, t["mask_size_m"], size)
        mask_encoding = encoding if t["mask_encoding"] is None else _choice(where, "mask_encoding",
                                                                             t["mask_encoding"], _ENCODINGS)
        mask = parse_mask(t["mask"], width, res, where, base_dir=base, height_m=height, encoding=mask_encoding)
        position = _vector(where, "position_m", t["position_m"], 3)
        forward = _vector(where, "forward", t["forward"], 3)
        up = _vector(where, "up", t["up"], 3)
        if np.linalg.norm(forward) == 0:
            raise ConfigError(f"{where} forward must be a non-zero direction, got {list(forward)}")
        if np.linalg.norm(np.cross(forward, up)) < 1e-9 * np.linalg.norm(forward) * max(np.linalg.norm(up), 1e-300):
            raise ConfigError(f"{where} up {list(up)} must not be parallel to forward {list(forward)}; give an up "
                              "direction across the viewing direction")
        mixel_d_f = d_f if t["d_f_m"] is None else _number(where, "d_f_m", t["d_f_m"], positive=True)
        mixel_det = det if t["detector_size_m"] is None else _number(where, "detector_size_m",
                                                                      t["detector_size_m"], positive=True)
        mixel_optics = optics if t["optics"] is None else _choice(where, "optics", t["optics"], _OPTICS)
        try:
            mixels.append(Mixel(mask, mixel_d_f, mixel_det, Pose(position, forward, up), name, mixel_optics,
                                wavelengths))
        except ValueError as err:
            raise ConfigError(f"{where}: {err}") from None
    try:
        return Mincam(tuple(mixels))
    except ValueError as err:
        raise ConfigError(f"[[mixel]]: {err}") from None


def _build_screen(cfg: dict) -> Screen:
    diagonal = _number("screen", "diagonal_in", cfg["diagonal_in"], positive=True)
    distance = _number("screen", "distance_m", cfg["distance_m"], positive=True)
    aspect = _vector("screen", "aspect", cfg["aspect"], 2)
    if any(a <= 0 for a in aspect):
        raise ConfigError(f"[screen] aspect must be two positive numbers, got {cfg['aspect']!r}")
    res = _int_pair("screen", "resolution", cfg["resolution"], maximum=4096)
    if res[0] * res[1] > MAX_SCREEN_TEXELS:
        raise ConfigError(f"[screen] resolution {list(res)} is too large (at most {MAX_SCREEN_TEXELS} texels)")
    width, height = diagonal_to_size(diagonal, aspect)
    try:
        return Screen(width, height, res, Pose((0.0, 0.0, -distance), (0.0, 0.0, 1.0)))
    except ValueError as err:
        raise ConfigError(f"[screen]: {err}") from None


def load_frames_npy(path: Path, screen: Screen) -> FrameSource:
    """Frames (n, rows, cols) [W m^-2 sr^-1] from a ``.npy`` file, validated; ConfigError names the file."""
    where = f"[frames] path {str(path)!r}"
    if not path.is_file():
        raise ConfigError(f"{where} is not a file; give a .npy of shape (n, rows, cols) (relative paths are "
                          "relative to the config file)")
    if path.stat().st_size == 0:
        raise ConfigError(f"{where} is an empty file (0 bytes); write the frames with numpy.save")
    try:
        with open(path, "rb") as fh:
            magic = fh.read(6)
        if magic != b"\x93NUMPY":
            raise ValueError("it does not start with the .npy magic bytes")
        frames = np.load(path, mmap_mode="r", allow_pickle=False)
    except (ValueError, OSError, EOFError) as err:
        pickled = "pickle" in str(err) or "Python objects" in str(err)
        detail = "it holds Python objects (pickled)" if pickled else str(err)
        raise ConfigError(f"{where} is not a readable .npy array ({detail}); save a float array of shape "
                          "(n, rows, cols) with numpy.save") from None
    if not isinstance(frames, np.ndarray) or frames.dtype.kind not in "biuf":
        dtype = getattr(frames, "dtype", type(frames).__name__)
        raise ConfigError(f"{where} holds {dtype} data; frames must be real numbers (radiance)")
    if frames.ndim == 2:
        frames = frames[None]
    if frames.ndim != 3:
        raise ConfigError(f"{where} has shape {frames.shape}; frames must be (n, rows, cols) or (rows, cols)")
    if len(frames) == 0:
        raise ConfigError(f"{where} holds no frames (shape {frames.shape})")
    if frames.shape[1:] != screen.shape:
        raise ConfigError(f"{where}: frames of shape {frames.shape[1:]} (rows, cols) do not match the screen's "
                          f"{screen.shape}; set [screen] resolution = [{frames.shape[2]}, {frames.shape[1]}]")
    for i in range(len(frames)):  # validated frame by frame from the memory map (bounded memory)
        try:
            screen.check_frame(frames[i], f"frame {i} of {path}")
        except ValueError as err:
            raise ConfigError(f"[frames]: {err}") from None
    return FrameSource.from_array(frames)


def _build_frames(cfg: dict, screen: Screen, base: Path) -> tuple[FrameSource, np.ndarray | None]:
    kind = _choice("frames", "kind", cfg["kind"], _FRAME_KINDS)
    if kind == "npy":
        if not isinstance(cfg["path"], str) or not cfg["path"]:
            raise ConfigError(f"[frames] kind = \"npy\" needs path = \"<file.npy>\" (a string), got "
                              f"{_describe(cfg['path'])}")
        return load_frames_npy(_path("frames", "path", cfg["path"], base), screen), None
    square = _number("frames", "square_m", cfg["square_m"], positive=True)
    radiance = _number("frames", "radiance_w_m2_sr", cfg["radiance_w_m2_sr"], positive=True)
    background = _number("frames", "background_w_m2_sr", cfg["background_w_m2_sr"], minimum=0.0)
    sweep: Sweep
    try:
        if kind == "line_sweep":
            n = _integer("frames", "n", cfg["n"], maximum=MAX_FRAMES)
            start = _vector("frames", "start_m", cfg["start_m"], 2)
            end = _vector("frames", "end_m", cfg["end_m"], 2)
            sweep = line_sweep(start, end, n, square, radiance)
        else:
            nx = _integer("frames", "nx", cfg["nx"], maximum=MAX_FRAMES)
            ny = _integer("frames", "ny", cfg["ny"], maximum=MAX_FRAMES)
            if nx * ny > MAX_FRAMES:
                raise ConfigError(f"[frames] nx x ny = {nx * ny} frames; at most {MAX_FRAMES} per run")
            x_range = _vector("frames", "x_range_m", cfg["x_range_m"], 2)
            y_range = _vector("frames", "y_range_m", cfg["y_range_m"], 2)
            sweep = grid_sweep(x_range, y_range, nx, ny, square, radiance)
        frames = sweep.frame_source(screen, background)  # made on demand: streams whatever the number
    except ConfigError:
        raise
    except ValueError as err:
        raise ConfigError(f"[frames]: {err}") from None
    return frames, sweep.positions_m


def _read_source(source: Any, base_dir: str | Path | None) -> tuple[dict, Path, Path | None]:
    """(raw dict, base directory, config file or None) from a path, TOML text or a dict."""
    if isinstance(source, dict):
        return source, Path(base_dir or "."), None
    if isinstance(source, Path) or (isinstance(source, str) and "\n" not in source and "=" not in source
                                    and (source.endswith(".toml") or Path(source).is_file())):
        path = Path(source)
        if not path.exists():
            raise ConfigError(f"config file {path} does not exist")
        if path.is_dir():
            raise ConfigError(f"config file {path} is a directory; give a .toml file")
        try:
            text = path.read_bytes().decode("utf-8-sig")  # a byte-order mark (Windows editors) is dropped
        except UnicodeDecodeError:
            raise ConfigError(f"config file {path} is not UTF-8 text; give a TOML file") from None
        except OSError as err:
            raise ConfigError(f"cannot read config file {path}: {err.strerror or err}") from None
        where = f"config file {path}"
        base = path.parent if base_dir is None else Path(base_dir)
    elif isinstance(source, str):
        text, where, base, path = source.removeprefix("\ufeff"), "config", Path(base_dir or "."), None
    else:
        raise ConfigError(f"a config is a TOML file path, TOML text or a dict, got {type(source).__name__}")
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{where} is not valid TOML: {err}") from None
    return raw, base, path


def load_config(source: str | Path | dict, base_dir: str | Path | None = None) -> RenderConfig:
    """Parse and validate a TOML file (path), TOML text, or an already-parsed dict.

    Parameters
    ----------
    source : str, Path or dict
        A ``.toml`` file (a ``Path`` is always a file), TOML text, or the parsed document.
    base_dir : str or Path, optional
        Directory that relative paths (``out_dir``, ``[frames] path``, ``file:`` masks) resolve against;
        default: the config file's directory, or the working directory for text and dicts.

    Raises
    ------
    ConfigError
        For every problem with the document (never TypeError, KeyError ...): the message names the field and
        the fix.
    """
    raw, base, path = _read_source(source, base_dir)
    bad = [k for k in raw if not isinstance(k, str)]
    if bad:
        raise ConfigError(f"section names must be strings, got {bad[0]!r}")
    unknown = sorted(set(raw) - set(_SCHEMA) - {"mixel"})
    if unknown:
        raise ConfigError(f"unknown section(s) {unknown}; allowed: {sorted(_SCHEMA)} and [[mixel]]")
    sections = {name: _check_keys(name, raw.get(name, {}), defaults) for name, defaults in _SCHEMA.items()}
    run = sections["run"]
    form = _choice("run", "form", run["form"], _FORMS)
    spp = _integer("run", "spp", run["spp"])
    samples_per_texel = _integer("run", "samples_per_texel", run["samples_per_texel"])
    if samples_per_texel < 2:
        raise ConfigError("[run] samples_per_texel must be >= 2 (its spread gives the standard error)")
    target = _number("run", "target_rel_stderr", run["target_rel_stderr"], minimum=0.0)
    if isinstance(run["replicates"], int) and not isinstance(run["replicates"], bool) and run["replicates"] < 2:
        raise ConfigError("[run] replicates must be >= 2 (the standard error needs two estimates)")
    replicates = _integer("run", "replicates", run["replicates"], minimum=2, maximum=MAX_REPLICATES)
    seed = _integer("run", "seed", run["seed"], minimum=0)
    variant = run["variant"]
    if not isinstance(variant, str) or variant not in _VARIANTS:
        raise ConfigError(f"[run] variant {variant!r}: use '', 'cuda_ad_mono', 'llvm_ad_mono' or 'scalar_rgb'")
    if isinstance(run["out_dir"], str) and not run["out_dir"].strip():
        raise ConfigError("[run] out_dir must not be empty; give a directory like \"out/render\"")
    out_dir = _path("run", "out_dir", run["out_dir"], base)
    tables = raw.get("mixel", [])
    if isinstance(tables, dict):
        raise ConfigError("mixels are given as [[mixel]] tables (an array of tables, double brackets), not as a "
                          "single [mixel] table")
    if not isinstance(tables, list):
        raise ConfigError(f"mixels are given as [[mixel]] tables (an array of tables), got {_describe(tables)}")
    for i, table in enumerate(tables):
        _table(f"[[mixel]] #{i + 1}", table)
    mincam = _build_mincam(sections["mincam"], tables, base)
    wave = [mx.name for mx in mincam if mx.optics == "wave"]
    if wave and form == "reference":
        raise ConfigError(f"[run] form = \"reference\" is the literal geometric-optics scene, but mixel(s) {wave} "
                          "have optics = \"wave\": use form = \"fast\" or \"response_map\", or optics = "
                          "\"geometric\"")
    screen = _build_screen(sections["screen"])
    try:
        check_visible(screen, mincam)
    except ValueError as err:
        raise ConfigError(f"[mincam]/[screen]: {err}") from None
    frames, positions = _build_frames(sections["frames"], screen, base)
    run_cfg = RunConfig(form, spp, samples_per_texel, target, replicates, seed, variant or None, out_dir)
    return RenderConfig(run_cfg, mincam, screen, frames, positions, {**sections, "mixel": tables}, path,
                        sections["frames"]["kind"])


# ------------------------------------------------------------------------------------ dataclass sections
def read_sections(source: str | Path | dict, allowed: Sequence[str]) -> dict[str, dict]:
    """A TOML document (file path, text or dict) whose top level holds only the tables ``allowed``.

    Raises
    ------
    ConfigError
        Unreadable or invalid TOML, a section that is not a table, or an unknown section (the message lists
        the allowed ones).
    """
    raw, _, _ = _read_source(source, None)
    unknown = sorted(set(raw) - set(allowed))
    if unknown:
        raise ConfigError(f"unknown section(s) {', '.join(f'[{u}]' for u in unknown)}; allowed sections are "
                          f"{', '.join(f'[{a}]' for a in allowed)}")
    return {name: _table(f"[{name}]", table) for name, table in raw.items()}


def _typed_value(section: str, key: str, value: Any, default: Any) -> Any:
    """``value`` checked against the type of ``default`` (bool, int, float, str, or a tuple of them)."""
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ConfigError(f"{_where(section, key)} must be true or false, got {_describe(value)}")
        return value
    if isinstance(default, int):
        return _integer(section, key, value, minimum=0)
    if isinstance(default, float):
        return _number(section, key, value)
    if isinstance(default, str):
        return _string(section, key, value)
    if isinstance(default, tuple):
        if not isinstance(value, list | tuple) or len(value) == 0:
            raise ConfigError(f"{_where(section, key)} must be a non-empty list like {list(default)}, got "
                              f"{_describe(value)}")
        item = default[0] if default else 0.0
        return tuple(_typed_value(section, f"{key}[{i}]", v, item) for i, v in enumerate(value))
    raise ConfigError(f"{_where(section, key)} cannot be set from a config file")


def dataclass_from_section(section: str, table: Any, defaults: Any) -> Any:
    """A copy of the dataclass instance ``defaults`` with the keys of a TOML ``[section]`` table applied.

    Every key must be a field of the dataclass and have the type of its default (integers stay integers,
    numbers carry no units or quotes); the dataclass's own ``__post_init__`` then checks ranges, and its
    ``ValueError`` comes back as a :class:`~mincam_sim.errors.ConfigError` naming the section.
    """
    current = {f.name: getattr(defaults, f.name) for f in dataclasses.fields(defaults) if f.init}
    given = _table(f"[{section}]", table)
    _check_keys(section, given, current)
    values = {key: _typed_value(section, key, value, current[key]) for key, value in given.items()}
    try:
        return dataclasses.replace(defaults, **values)
    except ValueError as err:
        raise ConfigError(f"[{section}]: {err}") from None
