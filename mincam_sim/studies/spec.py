"""A study file: which experiment, which parameter points, which metrics (TOML, validated like ``render``).

```toml
[study]
name = "spacing"
experiment = "spacing"         # spacing, intrusion, tracking, speed, render (+ config = "x.toml"), design
seed = 0
replicates = 2                 # runs per point: the metric is their mean, <metric>_stderr its standard error
common_random_numbers = true   # the same seed stream at every point (false: a seed per point)
out_dir = "../../out/studies/spacing"   # relative to this file

[fixed]                        # parameters held at one value (others keep the experiment's defaults)
calibration_depth_m = 0.5

[grid]                         # the full product of these lists (dimensions of the result)
spacing_m = [0.0, 0.02, 0.033, 0.06, 0.1]
depth_m = [0.3, 0.5, 1.0]

[quick]                        # with --quick: lists replace [grid] lists, single values replace [fixed] ones
spacing_m = [0.0, 0.033]
depth_m = [0.5, 1.0]

[metrics]
keep = ["avg_before_pct", "avg_after_pct"]   # default: all the experiment's metrics
```

Instead of ``[grid]``, ``[points]`` gives an explicit list (``spacing_m = [...]``, ``depth_m = [...]``, equal
lengths) or ``[random]`` a random sample (``n = 20``, ``seed = 1``, and ``param = [low, high]`` ranges); both
give one dimension ``point``. A render config's keys are dotted: ``mincam.d_f_m = [0.001, 0.002]``.

Refused, one line each: an unknown parameter, a non-integer value of an integer parameter, a key both in
``[fixed]`` and ``[grid]``, a value twice in one grid list, and a grid of more than ``max_points`` points (the
message gives the count and the estimated time; ``--max-points`` raises the limit).
"""

from __future__ import annotations

import itertools
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError
from .points import StudyExperiment, study_target

SECTIONS = {"study", "fixed", "grid", "points", "random", "quick", "metrics"}
STUDY_KEYS = ("name", "experiment", "seed", "out_dir", "replicates", "common_random_numbers", "config")
DEFAULT_MAX_POINTS = 10_000
MAX_REPLICATES = 1000


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


def _table(raw: dict, name: str) -> dict:
    value = raw.get(name, {})
    if not isinstance(value, dict):
        raise ConfigError(f"[{name}] must be a table, got {type(value).__name__}")
    return value


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
        raise ConfigError(f"[{section}] {key}: not a parameter of experiment {experiment.name!r}{_hint(experiment)}; "
                          f"choose from {', '.join(sorted(experiment.parameters))}")
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


def _hours(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.3g} h"


def _check_size(n_points: int, experiment: StudyExperiment, replicates: int, quick: bool, max_points: int) -> None:
    if n_points > max_points:
        per_point = experiment.seconds_per_point[0 if quick else 1] * replicates
        raise ConfigError(f"the study has {n_points:,} points (limit {max_points:,}): about "
                          f"{_hours(n_points * per_point)} of one worker at ~{per_point:g} s a point; shrink the "
                          f"grid or raise the limit with --max-points {n_points} (max_points={n_points})")


def _read(source: str | Path | dict, base_dir: str | Path | None) -> tuple[dict, Path]:
    if isinstance(source, dict):
        return source, Path(base_dir or ".")
    path = Path(source)
    if "\n" not in str(source) and path.suffix == ".toml":
        if not path.is_file():
            raise ConfigError(f"study file {path} does not exist")
        text, base = path.read_text(encoding="utf-8"), path.parent
    else:
        text, base = str(source), Path(base_dir or ".")
    try:
        return tomllib.loads(text), base
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"study is not valid TOML: {err}") from None


def _integer(key: str, value: Any, minimum: int, maximum: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum or (maximum and value > maximum):
        bound = f" and <= {maximum}" if maximum else ""
        raise ConfigError(f"[study] {key} must be an integer >= {minimum}{bound}, got {value!r}")
    return value


def load_study(source: str | Path | dict, quick: bool = False, base_dir: str | Path | None = None,
               max_points: int = DEFAULT_MAX_POINTS) -> StudySpec:
    """Parse and validate a study (TOML file, TOML text or dict); ``quick`` applies the ``[quick]`` table.

    Raises
    ------
    ConfigError
        One line naming the field and the fix (see the module docstring for what is refused).
    """
    raw, base = _read(source, base_dir)
    unknown = sorted(set(raw) - SECTIONS)
    if unknown:
        raise ConfigError(f"unknown section(s) {unknown} in the study; allowed: {sorted(SECTIONS)}")
    study = _table(raw, "study")
    bad = sorted(set(study) - set(STUDY_KEYS))
    if bad:
        raise ConfigError(f"[study]: unknown key(s) {bad}; allowed: {', '.join(STUDY_KEYS)}")
    exp_name = study.get("experiment")
    ref = {"name": exp_name}
    if exp_name == "render":
        config = study.get("config")
        if not isinstance(config, str) or not config:
            raise ConfigError("[study] experiment = \"render\" needs config = \"path/to/render.toml\" (relative to "
                              "the study file)")
        ref["config"] = str(Path(config) if Path(config).is_absolute() else base / config)
    elif "config" in study:
        raise ConfigError(f"[study] config is for experiment = \"render\" only (experiment is {exp_name!r})")
    experiment = study_target(ref)
    name = study.get("name", exp_name)
    if not isinstance(name, str) or not name:
        raise ConfigError(f"[study] name must be a non-empty string, got {name!r}")
    seed = _integer("seed", study.get("seed", 0), 0)
    replicates = _integer("replicates", study.get("replicates", 2), 1, MAX_REPLICATES)
    crn = study.get("common_random_numbers", True)
    if not isinstance(crn, bool):
        raise ConfigError(f"[study] common_random_numbers must be true or false, got {crn!r}")
    out_dir = study.get("out_dir", f"out/studies/{name}")
    if not isinstance(out_dir, str) or not out_dir:
        raise ConfigError(f"[study] out_dir must be a path string, got {out_dir!r}")
    out = Path(out_dir) if Path(out_dir).is_absolute() else base / out_dir
    if isinstance(max_points, bool) or not isinstance(max_points, int) or max_points < 1:
        raise ConfigError(f"--max-points must be an integer >= 1, got {max_points!r}")

    kinds = [k for k in ("grid", "points", "random") if k in raw]
    if len(kinds) != 1:
        raise ConfigError("a study needs exactly one of [grid], [points] or [random]")
    kind = kinds[0]
    table = _flatten(_table(raw, kind))
    fixed_table = _flatten(_table(raw, "fixed"))
    quick_table = _flatten(_table(raw, "quick")) if quick else {}
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
    fixed = dict(experiment.parameters)
    for key, value in fixed_table.items():
        fixed[key] = _values("fixed" if key not in quick_table else "quick", key, [value], experiment)[0]

    points: list[dict] = []
    indices: list[tuple[int, ...]] = []
    if kind == "grid":
        dims = {key: _values("grid" if key not in quick_table else "quick", key, v, experiment)
                for key, v in table.items()}
        if not dims:
            raise ConfigError("[grid] needs at least one parameter list")
        _check_size(math.prod(len(v) for v in dims.values()), experiment, replicates, quick, max_points)
        for idx in itertools.product(*(range(len(v)) for v in dims.values())):
            values = {key: dims[key][i] for key, i in zip(dims, idx, strict=True)}
            points.append({**fixed, **values})
            indices.append(idx)
    elif kind == "points":
        lists = {key: _values("points", key, v, experiment, unique=False) for key, v in table.items()}
        if not lists:
            raise ConfigError("[points] needs at least one parameter list")
        lengths = {len(v) for v in lists.values()}
        if len(lengths) != 1:
            raise ConfigError(f"[points] lists must have equal lengths, got {sorted(lengths)}")
        n = lengths.pop()
        _check_size(n, experiment, replicates, quick, max_points)
        rows = [tuple(v[i] for v in lists.values()) for i in range(n)]
        if len(set(rows)) != n:
            raise ConfigError("[points] lists the same point more than once; give each point once (use [study] "
                              "replicates for repeats)")
        dims = {"point": list(range(n))}
        for i in range(n):
            points.append({**fixed, **{key: v[i] for key, v in lists.items()}})
            indices.append((i,))
    else:
        n = table.pop("n", None)
        rseed = table.pop("seed", 0)
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise ConfigError(f"[random] n must be an integer >= 1, got {n!r}")
        if isinstance(rseed, bool) or not isinstance(rseed, int) or rseed < 0:
            raise ConfigError(f"[random] seed must be an integer >= 0, got {rseed!r}")
        if quick:
            n = min(n, 4)
        _check_size(n, experiment, replicates, quick, max_points)
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
        for i in range(n):
            points.append({**fixed, **{k: float(rng.uniform(lo, hi)) for k, (lo, hi) in ranges.items()}})
            indices.append((i,))
    keep = _table(raw, "metrics").get("keep", list(experiment.metrics))
    if not isinstance(keep, list) or not keep or any(m not in experiment.metrics for m in keep):
        raise ConfigError(f"[metrics] keep must list metrics of {experiment.name!r}: {', '.join(experiment.metrics)}")
    if len(set(keep)) != len(keep):
        raise ConfigError("[metrics] keep lists a metric more than once")
    return StudySpec(name, experiment, seed, out, dims, points, indices, tuple(keep), raw, replicates, crn)
