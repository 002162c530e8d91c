"""The explicit registry of experiments that ``reproduce``, ``study`` and ``demo`` iterate, and the runner that
writes ``results.json``. A reproduce config is TOML with a ``[setup]`` section and one section per experiment,
each validated against its dataclass (unknown keys, wrong types and bad values name the field)."""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path
from typing import Any

from ..atomic import atomic_write_text
from ..config import dataclass_from_section, read_sections
from ..errors import ConfigError
from ..render import backend
from .base import Experiment, ExperimentResult
from .intrusion import Intrusion
from .setup import Setup
from .spacing import Spacing
from .speed import Speed
from .tracking import Tracking

REGISTRY: dict[str, Experiment] = {e.name: e for e in (Intrusion(), Tracking(), Speed(), Spacing())}
#: The paper's experiments, in the paper's order (what ``reproduce all`` runs).
EXPERIMENTS: tuple[str, ...] = tuple(name for name, e in REGISTRY.items() if e.in_paper)

DEFINITIONS = {
    "position_error_pct": "|predicted - ground truth| (Euclidean in 2D) / calibrated range (field_m) x 100",
    "speed_error_pct": "|predicted - true speed| / true speed x 100",
}


def experiment(name: str) -> Experiment:
    """The registered experiment ``name`` (a clear error listing the choices otherwise)."""
    if name not in REGISTRY:
        raise ConfigError(f"unknown experiment {name!r}: choose from {', '.join(REGISTRY)}")
    return REGISTRY[name]


def load_reproduce_config(source: str | Path | dict | None, quick: bool = False,
                          **setup_overrides: Any) -> tuple[Setup, dict[str, Any]]:
    """The set-up and every experiment's parameters from a reproduce config (``None``: all defaults).

    ``setup_overrides`` (e.g. command-line flags) apply after the ``[setup]`` section; ``quick`` picks each
    experiment's quick-mode defaults before its section applies.
    """
    sections = read_sections(source, ("setup", *REGISTRY)) if source is not None else {}
    setup = dataclass_from_section("setup", sections.get("setup", {}), Setup(quick=quick))
    if setup_overrides:
        setup = dataclass_from_section("command line", setup_overrides, setup)
    if quick:
        setup = dataclasses.replace(setup, quick=True)
    params = {name: e.params(setup.quick, sections.get(name)) for name, e in REGISTRY.items()}
    return setup, params


def reproduce(names, setup: Setup, out_dir: str | Path, show_progress: bool = False,
              params: dict[str, Any] | None = None) -> dict:
    """Run experiments by name; write ``results.json`` (atomically, after each experiment) and plots.

    Returns the results as written: one entry per experiment (:meth:`ExperimentResult.as_dict`) and ``meta``.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results_path = out_dir / "results.json"
    results: dict = json.loads(results_path.read_text()) if results_path.exists() else {}
    for name in names:
        exp = experiment(name)
        p = (params or {}).get(name) or exp.params(setup.quick)
        t = time.perf_counter()
        result: ExperimentResult = exp.run(setup, p, out_dir, show_progress=show_progress)
        result.seconds = time.perf_counter() - t
        results[name] = {**result.as_dict(), "params": _jsonable(p)}
        results["meta"] = {"setup": setup.as_dict(), **backend.describe(), "definitions": DEFINITIONS}
        atomic_write_text(results_path, json.dumps(results, indent=1, default=float))
    return results


def _jsonable(params: Any) -> dict:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(params).items()}
