"""A study file: which experiment, which parameter points, which metrics (TOML, read like a render config).

Sections: ``[study]`` (:class:`StudySection`: the target, seed, replicates, output), ``[fixed]`` (parameters
held at one value; the others keep the experiment's defaults), exactly one of ``[grid]`` (the full product of
parameter lists: the result's dimensions), ``[points]`` (an explicit list, equal lengths) or ``[random]`` (``n``
points sampled from ``param = [low, high]`` ranges; both give one dimension ``point``), ``[quick]`` (with
``--quick``: lists replace ``[grid]`` lists, single values replace ``[fixed]`` ones) and ``[metrics]``
(:class:`MetricsSection`). A render config's keys are dotted: ``mincam.d_f_m = [0.001, 0.002]``. The documented
example, with every ``[study]`` default, is :func:`study_example_toml` (``mincam-sim config-example --study``);
``scenes/studies/*.toml`` are working studies.

Refused, one line each: an unknown section, key or parameter (with the closest name), a non-integer value of an
integer parameter, a key both in ``[fixed]`` and ``[grid]``, a value twice in one grid list, and a grid of more
than ``max_points`` points (the message gives the count and the estimated time; ``--max-points`` raises the
limit).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mincam_sim.configuration.schema import (
    Flag,
    Integer,
    Part,
    Schema,
    Text,
    closest,
    read_section,
    setting,
    toml_value,
)
from mincam_sim.configuration.toml_files import read_document
from mincam_sim.errors import ConfigError
from mincam_sim.experiments.registry import study_target, target_names
from mincam_sim.experiments.study_targets import StudyExperiment

DEFAULT_MAX_POINTS = 10_000
MAX_REPLICATES = 1000


def _experiment(section: str, key: str, value: Any) -> str:
    if not isinstance(value, str) or value not in target_names():
        hint = closest(value, target_names()) if isinstance(value, str) else None
        extra = f" (did you mean {hint!r}?)" if hint else ""
        raise ConfigError(f"[study] experiment = {value!r} is not one of {', '.join(map(repr, target_names()))}"
                          f"{extra}")
    return value


def _names(section: str, key: str, value: Any) -> tuple[str, ...]:
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        raise ConfigError(f"[{section}] {key} must be a non-empty list of metric names (strings), got {value!r}")
    return tuple(value)


@dataclass(frozen=True)
class StudySection:
    """``[study]``: the target, how many runs per point, where the results go."""

    name: str | None = setting(None, "the study's name (default: the experiment's)", Text(nonempty=True),
                               example="spacing")
    experiment: str | None = setting(None, 'spacing, intrusion, tracking, speed, render (+ config = "x.toml"), '
                                     "design (required)", _experiment, example="spacing", shown=True)
    config: str | None = setting(None, 'experiment = "render" only: the render config, relative to this file',
                                 Text(nonempty=True), example="render.toml")
    seed: int = setting(0, "seed of the study's random streams: same seed, same numbers", Integer(minimum=0))
    replicates: int = setting(2, "runs per point: a metric is their mean, <metric>_stderr its standard error",
                              Integer(minimum=1, maximum=MAX_REPLICATES))
    common_random_numbers: bool = setting(True, "the same seed stream at every point (false: a seed per point)",
                                          Flag())
    out_dir: str | None = setting(None, "default: out/studies/<name>; relative to this file", Text(nonempty=True),
                                  example="out/studies/spacing")


@dataclass(frozen=True)
class RandomSample:
    """The sample size and seed of ``[random]`` (its other keys are ``param = [low, high]`` ranges)."""

    n: int | None = setting(None, "points to sample (required; --quick: at most 4)", Integer(), example=20,
                            shown=True)
    seed: int = setting(0, "seed of the sample (its own: [study] seed does not move the points)",
                        Integer(minimum=0))


@dataclass(frozen=True)
class MetricsSection:
    """``[metrics]``: which of the target's metrics the result keeps."""

    keep: tuple[str, ...] | None = setting(None, "default: all the experiment's metrics", _names,
                                           example=("avg_before_pct", "avg_after_pct"))


def study_schema() -> Schema:
    """The sections of a study file; the free tables' examples use the spacing target's parameters."""
    depth = toml_value(study_target({"name": "spacing"}).parameters["calibration_depth_m"])
    return Schema(
        "mincam-sim study run STUDY.toml (written by `mincam-sim config-example --study`): a target, its\n"
        "parameter points and the metrics to keep. Units are in the parameter names.",
        (Part("study", StudySection),
         Part("fixed", intro="Parameters held at one value (the others keep the experiment's defaults):",
              example=f"calibration_depth_m = {depth}"),
         Part("grid", intro="The full product of these lists (the result's dimensions); or [points] or [random]:",
              example="spacing_m = [0.0, 0.033, 0.1]\ndepth_m = [0.5, 1.0]"),
         Part("points", commented=True, intro="Instead of [grid]: an explicit list of points (equal lengths), one "
              "dimension \"point\":", example="spacing_m = [0.0, 0.033]\ndepth_m = [0.5, 1.0]"),
         Part("random", RandomSample, commented=True, intro="Or a random sample, one dimension \"point\": "
              "param = [low, high] ranges:", example="spacing_m = [0.0, 0.1]"),
         Part("quick", intro="With --quick: lists replace [grid] lists, single values replace [fixed] ones:",
              example="spacing_m = [0.0, 0.033]"),
         Part("metrics", MetricsSection)),
    )


def study_example_toml() -> str:
    """The documented study file (a small spacing study), every ``[study]`` key with its default."""
    return study_schema().example()


@dataclass
class StudySpec:
    """A validated study: the target, the points (as parameter dicts), the result's dimensions."""

    name: str
    experiment: StudyExperiment
    seed: int
    out_dir: Path
    dims: dict[str, list]  # dimension -> coordinate values ("point" for lists and random samples)
    points: list[dict] = field(default_factory=list)  # full parameter dict of every point
    indices: list[tuple[int, ...]] = field(default_factory=list)  # its position along the dims
    metrics: tuple[str, ...] = ()
    raw: dict = field(default_factory=dict)
    replicates: int = 2
    common_random_numbers: bool = True

    @property
    def fixed(self) -> dict:
        """The parameters every point shares (those that are not a dimension)."""
        return {k: v for k, v in self.points[0].items() if k not in self.dims} if self.points else {}


def _flatten(table: dict, prefix: str = "") -> dict:
    """Nested tables (TOML dotted keys: ``mincam.d_f_m = [...]``) as dotted names."""
    out = {}
    for key, value in table.items():
        if isinstance(value, dict):
            out.update(_flatten(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def _hint(experiment: StudyExperiment) -> str:
    if experiment.name == "intrusion":
        return " (the screen boundary sweep over spacing and depth is experiment \"spacing\")"
    return ""


def _values(section: str, key: str, value: Any, experiment: StudyExperiment, unique: bool = True) -> list:
    if key not in experiment.parameters:
        near = closest(key, experiment.parameters)
        guess = f" (did you mean {near}?)" if near else ""
        raise ConfigError(f"[{section}] {key}: not a parameter of experiment {experiment.name!r}{guess}"
                          f"{_hint(experiment)}; choose from {', '.join(sorted(experiment.parameters))}")
    if not isinstance(value, list) or not value:
        raise ConfigError(f"[{section}] {key} must be a non-empty list of numbers, got {value!r}")
    integer = key in experiment.integer_parameters()
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v):
            raise ConfigError(f"[{section}] {key}: every value must be a finite number, got {v!r}")
        if integer and not isinstance(v, int):
            raise ConfigError(f"[{section}] {key} is an integer parameter, got {v!r}; write whole numbers "
                              f"like {int(v)} (no decimal point)")
        out.append(v)
    if unique and len(set(out)) != len(out):
        twice = sorted({v for v in out if out.count(v) > 1})
        raise ConfigError(f"[{section}] {key} lists {', '.join(map(repr, twice))} more than once; give each value "
                          "once (a grid axis needs distinct coordinates; use [study] replicates for repeats)")
    return out


def duration_text(seconds: float) -> str:
    """A duration as it reads best: seconds, minutes or hours."""
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.3g} h"


def _check_size(n_points: int, experiment: StudyExperiment, replicates: int, quick: bool, max_points: int) -> None:
    if n_points > max_points:
        per_point = experiment.seconds_per_point[0 if quick else 1] * replicates
        raise ConfigError(f"the study has {n_points:,} points (limit {max_points:,}): about "
                          f"{duration_text(n_points * per_point)} of one worker at ~{per_point:g} s a point; shrink "
                          f"the grid or raise the limit with --max-points {n_points} (max_points={n_points})")


def load_study(source: str | Path | dict, quick: bool = False, base_dir: str | Path | None = None,
               max_points: int = DEFAULT_MAX_POINTS) -> StudySpec:
    """Parse and validate a study (TOML file, TOML text or dict); ``quick`` applies the ``[quick]`` table.

    Raises
    ------
    ConfigError
        One line naming the field and the fix (see the module docstring for what is refused).
    """
    raw, base, _ = read_document(source, base_dir, kind="study")
    tables = study_schema().tables(raw)
    study, experiment = _study_target(tables, base)
    name = study.experiment if study.name is None else study.name
    out_dir = f"out/studies/{name}" if study.out_dir is None else study.out_dir
    out = Path(out_dir) if Path(out_dir).is_absolute() else base / out_dir
    if isinstance(max_points, bool) or not isinstance(max_points, int) or max_points < 1:
        raise ConfigError(f"--max-points must be an integer >= 1, got {max_points!r}")
    kind, table, fixed_table, quick_table = _sweep_tables(raw, tables, quick)
    fixed = _fixed_point(experiment, fixed_table, quick_table)
    size = (experiment, study.replicates, quick, max_points)
    if kind == "grid":
        dims, points, indices = _grid_points(table, fixed, quick_table, size)
    elif kind == "points":
        dims, points, indices = _listed_points(table, fixed, size)
    else:
        dims, points, indices = _random_points(table, fixed, size)
    keep = _kept_metrics(tables, experiment)
    return StudySpec(name, experiment, study.seed, out, dims, points, indices, tuple(keep), raw, study.replicates,
                     study.common_random_numbers)


def _study_target(tables: dict, base: Path) -> tuple[StudySection, StudyExperiment]:
    """The ``[study]`` section and its target (a render target's config resolved against ``base``)."""
    study: StudySection = read_section("study", tables["study"], StudySection)
    if study.experiment is None:
        raise ConfigError(f"[study] experiment is required: one of {', '.join(map(repr, target_names()))}")
    ref = {"name": study.experiment}
    if study.experiment == "render":
        if study.config is None:
            raise ConfigError("[study] experiment = \"render\" needs config = \"path/to/render.toml\" (relative to "
                              "the study file)")
        ref["config"] = str(Path(study.config) if Path(study.config).is_absolute() else base / study.config)
    elif study.config is not None:
        raise ConfigError(f"[study] config is for experiment = \"render\" only (experiment is "
                          f"{study.experiment!r})")
    return study, study_target(ref)


def _sweep_tables(raw: dict, tables: dict, quick: bool) -> tuple[str, dict, dict, dict]:
    """The sweep's kind and table, the ``[fixed]`` table and the ``[quick]`` one (empty without ``quick``), flat.

    With ``quick``, a ``[quick]`` list replaces the sweep's list of that name and a single value replaces (or adds)
    a ``[fixed]`` one; a ``[random]`` study takes no ``[quick]`` ranges.
    """
    kinds = [k for k in ("grid", "points", "random") if k in raw]
    if len(kinds) != 1:
        raise ConfigError("a study needs exactly one of [grid], [points] or [random]")
    kind = kinds[0]
    table = _flatten(tables[kind])
    fixed_table = _flatten(tables["fixed"])
    quick_table = _flatten(tables["quick"]) if quick else {}
    if kind == "random":
        swept = set(table) - {"n", "seed"}
    else:
        swept = set(table)
    both = sorted(swept & set(fixed_table))
    if both:
        raise ConfigError(f"{', '.join(both)} is both in [fixed] and in [{kind}]; keep it in one of them")
    for key, value in quick_table.items():
        if key in swept and kind != "random":
            table[key] = value
        elif key in swept or key in ("n", "seed"):
            raise ConfigError(f"[quick] {key}: a [random] study takes no [quick] ranges (--quick keeps at most 4 "
                              "points)")
        else:
            fixed_table[key] = value  # a single value replaces the [fixed] (or default) one
    return kind, table, fixed_table, quick_table


def _fixed_point(experiment: StudyExperiment, fixed_table: dict, quick_table: dict) -> dict:
    """The experiment's default parameters with the ``[fixed]`` (and ``[quick]``) values checked and put in."""
    fixed = dict(experiment.parameters)
    for key, value in fixed_table.items():
        fixed[key] = _values("fixed" if key not in quick_table else "quick", key, [value], experiment)[0]
    return fixed


# The sweeps' shared arguments for _check_size: (experiment, replicates, quick, max_points).
_Size = tuple[StudyExperiment, int, bool, int]
# A sweep: the result's dimensions, every point's parameters and its position along the dimensions.
_Sweep = tuple[dict[str, list], list[dict], list[tuple[int, ...]]]


def _grid_points(table: dict, fixed: dict, quick_table: dict, size: _Size) -> _Sweep:
    """``[grid]``: the full product of the lists, one dimension per parameter."""
    experiment = size[0]
    dims = {key: _values("grid" if key not in quick_table else "quick", key, v, experiment)
            for key, v in table.items()}
    if not dims:
        raise ConfigError("[grid] needs at least one parameter list")
    _check_size(math.prod(len(v) for v in dims.values()), *size)
    points: list[dict] = []
    indices: list[tuple[int, ...]] = []
    for idx in itertools.product(*(range(len(v)) for v in dims.values())):
        values = {key: dims[key][i] for key, i in zip(dims, idx, strict=True)}
        points.append({**fixed, **values})
        indices.append(idx)
    return dims, points, indices


def _listed_points(table: dict, fixed: dict, size: _Size) -> _Sweep:
    """``[points]``: the i-th value of every list is point i (equal lengths, no point twice), dimension "point"."""
    experiment = size[0]
    lists = {key: _values("points", key, v, experiment, unique=False) for key, v in table.items()}
    if not lists:
        raise ConfigError("[points] needs at least one parameter list")
    lengths = {len(v) for v in lists.values()}
    if len(lengths) != 1:
        raise ConfigError(f"[points] lists must have equal lengths, got {sorted(lengths)}")
    n = lengths.pop()
    _check_size(n, *size)
    rows = [tuple(v[i] for v in lists.values()) for i in range(n)]
    if len(set(rows)) != n:
        raise ConfigError("[points] lists the same point more than once; give each point once (use [study] "
                          "replicates for repeats)")
    dims = {"point": list(range(n))}
    points = [{**fixed, **{key: v[i] for key, v in lists.items()}} for i in range(n)]
    return dims, points, [(i,) for i in range(n)]


def _random_points(table: dict, fixed: dict, size: _Size) -> _Sweep:
    """``[random]``: ``n`` points drawn uniformly in the ``[low, high]`` ranges (own seed), dimension "point"."""
    experiment, quick = size[0], size[2]
    sample: RandomSample = read_section("random", {k: table.pop(k) for k in ("n", "seed") if k in table},
                                        RandomSample)
    if sample.n is None:
        raise ConfigError("[random] n is required: the number of points to sample (e.g. n = 20)")
    n, rseed = sample.n, sample.seed
    if quick:
        n = min(n, 4)
    _check_size(n, *size)
    ranges = {}
    for key, v in table.items():
        if key in experiment.integer_parameters():
            raise ConfigError(f"[random] {key} is an integer parameter; sample it with a [grid] or [points] "
                              "list instead")
        lo_hi = _values("random", key, v, experiment, unique=False)
        if len(lo_hi) != 2 or lo_hi[0] > lo_hi[1]:
            raise ConfigError(f"[random] {key} must be [low, high], got {v!r}")
        ranges[key] = lo_hi
    rng = np.random.default_rng(rseed)
    dims = {"point": list(range(n))}
    points = [{**fixed, **{k: float(rng.uniform(lo, hi)) for k, (lo, hi) in ranges.items()}} for _ in range(n)]
    return dims, points, [(i,) for i in range(n)]


def _kept_metrics(tables: dict, experiment: StudyExperiment) -> list[str]:
    """``[metrics] keep`` (default: all the target's metrics), checked against the target's metrics."""
    chosen = read_section("metrics", tables["metrics"], MetricsSection).keep
    keep = list(experiment.metrics) if chosen is None else list(chosen)
    if any(m not in experiment.metrics for m in keep):
        raise ConfigError(f"[metrics] keep must list metrics of {experiment.name!r}: {', '.join(experiment.metrics)}")
    if len(set(keep)) != len(keep):
        raise ConfigError("[metrics] keep lists a metric more than once")
    return keep
