"""A study file: which experiment, which parameter points, which metrics (TOML, validated like ``render``).

```toml
[study]
name = "spacing"
experiment = "intrusion"       # a name from mincam_sim.studies.STUDY_EXPERIMENTS
seed = 0
out_dir = "../../out/studies/spacing"   # relative to this file

[fixed]                        # parameters held at one value (others keep the experiment's defaults)
calibration_depth_m = 0.5

[grid]                         # the full product of these lists (dimensions of the result)
spacing_m = [0.0, 0.02, 0.033, 0.06, 0.1]
depth_m = [0.3, 0.5, 1.0]

[quick]                        # replaces [grid] lists with --quick
spacing_m = [0.0, 0.033]
depth_m = [0.5, 1.0]

[metrics]
keep = ["avg_before_pct", "avg_after_pct"]   # default: all the experiment's metrics
```

Instead of ``[grid]``, ``[points]`` gives an explicit list (``spacing_m = [...]``, ``depth_m = [...]``, equal
lengths) or ``[random]`` a random sample (``n = 20``, ``seed = 1``, and ``param = [low, high]`` ranges); both
give one dimension ``point``.
"""

from __future__ import annotations

import itertools
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError
from .points import STUDY_EXPERIMENTS, StudyExperiment

SECTIONS = {"study", "fixed", "grid", "points", "random", "quick", "metrics"}


@dataclass
class StudySpec:
    """A validated study: the experiment, the points (as parameter dicts), the result's dimensions."""

    name: str
    experiment: StudyExperiment
    seed: int
    out_dir: Path
    dims: dict[str, list]  # dimension -> coordinate values ("point" for lists and random samples)
    points: list[dict] = field(default_factory=list)  # full parameter dict of every point
    indices: list[tuple[int, ...]] = field(default_factory=list)  # its position along the dims
    metrics: tuple[str, ...] = ()
    raw: dict = field(default_factory=dict)


def _table(raw: dict, name: str) -> dict:
    value = raw.get(name, {})
    if not isinstance(value, dict):
        raise ConfigError(f"[{name}] must be a table, got {type(value).__name__}")
    return value


def _values(section: str, key: str, value: Any, experiment: StudyExperiment) -> list:
    if key not in experiment.parameters:
        raise ConfigError(f"[{section}] {key}: not a parameter of experiment {experiment.name!r}; choose from "
                          f"{', '.join(sorted(experiment.parameters))}")
    if not isinstance(value, list) or not value:
        raise ConfigError(f"[{section}] {key} must be a non-empty list of numbers, got {value!r}")
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v):
            raise ConfigError(f"[{section}] {key}: every value must be a finite number, got {v!r}")
        out.append(v)
    return out


def load_study(source: str | Path | dict, quick: bool = False, base_dir: str | Path | None = None) -> StudySpec:
    """Parse and validate a study (TOML file, TOML text or dict); ``quick`` uses the ``[quick]`` lists."""
    if isinstance(source, dict):
        raw, base = source, Path(base_dir or ".")
    else:
        path = Path(source)
        if "\n" not in str(source) and path.suffix == ".toml":
            if not path.is_file():
                raise ConfigError(f"study file {path} does not exist")
            text, base = path.read_text(), path.parent
        else:
            text, base = str(source), Path(base_dir or ".")
        try:
            raw = tomllib.loads(text)
        except tomllib.TOMLDecodeError as err:
            raise ConfigError(f"study is not valid TOML: {err}") from None
    unknown = sorted(set(raw) - SECTIONS)
    if unknown:
        raise ConfigError(f"unknown section(s) {unknown} in the study; allowed: {sorted(SECTIONS)}")
    study = _table(raw, "study")
    bad = sorted(set(study) - {"name", "experiment", "seed", "out_dir"})
    if bad:
        raise ConfigError(f"[study]: unknown key(s) {bad}; allowed: name, experiment, seed, out_dir")
    exp_name = study.get("experiment")
    if exp_name not in STUDY_EXPERIMENTS:
        raise ConfigError(f"[study] experiment = {exp_name!r} is not one of {', '.join(map(repr, STUDY_EXPERIMENTS))}")
    experiment = STUDY_EXPERIMENTS[exp_name]
    name = study.get("name", exp_name)
    if not isinstance(name, str) or not name:
        raise ConfigError(f"[study] name must be a non-empty string, got {name!r}")
    seed = study.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError(f"[study] seed must be an integer >= 0, got {seed!r}")
    out_dir = study.get("out_dir", f"out/studies/{name}")
    if not isinstance(out_dir, str) or not out_dir:
        raise ConfigError(f"[study] out_dir must be a path string, got {out_dir!r}")
    out = Path(out_dir) if Path(out_dir).is_absolute() else base / out_dir

    fixed = dict(experiment.parameters)
    for key, value in _table(raw, "fixed").items():
        fixed[key] = _values("fixed", key, [value], experiment)[0]
    kinds = [k for k in ("grid", "points", "random") if k in raw]
    if len(kinds) != 1:
        raise ConfigError("a study needs exactly one of [grid], [points] or [random]")
    kind = kinds[0]
    table = dict(_table(raw, kind))
    if quick and kind != "random" and raw.get("quick"):
        table = {**table, **_table(raw, "quick")}
    points: list[dict] = []
    indices: list[tuple[int, ...]] = []
    if kind == "grid":
        dims = {key: _values("grid", key, v, experiment) for key, v in table.items()}
        if not dims:
            raise ConfigError("[grid] needs at least one parameter list")
        for idx in itertools.product(*(range(len(v)) for v in dims.values())):
            values = {key: dims[key][i] for key, i in zip(dims, idx, strict=True)}
            points.append({**fixed, **values})
            indices.append(idx)
    elif kind == "points":
        lists = {key: _values("points", key, v, experiment) for key, v in table.items()}
        lengths = {len(v) for v in lists.values()}
        if len(lengths) != 1:
            raise ConfigError(f"[points] lists must have equal lengths, got {sorted(lengths)}")
        n = lengths.pop()
        dims = {"point": list(range(n))}
        for i in range(n):
            points.append({**fixed, **{key: v[i] for key, v in lists.items()}})
            indices.append((i,))
    else:
        n = table.pop("n", None)
        rseed = table.pop("seed", 0)
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise ConfigError(f"[random] n must be an integer >= 1, got {n!r}")
        if quick:
            n = min(n, 4)
        ranges = {}
        for key, v in table.items():
            lo_hi = _values("random", key, v, experiment)
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
    return StudySpec(name, experiment, seed, out, dims, points, indices, tuple(keep), raw)
