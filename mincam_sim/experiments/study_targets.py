"""What a study target is, and the two targets that are no experiment of the paper.

A study target (:class:`StudyExperiment`) is a point function ``point(params, seed, quick) -> {metric: value}``
(plain floats; a pure function of its parameters and seed, so a point gives the same numbers on any worker, in
any order), its parameters with their defaults (units from the names), the metrics it returns and a rough
wall time per point (for the grid-size refusal). Every experiment of the registry declares its own target
(``Experiment.study_target``); :mod:`.registry` adds the two below and is the
one place a target is looked up by name:

* ``render`` -- a render config (``[study] config = "file.toml"``): any numeric key as ``section.key``
  (``mincam.d_f_m``, ``screen.distance_m``, ``frames.square_m`` ...); metrics per mixel;
* ``design`` -- the mask design task (``mincam-sim design tracking``) over its printer resolution.
"""

from __future__ import annotations

import contextlib
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mincam_sim.errors import ConfigError

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
    ref: dict = field(default_factory=dict)  # how a worker rebuilds this target (registry.study_target)
    # refuses a point's parameters (ValueError) without computing it: every point is checked before the first runs
    check: Callable[[dict, bool], None] | None = None

    def integer_parameters(self) -> set[str]:
        """Parameters whose values must be integers (their default is an ``int``)."""
        return {k for k, v in self.parameters.items() if isinstance(v, int) and not isinstance(v, bool)}

    def units(self, name: str) -> str:
        return unit_of(name)


def numeric_details(result: dict) -> dict:
    """The numbers of an experiment's result entry as study metrics: ints and floats as floats, ``None`` (nothing
    could be scored) as NaN; everything else (lists, tables, names) left out."""
    out = {}
    for key, value in result.items():
        if isinstance(value, int | float) and not isinstance(value, bool):
            out[key] = float(value)
        elif value is None:
            out[key] = np.nan
    return out


@contextlib.contextmanager
def figures_not_saved() -> Iterator[None]:
    """A study keeps an experiment's numbers, not its per-run figures (drawing them is most of a quick point's
    time): while a point runs, :mod:`mincam_sim.plotting.plots` closes its figures instead of saving them."""
    from mincam_sim.plotting import plots

    def close(fig, path):
        plots.plt.close(fig)
        return Path(path)

    saved = plots._save
    plots._save = close
    try:
        yield
    finally:
        plots._save = saved


# ------------------------------------------------------------------------------------------ render config
def _flat_numeric(raw: dict) -> dict:
    from mincam_sim.configuration.config import _SCHEMA

    out = {}
    for section, defaults in _SCHEMA.items():
        given = raw.get(section, {})
        for key, default in defaults.items():
            value = given.get(key, default)
            if isinstance(value, int | float) and not isinstance(value, bool) and f"{section}.{key}" != "run.seed":
                out[f"{section}.{key}"] = value  # run.seed is the study's: [study] seed and replicates
    return out


def _render_config(config_path: str, params: dict, seed: int):
    """The render config of a study point: the file with the point's ``section.key`` values and its seed."""
    from mincam_sim.configuration.config import load_config
    from mincam_sim.configuration.toml_files import read_toml_file

    raw = read_toml_file(config_path, "[study] config")
    for key, value in params.items():
        section, name = key.split(".", 1)
        raw.setdefault(section, {})[name] = value
    raw.setdefault("run", {})["seed"] = int(seed)
    return load_config(raw, base_dir=Path(config_path).parent)


def _render_point(config_path: str) -> PointFunction:
    def point(params: dict, seed: int, quick: bool) -> dict:
        from mincam_sim.render.simulation import Simulation

        cfg = _render_config(config_path, params, seed)
        m = Simulation(cfg.mincam, screen=cfg.screen).measure(cfg.frames, cfg.run.solver, cfg.run.budget)
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
    from mincam_sim.configuration.config import load_config
    from mincam_sim.configuration.toml_files import read_toml_file

    path = Path(config_path)
    if not path.is_file():
        raise ConfigError(f"[study] config = {str(path)!r}: no such render config file")
    raw = read_toml_file(path, "[study] config")
    cfg = load_config(path)  # validated once here; each point validates its own values again
    metrics = tuple(f"{mixel.name}.{kind}" for mixel in cfg.mincam
                    for kind in ("mean_irradiance_w_m2", "peak_irradiance_w_m2"))
    return StudyExperiment(name="render", description=f"render config {path.name}", parameters=_flat_numeric(raw),
                           metrics=metrics, point=_render_point(str(path.resolve())), seconds_per_point=(2.0, 30.0),
                           ref={"name": "render", "config": str(path.resolve())},
                           check=lambda params, quick: _render_config(str(path.resolve()), params, 0) and None)


def render_target_from_ref(ref: dict) -> StudyExperiment:
    """The ``render`` target of a study reference (``ref["config"]``: the render config file)."""
    if not ref.get("config"):
        raise ConfigError("[study] experiment = \"render\" needs config = \"path/to/render.toml\" in [study]")
    return render_target(ref["config"])


# ----------------------------------------------------------------------------------------------- design
def _design_point(params: dict, seed: int, quick: bool) -> dict:
    from mincam_sim.design import run_design

    with tempfile.TemporaryDirectory(prefix="study_design_") as tmp:
        r = run_design("tracking", tmp, quick=quick, seed=int(seed), dpi=float(params["dpi"]),
                       baselines=False)
    out = {}
    for key in ("baseline", "designed"):
        for metric in ("avg_error_pct", "max_error_pct"):
            value = r[key].get(metric)
            out[f"{key}_{metric}"] = np.nan if value is None else float(value)
    return out


def design_target(ref: dict | None = None) -> StudyExperiment:
    """The mask design task for tracking (differentiable rendering) over its printer resolution (default: the
    design task's own)."""
    from mincam_sim.design.tracking import TrackingTask

    return StudyExperiment(
        name="design", description="mask design for tracking (differentiable rendering) vs printer resolution",
        parameters={"dpi": float(TrackingTask().dpi)}, metrics=("baseline_avg_error_pct", "baseline_max_error_pct",
                                            "designed_avg_error_pct", "designed_max_error_pct"),
        point=_design_point, seconds_per_point=(300.0, 3600.0), ref={"name": "design"}, check=_design_check)


def _design_check(params: dict, quick: bool) -> None:
    """A design point's printer resolution, refused as the design task refuses it (range, print sheet), before
    any point runs (a point takes minutes)."""
    from mincam_sim.design.run import make_task

    dpi = params["dpi"]
    if isinstance(dpi, bool) or not isinstance(dpi, int | float) or not np.isfinite(dpi):
        raise ConfigError(f"dpi must be a number of dots per inch, got {dpi!r}")
    make_task(quick, dpi=float(dpi))
