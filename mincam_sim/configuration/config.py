"""TOML configuration of a render: its sections, defaults and validation (pure Python/numpy).

Every key carries its unit in its name (``_m`` metres, ``_rad`` radians, ``_w_m2_sr`` radiance ...). The
sections are dataclasses of :mod:`mincam_sim.configuration.schema` (``RunSection``, ``MincamSection``,
``ScreenSection``, ``FramesSection``, ``MixelTable``, ``SinusoidMask``): each field holds
its default, its comment and its check, and :data:`EXAMPLE_TOML` (``mincam-sim config-example``) is written
from them. Unknown sections or keys are refused with the closest allowed name.

Every problem with a document raises :class:`~mincam_sim.errors.ConfigError` (a ``ValueError``) naming the
field and the fix -- never a ``TypeError`` or ``KeyError``. Relative paths (``[run] out_dir``, ``[frames] path``
and ``file:`` masks) resolve against the config file's directory.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mincam_sim import masks as masks_mod
from mincam_sim import paper
from mincam_sim.budget import MAX_REPLICATES, Budget, field_problem
from mincam_sim.configuration.schema import (
    Choice,
    Integer,
    IntPair,
    Number,
    Part,
    Schema,
    Text,
    Vector,
    dataclass_from_section,
    defaults,
    describe,
    inline_table,
    is_number,
    read_section,
    read_sections,
    setting,
    warn_ignored,
    where,
)
from mincam_sim.configuration.schema import number as _number
from mincam_sim.configuration.schema import path as _path
from mincam_sim.configuration.schema import string as _string
from mincam_sim.configuration.schema import vector as _vector
from mincam_sim.configuration.toml_files import read_document
from mincam_sim.errors import ConfigError, InputError
from mincam_sim.masks import Mask
from mincam_sim.model.geometry import Pose
from mincam_sim.model.optics import (
    DEFAULT_D_F_M,
    DEFAULT_DETECTOR_SIZE_M,
    FILE_NAME_RULE,
    PAPER_SPACING_M,
    Mincam,
    Mixel,
    cross_layout,
    file_name_clash,
    pair_layout,
)
from mincam_sim.render.solvers import (
    Aperture,
    DotProduct,
    PlainChange,
    PlaneReplay,
    Reference,
    ResponseMap,
    Solver,
    StratifiedChange,
)
from mincam_sim.scene.display import (
    DEFAULT_DISTANCE_M,
    DEFAULT_SCREEN_RESOLUTION,
    FrameSource,
    Screen,
    Sweep,
    check_visible,
    diagonal_to_size,
    grid_sweep,
    line_sweep,
)

__all__ = ["EXAMPLE_TOML", "RENDER_SCHEMA", "SOLVERS", "RenderConfig", "RunConfig", "dataclass_from_section",
           "load_config", "load_frames_npy", "parse_mask", "read_sections", "solver_name", "traced_samples"]

MAX_FRAMES = 10_000_000  # frames stream through the renderer; this bounds run time and the result files
_OPTICS = ("geometric", "wave")
_ENCODINGS = ("linear", "srgb")
_LAYOUTS = ("pair", "cross", "custom")
_FRAME_KINDS = ("line_sweep", "grid_sweep", "npy")
_VARIANTS = ("", "cuda_ad_mono", "llvm_ad_mono", "scalar_rgb")

MAX_MASK_RESOLUTION = 8192  # texels per side (masks.MAX_TEXELS = 8192^2)
MAX_SCREEN_TEXELS = 4096 * 4096  # Screen's own limit
#: The largest length [m] of a mincam's own parts (spacing_m, d_f_m, detector_size_m, mask_size_m): a larger one is
#: a unit mistake, and squares of lengths near 1e300 overflow a float
MAX_MINCAM_LENGTH_M = 100.0
#: The largest radiance [W m^-2 sr^-1] a generated frame may hold: frames are 32-bit floats
MAX_RADIANCE_W_M2_SR = float(np.finfo(np.float32).max)


# ------------------------------------------------------------------------------------------------ solvers
def solver_name(solver: Solver | type[Solver]) -> str:
    """The configuration name of a solver: its class name in snake case (``ResponseMap`` -> ``"response_map"``)."""
    cls = solver if isinstance(solver, type) else type(solver)
    return "".join(f"_{c.lower()}" if c.isupper() else c for c in cls.__name__).lstrip("_")


#: ``[run] solver`` names -> solver classes, for display and world files alike.
SOLVERS: dict[str, type[Solver]] = {solver_name(cls): cls for cls in (Reference, Aperture, ResponseMap, PlainChange,
                                                                       StratifiedChange, PlaneReplay, DotProduct)}
# The keys and values of earlier releases: refused with the new key and value.
_OLD_SOLVER_KEYS = {"form": {"response_map": "response_map", "fast": "aperture", "reference": "reference"},
                    "estimator": {"stratified": "stratified_change", "plain": "plain_change"}}


def refuse_old_solver_keys(run_table: dict, kind: str) -> None:
    """A ``[run] form`` or ``[run] estimator`` (the old names) is refused, naming ``[run] solver`` and its value."""
    for key, names in _OLD_SOLVER_KEYS.items():
        if key in run_table:
            old = run_table[key]
            new = names.get(old) if isinstance(old, str) else None
            if new is not None:
                raise ConfigError(f"[run] {key} = {old!r} is the old name of the solver: use [run] solver = "
                                  f'"{new}"')
            names = ", ".join(f'"{n}"' for n in solvers_for(kind))
            raise ConfigError(f"[run] {key} is the old key of the solver: use [run] solver = one of {names}")


def solvers_for(kind: str) -> tuple[str, ...]:
    """The solver names a ``kind`` ("display" or "world") config accepts."""
    if kind == "world":
        return ("stratified_change", "plain_change")  # a world file measures changes (dP); see jobs.py
    return tuple(name for name, cls in SOLVERS.items() if "display" in cls().scenes)


def solver_check(kind: str):
    """The check of ``[run] solver`` in a ``kind`` config: one of :func:`solvers_for`, with a hint for the
    names of the other kind and for misspellings."""
    allowed = solvers_for(kind)

    def check(section: str, key: str, value: Any) -> str:
        if isinstance(value, str) and value in SOLVERS and value not in allowed:
            names = " or ".join(map(repr, allowed))
            if kind == "world" and "world" in SOLVERS[value]().scenes:  # aperture, plane_replay: absolute P
                raise ConfigError(f"[run] solver = {value!r} measures absolute P; a world config measures the "
                                  f"changes dP with {names} (absolute P: Simulation.measure in Python)")
            raise ConfigError(f"[run] solver = {value!r} does not solve {kind} scenes; a {kind} config takes "
                              f"{names}")
        return Choice(allowed)(section, key, value)
    return check


def make_solver(name: str) -> Solver:
    """The solver object of a checked ``[run] solver`` name."""
    return SOLVERS[name]()


def display_solver(name: str, dot_product_table: dict) -> Solver:
    """The solver of a display file: ``make_solver(name)``, or for ``"dot_product"`` the model with the options of
    ``[run.dot_product]`` (the solver's own checks, as one ``[run.dot_product]`` line)."""
    if name != "dot_product":
        return make_solver(name)
    options = RENDER_SCHEMA.read("run.dot_product", dot_product_table)
    try:
        return DotProduct(**dataclasses.asdict(options))
    except InputError as err:
        raise ConfigError("[run.dot_product] " + str(err).removeprefix("DotProduct ")) from None


def make_budget(solver: Solver, kind: str, spp: int, samples_per_texel: int | None, target_rel_stderr: float,
                replicates: int, seed: int) -> Budget:
    """The :class:`~mincam_sim.budget.Budget` of a ``[run]`` section with the fields the solver reads on ``kind``
    scenes (the file's reader warns about the others); the Budget's own checks, as one ``[run]`` line."""
    given = {"spp": spp, "samples_per_texel": samples_per_texel, "target_rel_stderr": target_rel_stderr,
             "replicates": replicates, "seed": seed}
    reads = solver.budget_fields(kind)
    try:
        return Budget(**{name: value for name, value in given.items() if name in reads})
    except InputError as err:
        raise ConfigError("[run] " + str(err).removeprefix("Budget.")) from None


# ------------------------------------------------------------------------------------------------ checks
def budget_field(section: str, key: str, value: Any) -> int | float:
    """A ``[run]`` key of the budget (``spp``, ``samples_per_texel``, ``replicates``, ``seed``,
    ``target_rel_stderr``), checked by the budget's own rule (:func:`mincam_sim.budget.field_problem`): a
    ``Budget(...)`` in Python refuses the same values with the same words."""
    problem = field_problem(key, value)
    if problem is not None:
        raise ConfigError(where(section, key) + problem.removeprefix(key))
    return float(value) if key == "target_rel_stderr" else int(value)


def _variant(section: str, key: str, value: Any) -> str:
    if not isinstance(value, str) or value not in _VARIANTS:
        raise ConfigError(f"[run] variant {value!r}: use '', 'cuda_ad_mono', 'llvm_ad_mono' or 'scalar_rgb'")
    return value


def _out_dir(section: str, key: str, value: Any) -> str:
    text = _string(section, key, value)
    if not text.strip():
        raise ConfigError(f"[{section}] out_dir must not be empty; give a directory like \"out/render\"")
    if "\x00" in text:
        raise ConfigError(f"[{section}] out_dir contains a NUL character; give a plain file path")
    return text


def _wavelengths(section: str, key: str, value: Any) -> tuple[float, ...]:
    where = f"[{section}] {key}"
    if not isinstance(value, list | tuple) or not value or not all(is_number(v) for v in value):
        raise ConfigError(f"{where} must be a non-empty list of wavelengths in metres like [550e-9], got "
                          f"{describe(value)}")
    if not all(np.isfinite(v) and 400e-9 <= v <= 1100e-9 for v in value):
        raise ConfigError(f"{where} = {value!r}: give wavelengths in metres between 400e-9 and 1100e-9 "
                          "(550e-9 for 550 nm; the silicon QE curve spans 400-1100 nm)")
    repeated = sorted({float(v) for v in value if list(value).count(v) > 1})
    if repeated:
        raise ConfigError(f"{where} repeats {', '.join(f'{v:g}' for v in repeated)} m: give each wavelength once "
                          "(each is weighted by its own band)")
    return tuple(float(v) for v in value)


def _aspect(section: str, key: str, value: Any) -> tuple[float, float]:
    aspect = _vector(section, key, value, 2)
    if any(a <= 0 for a in aspect):
        raise ConfigError(f"[screen] aspect must be two positive numbers, got {value!r}")
    return aspect  # type: ignore[return-value]


def _resolution(section: str, key: str, value: Any) -> tuple[int, int]:
    res = IntPair(4096)(section, key, value)
    if res[0] * res[1] > MAX_SCREEN_TEXELS:
        raise ConfigError(f"[screen] resolution {list(res)} is too large (at most {MAX_SCREEN_TEXELS} texels)")
    return res


def _mask_size(section: str, key: str, value: Any) -> tuple[float, float | None]:
    """(width, height or None for square) [m] from a [[mixel]] mask_size_m: a side, or [width, height]."""
    if isinstance(value, list | tuple):
        if len(value) != 2:
            raise ConfigError(f"{section} mask_size_m must be one side or [width, height] in metres, got "
                              f"{describe(value)}")
        return (_number(section, "mask_size_m[0]", value[0], positive=True, maximum=MAX_MINCAM_LENGTH_M),
                _number(section, "mask_size_m[1]", value[1], positive=True, maximum=MAX_MINCAM_LENGTH_M))
    return _number(section, "mask_size_m", value, positive=True, maximum=MAX_MINCAM_LENGTH_M), None


def _any(section: str, key: str, value: Any) -> Any:
    """Checked by the code that uses it (a mask: :func:`parse_mask`)."""
    return value


# ------------------------------------------------------------------------------------------------ sections
@dataclass(frozen=True)
class RunSection:
    """``[run]``: how to render."""

    solver: str = setting("response_map", '"response_map" (maps over the screen, then a dot product per frame), '
                          '"aperture" (rays through the mask aperture), "reference" (the literal scene) or '
                          '"dot_product" (the idealised model, deterministic quadrature; its options in '
                          '[run.dot_product])',
                          solver_check("display"))
    spp: int = setting(65536, 'samples per mixel per frame ("aperture"/"reference"); rounded UP to a multiple of '
                       "replicates (65536 with 8 replicates runs exactly)", budget_field)
    samples_per_texel: int = setting(
        64, 'samples per display texel per mixel ("response_map"): traced as replicates x k^2 stratified samples, '
        "k = floor(sqrt(samples_per_texel / replicates)), i.e. rounded DOWN:\n64 with 8 replicates traces 32 "
        "(8 x 2^2); 72 (8 x 3^2) and 128 (8 x 4^2) run exactly. `render` prints the count it traces when it "
        "differs from the one asked.", budget_field)
    target_rel_stderr: float = setting(0.0, "> 0: pick samples automatically to reach this relative standard error",
                                       budget_field)
    replicates: int = setting(8, f"independent estimates per value, for the standard error (2 .. {MAX_REPLICATES})",
                              budget_field)
    seed: int = setting(0, "same seed, same numbers", budget_field)
    variant: str = setting("", '"" = automatic (cuda_ad_mono > llvm_ad_mono > scalar_rgb)', _variant)
    out_dir: str = setting("out/render", "measurements.npz / .csv (+ response maps as OpenEXR); relative to this "
                           "file", _out_dir)


@dataclass(frozen=True)
class DotProductTable:
    """``[run.dot_product]``: the options of ``solver = "dot_product"``
    (:class:`~mincam_sim.render.solvers.DotProduct`); the defaults are the bare model."""

    parallax: bool = setting(False, "each mixel sees from its own detector centre (the field-of-view offset "
                             "between mixels), not from the mincam's centre")
    vignetting: bool = setting(False, "weigh the mask by cos^4 about the mixel's axis (the physical fall-off) "
                               "instead of uniformly")
    detector_blur: bool = setting(False, "average the pinhole over the detector's area (the finite detector's "
                                  "blur; costs (detector_cells * nodes)^2 times the bare model)")
    nodes: int = setting(4, "Gauss-Legendre points per axis of each texel's image (of each part of it, for a "
                         "raster mask) and of each detector cell", Integer())
    detector_cells: int = setting(1, "with detector_blur: squares per axis the detector is split into; raise it "
                                  "where the error estimate (stderr_w_m2) is too large (a detector large beside "
                                  "d_f)", Integer())


@dataclass(frozen=True)
class MincamSection:
    """``[mincam]``: the layout of the mixels and their common geometry."""

    layout: str = setting("pair", '"pair" (x | 1-x), "cross" (x, 1-x, y, 1-y around a centre), "custom" '
                          "([[mixel]] below)", Choice(_LAYOUTS))
    spacing_m: float = setting(PAPER_SPACING_M, "distance between neighbouring mixels (paper: 3.3 cm)",
                               Number(minimum=0.0, maximum=MAX_MINCAM_LENGTH_M))
    d_f_m: float = setting(DEFAULT_D_F_M, "mask-to-detector distance",
                           Number(positive=True, maximum=MAX_MINCAM_LENGTH_M))
    detector_size_m: float = setting(DEFAULT_DETECTOR_SIZE_M, "side of the square detector (paper: 48x48 pixels "
                                     "~ 0.1 mm)", Number(positive=True, maximum=MAX_MINCAM_LENGTH_M))
    mask_size_m: float = setting(masks_mod.DEFAULT_MASK_SIZE_M, "side of the square mask (aperture)",
                                 Number(positive=True, maximum=MAX_MINCAM_LENGTH_M))
    mask_resolution: int = setting(masks_mod.DEFAULT_RESOLUTION, "texels per side of generated masks",
                                   Integer(maximum=MAX_MASK_RESOLUTION))
    mask_encoding: str = setting("linear", 'how file: PNG values map to transmission: "linear" (value/255 is the '
                                 'transmission; 128 passes 50 %) or "srgb" (sRGB-encoded, as image editors save; '
                                 "128 passes 22 %)", Choice(_ENCODINGS))
    optics: str = setting("geometric", '"geometric" (rays) or "wave" (each mixel\'s scalar-wave angular response, '
                          "see README)", Choice(_OPTICS))
    wavelengths_m: tuple[float, ...] = setting((550e-9,), 'wavelengths of the wave response, weighted by a silicon '
                                               'QE curve ("wave" only)', _wavelengths)


@dataclass(frozen=True)
class SinusoidMask:
    """A mask given as a table: ``{kind = "sinusoid", omega_rad_per_m = ...}``."""

    kind: str = setting("sinusoid", "the only mask table", Choice(("sinusoid",)))
    omega_rad_per_m: float | None = setting(None, "angular frequency on the mask (required)", Number(minimum=0.0),
                                            example=15708.0)
    a0: float = setting(0.5, "mean transmission", Number())
    a1: float = setting(0.5, "amplitude", Number())
    phase_rad: float = setting(0.0, "phase", Number())
    direction_deg: float = setting(0.0, "direction of the stripes' normal", Number())


@dataclass(frozen=True)
class MixelTable:
    """One ``[[mixel]]`` table (``layout = "custom"``): its mask, pose and optional overrides."""

    name: str | None = setting(None, "optional: default m0, m1, ...", Text(nonempty=True), example="left",
                               shown=True)
    mask: Any = setting(None, '"ramp:x|1-x|y|1-y", "constant:<t>", "file:<path.png|.exr>" (relative to this file), '
                        f"or a table:\n{inline_table(SinusoidMask, omega_rad_per_m=15708.0)}", _any,
                        example="ramp:x", shown=True)
    optics: str | None = setting(None, "optional: overrides [mincam] optics for this mixel", Choice(_OPTICS),
                                 example="wave")
    mask_size_m: Any = setting(None, "optional: this mixel's mask, one side (square) or [width, height] in metres; "
                               "a file: image must have the mask's aspect ratio (a non-square image needs [width, "
                               "height]; nothing is stretched)", _mask_size, example=masks_mod.DEFAULT_MASK_SIZE_M)
    mask_encoding: str | None = setting(None, "optional: overrides [mincam] mask_encoding for this mixel's file: PNG",
                                        Choice(_ENCODINGS), example="srgb")
    d_f_m: float | None = setting(None, "optional: overrides [mincam] d_f_m for this mixel",
                                  Number(positive=True, maximum=MAX_MINCAM_LENGTH_M), example=DEFAULT_D_F_M)
    detector_size_m: float | None = setting(None, "optional: overrides [mincam] detector_size_m for this mixel",
                                            Number(positive=True, maximum=MAX_MINCAM_LENGTH_M),
                                            example=DEFAULT_DETECTOR_SIZE_M)
    position_m: tuple[float, float, float] = setting((0.0, 0.0, 0.0), "centre of the mask, mincam coordinates",
                                                     Vector(3))
    forward: tuple[float, float, float] = setting((0.0, 0.0, -1.0), "viewing direction", Vector(3))
    up: tuple[float, float, float] = setting((0.0, 1.0, 0.0), "the mask's +y", Vector(3))


@dataclass(frozen=True)
class ScreenSection:
    """``[screen]``: the display the frames are shown on."""

    diagonal_in: float = setting(paper.SCREEN_DIAGONAL_IN, 'display diagonal (paper: 50")', Number(positive=True))
    aspect: tuple[float, float] = setting((16, 9), "width : height", _aspect)
    resolution: tuple[int, int] = setting(tuple(DEFAULT_SCREEN_RESOLUTION), "display texels (columns, rows)",
                                          _resolution)
    distance_m: float = setting(DEFAULT_DISTANCE_M,
                                "from the mincam plane (z = 0) to the screen, which faces the mincam",
                                Number(positive=True))


@dataclass(frozen=True)
class FramesSection:
    """``[frames]``: what the screen shows, frame by frame."""

    kind: str = setting("line_sweep", '"line_sweep", "grid_sweep" or "npy" (a (n, rows, cols) radiance array '
                        "file)", Choice(_FRAME_KINDS))
    start_m: tuple[float, float] = setting((-0.25, 0.0), "line_sweep: first square centre, screen coordinates (x "
                                           "right, y up)", Vector(2))
    end_m: tuple[float, float] = setting((0.25, 0.0), "line_sweep: last square centre", Vector(2))
    n: int = setting(26, "line_sweep: number of positions", Integer(maximum=MAX_FRAMES))
    x_range_m: tuple[float, float] = setting((-0.2, 0.2), "grid_sweep: square centres from x_range_m[0] to [1]",
                                             Vector(2))
    y_range_m: tuple[float, float] = setting((-0.2, 0.2), "grid_sweep: and from y_range_m[0] to [1]", Vector(2))
    nx: int = setting(9, "grid_sweep: positions along x", Integer(maximum=MAX_FRAMES))
    ny: int = setting(9, "grid_sweep: positions along y", Integer(maximum=MAX_FRAMES))
    square_m: float = setting(0.03, "side of the white square", Number(positive=True))
    radiance_w_m2_sr: float = setting(1.0, "radiance of the white square (black elsewhere)",
                                      Number(positive=True, maximum=MAX_RADIANCE_W_M2_SR))
    background_w_m2_sr: float = setting(0.0, "radiance of the rest of the screen",
                                        Number(minimum=0.0, maximum=MAX_RADIANCE_W_M2_SR))
    path: str = setting("", "npy: path of the frame stack (relative to this file)", Text())


#: The render file: its sections, in the order the documented example shows them.
RENDER_SCHEMA = Schema(
    "mincam-sim render configuration. Units are in the key names: _m metres, _in inches, _deg degrees,\n"
    "_rad_per_m radians per metre, _w_m2_sr radiance (W m^-2 sr^-1).",
    (Part("run", RunSection),
     Part("run.dot_product", DotProductTable, commented=True,
          intro='For solver = "dot_product" (the idealised model), its options (defaults: the bare model):'),
     Part("mincam", MincamSection),
     Part("mixel", MixelTable, array=True, commented=True, intro='For layout = "custom", one table per mixel:'),
     Part("screen", ScreenSection), Part("frames", FramesSection)),
)
_SECTIONS = {"run": RunSection, "mincam": MincamSection, "screen": ScreenSection, "frames": FramesSection}

#: The documented render schema with every default (``mincam-sim config-example``), written from the sections.
EXAMPLE_TOML = RENDER_SCHEMA.example()

# The keys and defaults of each section as TOML values (a study's render target sweeps the numeric ones).
_SCHEMA: dict[str, dict[str, Any]] = {name: defaults(cls) for name, cls in _SECTIONS.items()}
_MIXEL_KEYS = defaults(MixelTable)
_SINUSOID_KEYS = defaults(SinusoidMask)


@dataclass
class RunConfig:
    """[run]: how to render. ``out_dir`` is resolved against the config file's directory."""

    solver: Solver
    budget: Budget
    variant: str | None
    out_dir: Path


@dataclass
class RenderConfig:
    """A validated configuration: run settings, the mincam, the screen and the frames."""

    run: RunConfig
    mincam: Mincam
    screen: Screen
    frames: FrameSource
    frame_positions_m: np.ndarray | None
    source: Path | None = None
    frames_kind: str = "line_sweep"


def traced_samples(run: RunConfig) -> tuple[int, str | None]:
    """The sample count a fixed-budget run traces, and one line saying so when it is not the count asked.

    ``response_map`` traces ``replicates x k^2`` samples per texel with ``k = floor(sqrt(samples_per_texel /
    replicates))`` (stratified, rounded down); ``fast`` / ``reference`` trace ``replicates x ceil(spp /
    replicates)`` samples per mixel per frame (rounded up). With ``target_rel_stderr > 0`` the counts are chosen
    automatically and this returns the starting count and None.
    """
    b = run.budget
    replicates = b.replicates_or(8)
    if isinstance(run.solver, ResponseMap):
        asked = b.samples_per_texel
        k = max(1, int(np.sqrt(asked / replicates)))
        traced = replicates * k * k
        if traced == asked or b.target_rel_stderr > 0:
            return traced, None
        up = replicates * (k + 1) ** 2
        return traced, (f"[run] samples_per_texel = {asked} traces {traced} samples per texel "
                        f"({replicates} replicates x {k}x{k} strata, rounded down); ask {traced} or {up} to "
                        "get exactly what runs")
    per = -(-b.rays() // replicates)
    traced = replicates * per
    if traced == b.rays() or b.target_rel_stderr > 0:
        return traced, None
    return traced, (f"[run] spp = {b.rays()} traces {traced} samples per mixel per frame ({replicates} "
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
        return _string_mask(spec, res, width_m, height, where, base_dir, height_m, encoding)
    if isinstance(spec, dict):
        return _sinusoid_table_mask(spec, res, width_m, height, where)
    raise ConfigError(f"{where}: mask must be a string like \"ramp:x\" or a sinusoid table, got {describe(spec)}")


def _string_mask(spec: str, res: tuple[int, int], width_m: float, height: float, where: str,
                 base_dir: str | Path | None, height_m: float | None, encoding: str) -> Mask:
    """A mask from ``"ramp:<dir>"``, ``"constant:<t>"`` or ``"file:<path>"`` (``res``: rows, cols; sizes [m])."""
    kind, _, arg = spec.partition(":")
    if kind == "ramp":
        try:
            return masks_mod.ramp(arg, res, width_m, height)
        except ValueError as err:
            raise ConfigError(f"{where}: {err}") from None
    if kind == "constant":
        return _constant_mask(spec, arg, width_m, height, where)
    if kind == "file":
        path = _mask_file_path(arg, where, base_dir)
        return _file_mask(path, width_m, height, where, height_m, encoding)
    raise ConfigError(
        f"{where}: mask {spec!r} not understood; use 'ramp:x|1-x|y|1-y', 'constant:<t>', 'file:<path>' or a "
        "table {kind = \"sinusoid\", omega_rad_per_m = ...}"
    )


def _constant_mask(spec: str, arg: str, width_m: float, height: float, where: str) -> Mask:
    """``"constant:<t>"``: one transmission ``t`` in [0, 1] (default 1) over a ``width_m`` x ``height`` [m] mask."""
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


def _mask_file_path(arg: str, where: str, base_dir: str | Path | None) -> Path:
    """The existing file a ``"file:<path>"`` mask names (``~`` expanded; relative to ``base_dir`` if given)."""
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
    return path


def _file_mask(path: Path, width_m: float, height: float, where: str, height_m: float | None,
               encoding: str) -> Mask:
    """The mask in an image file, at ``width_m`` x ``height`` [m]; refused if the image has another aspect ratio.

    ``height_m`` is the height the config gave (None: square by default), which chooses the fix the error names.
    """
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


def _sinusoid_table_mask(spec: dict, res: tuple[int, int], width_m: float, height: float, where: str) -> Mask:
    """A mask from a ``{kind = "sinusoid", omega_rad_per_m = ...}`` table (``res``: rows, cols; sizes [m])."""
    kind = spec.get("kind")
    if kind != "sinusoid":
        raise ConfigError(f"{where}: mask tables support kind = \"sinusoid\" (got {kind!r})")
    table = read_section(f"{where} mask", spec, SinusoidMask)
    if table.omega_rad_per_m is None:
        raise ConfigError(f"{where}: a sinusoid mask needs omega_rad_per_m (angular frequency on the mask)")
    try:
        return masks_mod.sinusoid(resolution=res, width_m=width_m, height_m=height, omega_rad_per_m=
                                  table.omega_rad_per_m, a0=table.a0, a1=table.a1, phase_rad=table.phase_rad,
                                  direction_deg=table.direction_deg)
    except (TypeError, ValueError) as err:
        raise ConfigError(f"{where}: {err}") from None


def _build_mincam(m: MincamSection, mixel_tables: list, base: Path) -> Mincam:
    """The mincam of a validated ``[mincam]`` section and its ``[[mixel]]`` tables (``layout = "custom"``)."""
    if m.layout != "custom" and mixel_tables:
        raise ConfigError("[[mixel]] tables are only used with [mincam] layout = \"custom\"; remove them or set "
                          "layout = \"custom\"")
    try:
        if m.layout == "pair":
            mincam = pair_layout(m.spacing_m, m.mask_resolution, m.mask_size_m, d_f_m=m.d_f_m,
                                 detector_size_m=m.detector_size_m)
        elif m.layout == "cross":
            mincam = cross_layout(m.spacing_m, m.mask_resolution, m.mask_size_m, d_f_m=m.d_f_m,
                                  detector_size_m=m.detector_size_m)
    except ValueError as err:
        raise ConfigError(f"[mincam]: {err}") from None
    if m.layout == "custom":
        return _custom_mincam(m, mixel_tables, base)
    mixels = tuple(mx.with_optics(m.optics, m.wavelengths_m) for mx in mincam)
    return Mincam(mixels, allow_overlap=mincam.allow_overlap)


def check_file_names(names: list[str], where: str = "[[mixel]]") -> None:
    """Refuse mixel ``names`` that would be written to the same files (``"a/b"`` and ``"a_b"``; ``"X"`` and ``"x"``
    on a disk that ignores case): one mixel's response map would silently replace the other's.

    Raises
    ------
    ConfigError
        Naming both tables and the file name they share.
    """
    clash = file_name_clash(names)
    if clash is not None:
        j, i, stem = clash
        raise ConfigError(f"{where} #{j + 1} name {names[j]!r} and #{i + 1} name {names[i]!r} would write the same "
                          f"files (response_{stem}.exr, maps/{stem}.npy): {FILE_NAME_RULE}; give names that differ "
                          "in those")


def _custom_mincam(m: MincamSection, mixel_tables: list, base: Path) -> Mincam:
    if not mixel_tables:
        raise ConfigError("[mincam] layout = \"custom\" needs at least one [[mixel]] table")
    named = [t.get("name") if isinstance(t, dict) else 0 for t in mixel_tables]  # 0: not a table, named below
    names = [f"m{i}" if name is None else name for i, name in enumerate(named)]
    if all(isinstance(n, str) for n in names) and len(set(names)) == len(names):  # else the checks below say
        check_file_names(names)
    mixels = []
    for i, given in enumerate(mixel_tables):
        where = f"[[mixel]] #{i + 1}"
        t: MixelTable = read_section(where, given, MixelTable)
        if t.mask is None:
            raise ConfigError(f"{where}: mask is required (e.g. mask = \"ramp:x\")")
        name = f"m{i}" if t.name is None else t.name
        width, height = (m.mask_size_m, None) if t.mask_size_m is None else t.mask_size_m
        encoding = m.mask_encoding if t.mask_encoding is None else t.mask_encoding
        mask = parse_mask(t.mask, width, m.mask_resolution, where, base_dir=base, height_m=height, encoding=encoding)
        forward, up = t.forward, t.up
        if np.linalg.norm(forward) == 0:
            raise ConfigError(f"{where} forward must be a non-zero direction, got {list(forward)}")
        if np.linalg.norm(np.cross(forward, up)) < 1e-9 * np.linalg.norm(forward) * max(np.linalg.norm(up), 1e-300):
            raise ConfigError(f"{where} up {list(up)} must not be parallel to forward {list(forward)}; give an up "
                              "direction across the viewing direction")
        try:
            mixels.append(Mixel(mask, m.d_f_m if t.d_f_m is None else t.d_f_m,
                                m.detector_size_m if t.detector_size_m is None else t.detector_size_m,
                                Pose(t.position_m, forward, up), name, m.optics if t.optics is None else t.optics,
                                m.wavelengths_m))
        except ValueError as err:
            raise ConfigError(f"{where}: {err}") from None
    try:
        return Mincam(tuple(mixels))
    except ValueError as err:  # the Python fix (allow_overlap=True) is no key of a config file
        text = str(err).replace("move them apart, or pass allow_overlap=True to render an idealised mincam in which "
                                "each mixel sees the scene as if it were alone",
                                "move them apart (position_m of their [[mixel]] tables)")
        raise ConfigError(f"[[mixel]]: {text}") from None


def _build_screen(s: ScreenSection) -> Screen:
    width, height = diagonal_to_size(s.diagonal_in, s.aspect)
    try:
        return Screen(width, height, s.resolution, Pose((0.0, 0.0, -s.distance_m), (0.0, 0.0, 1.0)))
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


def _build_frames(f: FramesSection, screen: Screen, base: Path) -> tuple[FrameSource, np.ndarray | None]:
    if f.kind == "npy":
        if not f.path:
            raise ConfigError("[frames] kind = \"npy\" needs path = \"<file.npy>\" (a .npy of shape (n, rows, "
                              "cols), relative to the config file)")
        return load_frames_npy(_path("frames", "path", f.path, base), screen), None
    sweep: Sweep
    try:
        if f.kind == "line_sweep":
            sweep = line_sweep(f.start_m, f.end_m, f.n, f.square_m, f.radiance_w_m2_sr)
        else:
            if f.nx * f.ny > MAX_FRAMES:
                raise ConfigError(f"[frames] nx x ny = {f.nx * f.ny} frames; at most {MAX_FRAMES} per run")
            sweep = grid_sweep(f.x_range_m, f.y_range_m, f.nx, f.ny, f.square_m, f.radiance_w_m2_sr)
        frames = sweep.frame_source(screen, f.background_w_m2_sr)  # made on demand: streams whatever the number
    except ConfigError:
        raise
    except ValueError as err:
        raise ConfigError(f"[frames]: {err}") from None
    return frames, sweep.positions_m


#: The ``[frames]`` keys each kind uses (``kind`` aside); the others are ignored with a warning.
FRAME_KEYS = {"line_sweep": ("start_m", "end_m", "n", "square_m", "radiance_w_m2_sr", "background_w_m2_sr"),
              "grid_sweep": ("x_range_m", "y_range_m", "nx", "ny", "square_m", "radiance_w_m2_sr",
                             "background_w_m2_sr"),
              "npy": ("path",)}


def _is_file_mask(spec: Any) -> bool:
    return isinstance(spec, str) and spec.startswith("file:")


def warn_ignored_mincam(given: dict, mixel_tables: list, mincam: Mincam, cls: type,
                        placed: tuple[str, ...] = ("spacing_m",)) -> None:
    """One warning per ``[mincam]`` / ``[[mixel]]`` key that the rest of the file makes ineffective (``placed``:
    the keys that place a pair or cross layout, ignored by ``layout = "custom"``)."""
    custom = given.get("layout") == "custom"
    if custom:
        warn_ignored("mincam", given, placed, 'layout = "custom" places each [[mixel]] at its own position_m', cls)
    if not any(mx.optics == "wave" for mx in mincam):
        warn_ignored("mincam", given, ("wavelengths_m",), 'no mixel has optics = "wave"', cls)
    masks = [t.get("mask") for t in mixel_tables] if custom else []
    if not any(_is_file_mask(m) for m in masks):
        warn_ignored("mincam", given, ("mask_encoding",), "it applies to file: masks, and no mixel has one", cls)
    elif all(_is_file_mask(m) for m in masks):
        warn_ignored("mincam", given, ("mask_resolution",), "every mask is a file: image (its pixels are the "
                     "texels)", cls)
    for i, table_ in enumerate(mixel_tables if custom else []):
        if not _is_file_mask(table_.get("mask")):
            warn_ignored(f"[[mixel]] #{i + 1}", table_, ("mask_encoding",), "its mask is not a file: image")


def _warn_ignored(tables: dict, run: RunSection, mincam: Mincam, frames_kind: str) -> None:
    """One warning line per key the rest of a display file makes ineffective (nothing is refused)."""
    if run.solver == "dot_product":
        warn_ignored("run", tables["run"], ("spp", "samples_per_texel", "target_rel_stderr", "replicates", "seed"),
                     'solver = "dot_product" is deterministic quadrature (no samples; its error is the '
                     "quadrature's estimate)", RunSection)
    else:
        warn_ignored("run.dot_product", tables["run.dot_product"], list(tables["run.dot_product"]),
                     f'they are the options of solver = "dot_product", and this file\'s solver is "{run.solver}"',
                     DotProductTable)
    if run.solver == "response_map":
        warn_ignored("run", tables["run"], ("spp",), 'solver = "response_map" traces samples_per_texel (spp is for '
                     'the "aperture" and "reference" solvers)', RunSection)
    elif run.solver != "dot_product":
        warn_ignored("run", tables["run"], ("samples_per_texel",), f"solver = {run.solver!r} traces spp rays per "
                     'mixel per frame (samples_per_texel is for the "response_map" solver)', RunSection)
    warn_ignored_mincam(tables["mincam"], tables["mixel"], mincam, MincamSection)
    unused = [k for keys in FRAME_KEYS.values() for k in keys if k not in FRAME_KEYS[frames_kind]]
    warn_ignored("frames", tables["frames"], list(dict.fromkeys(unused)), f'kind = "{frames_kind}" uses only '
                 f"{', '.join(FRAME_KEYS[frames_kind])}", FramesSection)


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

    Warns
    -----
    IgnoredSettingWarning
        One line per key that the rest of the file makes ineffective (``spp`` with ``solver = "response_map"``,
        a ``grid_sweep`` key with ``kind = "line_sweep"`` ...).
    """
    raw, base, path = read_document(source, base_dir)
    tables = RENDER_SCHEMA.tables(raw)
    refuse_old_solver_keys(tables["run"], "display")
    sections = {name: RENDER_SCHEMA.read(name, tables[name]) for name in _SECTIONS}
    run: RunSection = sections["run"]
    solver = display_solver(run.solver, tables["run.dot_product"])
    budget = make_budget(solver, "display", run.spp, run.samples_per_texel, run.target_rel_stderr, run.replicates,
                         run.seed)
    mincam = _build_mincam(sections["mincam"], tables["mixel"], base)
    wave = [mx.name for mx in mincam if mx.optics == "wave"]
    if wave and isinstance(solver, Reference):
        raise ConfigError(f"[run] solver = \"reference\" is the literal geometric-optics scene, but mixel(s) {wave} "
                          "have optics = \"wave\": use solver = \"aperture\" or \"response_map\", or optics = "
                          "\"geometric\"")
    screen = _build_screen(sections["screen"])
    try:
        check_visible(screen, mincam)
    except ValueError as err:
        raise ConfigError(f"[mincam]/[screen]: {err}") from None
    frames, positions = _build_frames(sections["frames"], screen, base)
    _warn_ignored(tables, run, mincam, sections["frames"].kind)
    run_cfg = RunConfig(solver, budget, run.variant or None, _path("run", "out_dir", run.out_dir, base))
    return RenderConfig(run_cfg, mincam, screen, frames, positions, path, sections["frames"].kind)
