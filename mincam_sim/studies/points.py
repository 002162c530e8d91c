"""What one study point computes: ``point(params, seed, quick) -> {metric: value}`` (plain floats).

A point function is a pure function of its parameters and seed (so a point gives the same numbers on any
worker, in any order). Each study target declares its parameters with defaults, their units, the metrics it
returns and a rough cost per point (for the grid-size refusal).

Targets (:func:`study_target`):

* ``spacing`` -- the screen boundary sweep of the spacing experiment, one (spacing, depth, sensor) per point;
* every other experiment of :data:`mincam_sim.experiments.REGISTRY` (``intrusion``, ``tracking``, ``speed``):
  any scalar field of :class:`~mincam_sim.experiments.Setup` or of the experiment's parameters dataclass is a
  parameter; the metrics are the experiment's headline numbers and its numeric details;
* ``render`` -- a render config (``[study] config = "file.toml"``): any numeric key as ``section.key``
  (``mincam.d_f_m``, ``screen.distance_m``, ``frames.square_m`` ...); metrics per mixel;
* ``design`` -- the mask design task (``mincam-sim design tracking``) over its printer resolution.
"""

from __future__ import annotations

import contextlib
import dataclasses
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import ConfigError
from ..optics import DEFAULT_D_F_M, DEFAULT_DETECTOR_SIZE_M, PAPER_SPACING_M
from ..sensor import SensorModel

PointFunction = Callable[[dict, int, bool], dict]

#: Unit of a name from its suffix (longest first); names without a unit suffix are listed in ``_NAMED_UNITS``.
_SUFFIX_UNITS = (("_w_m2_sr", "W m^-2 sr^-1"), ("_w_m2", "W m^-2"), ("_rad_per_m", "rad/m"), ("_m_s", "m/s"),
                 ("_px_s", "px/s"), ("_e_per_s", "e-/s"), ("_pct", "%"), ("_hz", "Hz"), ("_deg", "deg"),
                 ("_rad", "rad"), ("_in", "in"), ("_px", "px"), ("_m2", "m^2"), ("_m", "m"), ("_s", "s"),
                 ("_e", "e-"))
_NAMED_UNITS = {"bit_depth": "bit", "point": "1", "replicate": "1", "spp": "samples", "samples_per_texel":
                "samples", "dpi": "dots/inch", "exposure_fill": "1", "reach_fraction": "1"}


def unit_of(name: str) -> str:
    """The unit of a parameter or metric from its name (``_m`` -> "m", ``_pct`` -> "%"; counts -> "1")."""
    base = name.rsplit(".", 1)[-1].removesuffix("_stderr")
    if base in _NAMED_UNITS:
        return _NAMED_UNITS[base]
    for suffix, unit in _SUFFIX_UNITS:
        if base.endswith(suffix):
            return unit
    return "1"


@dataclass(frozen=True)
class StudyExperiment:
    """A study target: its point function, parameters (name -> default, units from the names), metric names
    and the rough wall time of one point [s] (quick, full) used to refuse grids that cannot finish."""

    name: str
    description: str
    parameters: dict
    metrics: tuple[str, ...]
    point: PointFunction
    seconds_per_point: tuple[float, float] = (1.0, 10.0)
    ref: dict = field(default_factory=dict)  # how a worker rebuilds this target (see :func:`study_target`)

    def integer_parameters(self) -> set[str]:
        """Parameters whose values must be integers (their default is an ``int``)."""
        return {k for k, v in self.parameters.items() if isinstance(v, int) and not isinstance(v, bool)}

    def units(self, name: str) -> str:
        return unit_of(name)


# ----------------------------------------------------------------------------------------------- spacing
def _spacing_point(params: dict, seed: int, quick: bool) -> dict:
    """Two-mixel intrusion (band masks y | 1 - y) calibrated on a screen at ``calibration_depth_m``, then a
    white square swept along the boundary on a screen at ``depth_m``: position errors (% of the calibrated
    range at that depth) before / after the cubic calibration, noiseless and through the sensor model.

    The noisy read-out goes through :func:`~mincam_sim.readout.read_out`: the dark frame (the black screen) is
    measured with the same sensor, its mean is subtracted and frames whose change stays within its noise
    (``threshold_dn``) carry no position, as in the tabletop experiments."""
    from ..estimators import intrusion_position
    from ..experiments import Setup
    from ..experiments.screen_calibration import fit_calibration_1d
    from ..experiments.spacing import boundary_errors, boundary_sweep_irradiance
    from ..readout import read_out

    setup = Setup(depth_m=float(params["calibration_depth_m"]), spacing_m=float(params["spacing_m"]),
                  d_f_m=float(params["d_f_m"]), detector_size_m=float(params["detector_size_m"]),
                  bit_depth=int(params["bit_depth"]), seed=seed, quick=quick)
    sweep = {"positions": 15 if quick else 41, "samples_per_texel": 16 if quick else 64,
             "screen_texels": 96 if quick else 160}
    irr_cal, true_cal = boundary_sweep_irradiance(setup, setup.depth_m, **sweep)
    cal = fit_calibration_1d(intrusion_position(irr_cal[:, 0], irr_cal[:, 1]), true_cal,
                             {"spacing_m": setup.spacing_m})
    depth = float(params["depth_m"])
    irr, true = boundary_sweep_irradiance(setup, depth, **sweep)
    sensor = replace(setup.sensor(), read_noise_e=float(params["read_noise_e"]))
    dark = np.zeros(irr.shape[1])  # the black screen: the sensor's dark level and noise only
    readout = read_out(irr, dark, sensor, np.random.default_rng(seed), setup.exposure_fill)
    noisy = readout.change_dn
    out = {}
    for label, values, floor in (("", irr, 0.0), ("noisy_", noisy, readout.threshold_dn)):
        observed = intrusion_position(values[:, 0], values[:, 1], floor)
        before, after = boundary_errors(setup, cal, observed, true, depth)
        out[f"{label}avg_before_pct"] = before["avg_error_pct"]
        out[f"{label}max_before_pct"] = before["max_error_pct"]
        out[f"{label}avg_after_pct"] = after["avg_error_pct"]
        out[f"{label}max_after_pct"] = after["max_error_pct"]
        out[f"{label}missing_pct"] = after.get("missing_pct")
    return {k: (np.nan if v is None else float(v)) for k, v in out.items()}


SPACING = StudyExperiment(
    name="spacing",
    description="1D intrusion error on a screen vs mincam geometry and sensor noise (calibrated at one depth, "
                "used at another): the spacing experiment, one point per set-up",
    parameters={"spacing_m": PAPER_SPACING_M, "depth_m": 0.5, "calibration_depth_m": 0.5, "d_f_m": DEFAULT_D_F_M,
                "detector_size_m": DEFAULT_DETECTOR_SIZE_M, "bit_depth": SensorModel.paper_prototype().bit_depth,
                "read_noise_e": SensorModel.paper_prototype().read_noise_e},
    metrics=tuple(f"{p}{k}" for p in ("", "noisy_") for k in ("avg_before_pct", "max_before_pct", "avg_after_pct",
                                                              "max_after_pct", "missing_pct")),
    point=_spacing_point,
    seconds_per_point=(2.0, 10.0),
    ref={"name": "spacing"},
)


# -------------------------------------------------------------------------------- registry experiments
_SETUP_SKIP = {"seed", "quick", "screen_resolution", "dp_estimator"}
_HEADLINE = ("avg_error_pct", "max_error_pct", "rms_error_pct")
_SECONDS = {"intrusion": (60.0, 1200.0), "tracking": (60.0, 1800.0), "speed": (120.0, 1800.0)}


def _scalar_fields(obj) -> dict:
    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj) if f.init
            and isinstance(getattr(obj, f.name), int | float) and not isinstance(getattr(obj, f.name), bool)}


def _experiment_parameters(name: str) -> tuple[dict, set[str]]:
    """(parameter -> full-mode default, the names that belong to the set-up) of registry experiment ``name``."""
    from ..experiments import REGISTRY, Setup

    setup = {k: v for k, v in _scalar_fields(Setup()).items() if k not in _SETUP_SKIP}
    own = _scalar_fields(REGISTRY[name].Params())
    clash = sorted(set(setup) & set(own))
    if clash:  # a programming error: parameters must name one thing
        raise RuntimeError(f"experiment {name}: parameters {clash} are both set-up and experiment fields")
    return {**setup, **own}, set(setup)


def _numeric_details(result: dict) -> dict:
    out = {}
    for key, value in result.items():
        if isinstance(value, int | float) and not isinstance(value, bool):
            out[key] = float(value)
        elif value is None:
            out[key] = np.nan
    return out


@contextlib.contextmanager
def _figures_not_saved():
    """A study keeps an experiment's numbers, not its per-run figures (drawing them is most of a quick point's
    time): while a point runs, :mod:`mincam_sim.plots` closes its figures instead of saving them."""
    from .. import plots

    def close(fig, path):
        plots.plt.close(fig)
        return Path(path)

    saved = plots._save
    plots._save = close
    try:
        yield
    finally:
        plots._save = saved


def _experiment_point(name: str) -> PointFunction:
    def point(params: dict, seed: int, quick: bool) -> dict:
        from ..experiments import REGISTRY, Setup

        exp = REGISTRY[name]
        _, setup_keys = _experiment_parameters(name)
        setup = dataclasses.replace(Setup(quick=quick, seed=seed),
                                    **{k: v for k, v in params.items() if k in setup_keys})
        exp_params = dataclasses.replace(exp.params(quick), **{k: v for k, v in params.items()
                                                                if k not in setup_keys})
        with tempfile.TemporaryDirectory(prefix=f"study_{name}_") as tmp, _figures_not_saved():
            result = exp.run(setup, exp_params, Path(tmp)).as_dict()
        return _numeric_details(result)
    return point


_EXPERIMENT_METRICS = {
    "intrusion": (*_HEADLINE, "noise_sigma_median_pct", "unscored_frames_pct", "missed_frames",
                  "false_alarm_frames"),
    "tracking": (*_HEADLINE, "noise_sigma_median_pct", "unscored_frames_pct", "missed_frames",
                 "false_alarm_frames"),
    "speed": ("avg_error_pct", "max_error_pct"),
}


def _registry_target(name: str) -> StudyExperiment:
    from ..experiments import REGISTRY

    exp = REGISTRY[name]
    parameters, _ = _experiment_parameters(name)
    return StudyExperiment(name=name, description=f"the {name} experiment (paper Sec. {exp.paper_section}) per point",
                           parameters=parameters, metrics=_EXPERIMENT_METRICS[name], point=_experiment_point(name),
                           seconds_per_point=_SECONDS.get(name, (60.0, 1800.0)), ref={"name": name})


# ------------------------------------------------------------------------------------------ render config
def _flat_numeric(raw: dict) -> dict:
    from ..config import _SCHEMA

    out = {}
    for section, defaults in _SCHEMA.items():
        given = raw.get(section, {})
        for key, default in defaults.items():
            value = given.get(key, default)
            if isinstance(value, int | float) and not isinstance(value, bool) and f"{section}.{key}" != "run.seed":
                out[f"{section}.{key}"] = value  # run.seed is the study's: [study] seed and replicates
    return out


def _render_point(config_path: str) -> PointFunction:
    def point(params: dict, seed: int, quick: bool) -> dict:
        import tomllib

        from ..config import load_config
        from ..render.screen_engine import render_frames

        raw = tomllib.loads(Path(config_path).read_text(encoding="utf-8"))
        for key, value in params.items():
            section, name = key.split(".", 1)
            raw.setdefault(section, {})[name] = value
        raw.setdefault("run", {})["seed"] = int(seed)
        cfg = load_config(raw, base_dir=Path(config_path).parent)
        run = cfg.run
        m, _ = render_frames(cfg.mincam, cfg.screen, cfg.frames, run.form, run.spp, run.samples_per_texel,
                             run.target_rel_stderr, run.seed, run.replicates)
        out = {}
        for j, mixel in enumerate(m.mixel_names):
            values, stderr = m.irradiance_w_m2[:, j], m.stderr_w_m2[:, j]
            peak = int(np.argmax(values))
            out[f"{mixel}.mean_irradiance_w_m2"] = float(values.mean())
            out[f"{mixel}.mean_irradiance_w_m2_stderr"] = float(np.sqrt(np.sum(stderr ** 2)) / len(values))
            out[f"{mixel}.peak_irradiance_w_m2"] = float(values[peak])
            out[f"{mixel}.peak_irradiance_w_m2_stderr"] = float(stderr[peak])
        return out
    return point


def render_target(config_path: str | Path) -> StudyExperiment:
    """A render config as a study target: every numeric key (``section.key``) is a parameter."""
    import tomllib

    from ..config import load_config

    path = Path(config_path)
    if not path.is_file():
        raise ConfigError(f"[study] config = {str(path)!r}: no such render config file")
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"[study] config {path} is not valid TOML: {err}") from None
    cfg = load_config(path)  # validated once here; each point validates its own values again
    metrics = tuple(f"{mixel.name}.{kind}" for mixel in cfg.mincam
                    for kind in ("mean_irradiance_w_m2", "peak_irradiance_w_m2"))
    return StudyExperiment(name="render", description=f"render config {path.name}", parameters=_flat_numeric(raw),
                           metrics=metrics, point=_render_point(str(path.resolve())), seconds_per_point=(2.0, 30.0),
                           ref={"name": "render", "config": str(path.resolve())})


# ----------------------------------------------------------------------------------------------- design
def _design_point(params: dict, seed: int, quick: bool) -> dict:
    from ..design import run_design

    with tempfile.TemporaryDirectory(prefix="study_design_") as tmp:
        r = run_design("tracking", tmp, quick=quick, seed=int(seed), dpi=float(params["dpi"]))
    out = {}
    for key in ("baseline", "designed"):
        for metric in ("avg_error_pct", "max_error_pct"):
            value = r[key].get(metric)
            out[f"{key}_{metric}"] = np.nan if value is None else float(value)
    return out


DESIGN = StudyExperiment(
    name="design", description="mask design for tracking (differentiable rendering) vs printer resolution",
    parameters={"dpi": 600.0}, metrics=("baseline_avg_error_pct", "baseline_max_error_pct",
                                        "designed_avg_error_pct", "designed_max_error_pct"),
    point=_design_point, seconds_per_point=(300.0, 3600.0), ref={"name": "design"})


def target_names() -> tuple[str, ...]:
    """Every name ``[study] experiment`` accepts: the registry's experiments, ``render`` and ``design``."""
    from ..experiments import REGISTRY

    return (*REGISTRY, "render", "design")


def study_target(ref: dict) -> StudyExperiment:
    """The study target ``ref["name"]`` (``ref["config"]``: the render config file of ``render``)."""
    name = ref.get("name")
    if name == "spacing":
        return SPACING
    if name == "design":
        return DESIGN
    if name == "render":
        if not ref.get("config"):
            raise ConfigError("[study] experiment = \"render\" needs config = \"path/to/render.toml\" in [study]")
        return render_target(ref["config"])
    from ..experiments import REGISTRY

    if name in REGISTRY and name in _EXPERIMENT_METRICS:
        return _registry_target(name)
    raise ConfigError(f"[study] experiment = {name!r} is not one of {', '.join(map(repr, target_names()))}")
