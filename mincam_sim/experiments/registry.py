"""The one registry of what ``reproduce``, ``study`` and ``demo`` run, and the runner that writes
``results.json``.

``REGISTRY`` holds the experiments. Each declares, once, both how it runs as a reproduction (its parameters
dataclass, quick-mode overrides and ``Experiment.run``) and how one study point of it runs (its
study parameters, metrics and typical seconds: ``Experiment.study_target``). ``STUDY_ONLY``
holds the two study targets that are no experiment: a render config and the mask design. ``study_target``
looks any of them up by name; :mod:`mincam_sim.studies` reads nothing else.

A reproduce config is TOML with a ``[setup]`` section and one section per experiment, each validated against
its dataclass (unknown keys, wrong types and bad values name the field)."""

from __future__ import annotations

import dataclasses
import json
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mincam_sim.configuration.config import dataclass_from_section, read_sections
from mincam_sim.errors import ConfigError, IgnoredSettingWarning, StaleResultError, StoreError
from mincam_sim.experiments.base import Experiment, ExperimentResult
from mincam_sim.experiments.intrusion import Intrusion
from mincam_sim.experiments.setup import Setup
from mincam_sim.experiments.spacing import Spacing
from mincam_sim.experiments.speed import Speed
from mincam_sim.experiments.study_targets import StudyExperiment, design_target, render_target_from_ref
from mincam_sim.experiments.tracking import Tracking
from mincam_sim.render import backend
from mincam_sim.storage.atomic import atomic_write_text
from mincam_sim.storage.identity import build_identity, fingerprint
from mincam_sim.storage.store import check_identity

REGISTRY: dict[str, Experiment] = {e.name: e for e in (Intrusion(), Tracking(), Speed(), Spacing())}
#: The paper's experiments, in the paper's order (what ``reproduce all`` runs).
EXPERIMENTS: tuple[str, ...] = tuple(name for name, e in REGISTRY.items() if e.in_paper)

#: Study targets that are no experiment, by name: how each is built from a study's reference (``{"name": ...}``,
#: for ``render`` with its ``config`` file).
STUDY_ONLY: dict[str, Callable[[dict], StudyExperiment]] = {"render": render_target_from_ref, "design": design_target}

DEFINITIONS = {
    "position_error_pct": "|predicted - ground truth| (Euclidean in 2D; per_axis: |dx|, |dy| pooled) / calibrated "
                          "range (field_m) x 100",
    "ground_truth": "object: centroid of the object's silhouette in the centre camera (the paper's); change: "
                    "centroid of the binary change (object and shadow); each entry's ground_truth names the one "
                    "its headline uses",
    "speed_error_pct": "|predicted - true speed| / true speed x 100",
}


def experiment(name: str) -> Experiment:
    """The registered experiment ``name`` (a clear error listing the choices otherwise)."""
    if name not in REGISTRY:
        raise ConfigError(f"unknown experiment {name!r}: choose from {', '.join(REGISTRY)}")
    return REGISTRY[name]


def target_names() -> tuple[str, ...]:
    """Every name ``[study] experiment`` accepts: the registry's experiments, ``render`` and ``design``."""
    return (*REGISTRY, *STUDY_ONLY)


def study_target(ref: dict) -> StudyExperiment:
    """The study target ``ref["name"]`` (``ref["config"]``: the render config file of ``render``); a problem with
    that file is one ConfigError that names it (``[study] config = 'sweep.toml': unknown section [wrld] ...``)."""
    name = ref.get("name")
    if name in STUDY_ONLY:
        try:
            target = STUDY_ONLY[name](ref)
        except ConfigError as err:
            config = ref.get("config")
            if not config or str(err).startswith("[study] config"):
                raise
            raise ConfigError(f"[study] config = {str(config)!r}: {err}") from None
        return _with_render_budget(target) if name == "render" else target
    if name in REGISTRY:
        return _with_reproduce_checks(REGISTRY[name])
    raise ConfigError(f"[study] experiment = {name!r} is not one of {', '.join(map(repr, target_names()))}")


def _with_render_budget(target: StudyExperiment) -> StudyExperiment:
    """The ``render`` target ``target`` whose points are also refused, before any runs, where ``mincam-sim render``
    would refuse the point's config: estimated to take longer than its default limit
    (:data:`~mincam_sim.runs.jobs.DEFAULT_TIME_LIMIT_S`, 4 h), or holding more than the memory free now. A study's
    own time estimate counts a typical point, not this one's samples."""
    from mincam_sim.experiments.study_targets import _render_config
    from mincam_sim.runs.jobs import DEFAULT_TIME_LIMIT_S, _duration, check_memory, estimate_bytes, estimate_seconds

    config = target.ref["config"]
    first = target.check

    def check(params: dict, quick: bool) -> None:
        if first is not None:
            first(params, quick)
        cfg = _render_config(config, params, 0)
        seconds, what = estimate_seconds(cfg)
        if seconds > DEFAULT_TIME_LIMIT_S:
            key = "[run] samples_per_texel" if cfg.run.budget.samples_per_texel is not None else "[run] spp"
            raise ConfigError(f"its render would take about {_duration(seconds)} ({what}), over the "
                              f"{_duration(DEFAULT_TIME_LIMIT_S)} that `mincam-sim render` allows: lower {key} "
                              "(or the frames) for this point")
        n_bytes, held = estimate_bytes(cfg)
        check_memory(n_bytes, held, "fewer frames, fewer mixels or a lower [screen] resolution")

    return dataclasses.replace(target, check=check)


def _with_reproduce_checks(experiment) -> StudyExperiment:
    """``experiment`` as a study target whose points are also checked as a reproduce file's values are
    (:func:`~.input_checks.check_reproduce`: the lamp above the mincam, steps that do not fit, too few rays)."""
    from mincam_sim.experiments.input_checks import check_reproduce

    target = experiment.study_target()
    if experiment.name not in EXPERIMENTS:  # the spacing study's points build their own set-up
        return target

    def check(params: dict, quick: bool) -> None:
        experiment.study_check(params, quick)
        setup, own = experiment.study_inputs(params, 0, quick)
        check_reproduce(setup, {experiment.name: own})

    return dataclasses.replace(target, check=check)


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
        if sections.get("setup", {}).get("quick") is False:
            warnings.warn("[setup] quick = false is ignored: --quick runs quick mode", IgnoredSettingWarning,
                          stacklevel=2)
        setup = dataclasses.replace(setup, quick=True)
    params = {name: e.params(setup.quick, sections.get(name)) for name, e in REGISTRY.items()}
    return setup, params


def reproduce(names, setup: Setup, out_dir: str | Path, show_progress: bool = False,
              params: dict[str, Any] | None = None, overwrite: bool = False,
              say: Callable[[str], None] | None = None) -> dict:
    """Run experiments by name; write ``results.json`` (atomically, after each experiment) and plots.

    An out dir belongs to one set-up: the set-up, the library versions and the backend are recorded in
    ``reproduce_identity.json``. A rerun with the same record reuses every experiment already in
    ``results.json`` with the same parameters (so a killed ``reproduce all`` resumes with the next experiment)
    and runs the others; a different record is refused, naming what changed. ``overwrite`` drops the old
    results first and recomputes everything. So ``results.json`` never holds numbers of two set-ups under one
    ``meta``. Each entry lists the files its experiment wrote in ``out_dir`` (``files``): an experiment
    whose files are no longer all there is run again, and ``say`` (default: a line on stderr) names them.

    Returns the results as written: one entry per experiment (:meth:`ExperimentResult.as_dict` plus its
    ``params`` and their ``params_key``) and ``meta`` (``meta["reused"]``: the experiments of ``names`` that
    were taken from an earlier run).
    """
    for name in names:
        experiment(name)  # unknown names fail before anything is written
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results_path = out_dir / "results.json"
    if results_path.exists() and not (out_dir / IDENTITY_NAME).exists() and not overwrite:
        raise StaleResultError(f"{results_path} has no record of the set-up it was made with (an older "
                               "mincam_sim); rerun with --overwrite (overwrite=True) to replace it, or choose "
                               "another output directory")
    identity = build_identity("reproduce", {"setup": setup.as_dict()}, variant=backend.variant())
    same = check_identity(out_dir, identity, overwrite=overwrite, name=IDENTITY_NAME)
    if same:
        results = _read_results(results_path)
    else:
        results_path.unlink(missing_ok=True)  # another set-up's numbers must not survive a kill of this run
        results = {}
    reused = []
    for name in names:
        exp = experiment(name)
        p = (params or {}).get(name) or exp.params(setup.quick)
        params_key = _params_key(exp, p)
        old = results.get(name)
        if isinstance(old, dict) and old.get("params_key") == params_key:
            lost = _lost_files(out_dir, old.get("files"))
            if not lost:
                reused.append(name)
                continue
            (say or _stderr_say)(f"{out_dir} lacks {', '.join(lost[:4])}{' ...' if len(lost) > 4 else ''} of "
                                 f"experiment {name}: running it again")
        before = _listing(out_dir)
        t = time.perf_counter()
        result: ExperimentResult = exp.run(setup, p, out_dir, show_progress=show_progress)
        result.seconds = time.perf_counter() - t
        after = _listing(out_dir)
        files = sorted(path for path, stamp in after.items() if before.get(path) != stamp)
        results[name] = {**result.as_dict(), "params": _jsonable(p), "params_key": params_key, "files": files}
        results["meta"] = _meta(setup, reused)
        atomic_write_text(results_path, json.dumps(results, indent=1, default=float))
    if reused:
        results["meta"] = _meta(setup, reused)
        atomic_write_text(results_path, json.dumps(results, indent=1, default=float))
    return results


IDENTITY_NAME = "reproduce_identity.json"
#: Files of a reproduce folder that belong to no one experiment (not listed in an entry's ``files``).
_SHARED_FILES = frozenset({"results.json", IDENTITY_NAME, ".mincam.lock"})


def _stderr_say(message: str) -> None:
    import sys

    print(f"mincam-sim: {message}", file=sys.stderr)


def _listing(folder: Path) -> dict[str, tuple[int, int]]:
    """The files in ``folder`` (the experiments write their plots and data there, not in folders below, which
    are not looked into: an output folder may be a large one of the user's) but the shared ones, by name: (size
    [bytes], modification time [ns])."""
    listing = {}
    for path in folder.iterdir():
        if path.name in _SHARED_FILES:
            continue
        try:
            info = path.stat()
        except OSError:  # removed meanwhile: not a file of the folder
            continue
        if path.is_file():
            listing[path.name] = (info.st_size, info.st_mtime_ns)
    return listing


def _lost_files(folder: Path, files: Any) -> list[str]:
    """The files an entry lists (``files``; an entry of an older run lists none) that ``folder`` lacks."""
    if not isinstance(files, list):
        return []
    return [f for f in files if isinstance(f, str) and not (folder / f).is_file()]


def _meta(setup: Setup, reused: list[str]) -> dict:
    return {"setup": setup.as_dict(), **backend.describe(), "definitions": DEFINITIONS, "reused": list(reused)}


def _read_results(path: Path) -> dict:
    """The experiments' entries of an earlier run of the same set-up (empty if there is none yet)."""
    if not path.exists():
        return {}
    try:
        results = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise StoreError(f"{path} is torn or unreadable ({err}); rerun with --overwrite (overwrite=True) to "
                         "recompute it, or choose another output directory") from None
    if not isinstance(results, dict):
        raise StoreError(f"{path} is not a reproduce results file (a JSON object); rerun with --overwrite "
                         "(overwrite=True) to recompute it, or choose another output directory")
    return results


def _params_key(exp: Experiment, params: Any) -> str:
    """What a result entry was computed with: the parameters and, once raised, the experiment's code version."""
    jsonable = _jsonable(params)
    return fingerprint(jsonable if exp.version == 1 else {"params": jsonable, "version": exp.version})


def _jsonable(params: Any) -> dict:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(params).items()}
