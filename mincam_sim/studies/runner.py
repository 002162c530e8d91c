"""Run a study's points on ``dask.distributed`` and keep the results as an xarray Dataset in Zarr.

* Each point is one task. ``workers = 1`` runs the points in this process; ``workers >= 2`` starts an embedded
  ``LocalCluster`` of *process* workers (spawned, never forked; one Dr.Jit per process, each with its own
  ``DRJIT_CACHE_DIR`` in a temporary folder removed when the study ends, and a thread pool capped so that
  workers x threads <= cores); ``scheduler=ADDRESS`` uses an existing cluster instead (e.g. one started by
  ``dask-jobqueue`` on Slurm/PBS). ``workers < 1`` is refused.
* Each point runs ``replicates`` times; a metric is the mean over them and ``<metric>_stderr`` its standard
  error (the replicates' spread / sqrt(n); with one replicate, the point's own Monte Carlo standard error where
  it reports one, else NaN). With common random numbers (the default) replicate ``r`` has the same seed at every
  point, so differences along an axis are not seed noise; the seeds depend only on the study seed and ``r``
  (and, without common random numbers, on the point's parameters): 1 or N workers give identical datasets.
* Results go to ``OUT/results.zarr`` (Zarr v2, consolidated metadata, one chunk per point, ``units`` on every
  variable and coordinate) as points finish. After its values, each point gets a completion record
  ``OUT/points/<index>.json`` (written atomically) holding what was stored. A rerun reuses a point only if its
  record matches the store variable by variable; a damaged point is named and computed again.
* ``OUT`` is locked while a study runs: a second study there is refused, naming the holder. The store's
  attributes hold the study's identity (for a render config, its text and what every file it names holds, as
  ``mincam-sim render`` identifies them); a different study in the same directory is refused, naming what
  changed, unless ``overwrite``.
* A failed write (a full disk) raises :class:`~mincam_sim.errors.StoreError` naming the file; the point then
  has no completion record, so nothing half-written is ever reused. A store that lacks a variable or a
  coordinate, or whose coordinates no longer hold the study's values, is refused (``--overwrite`` recomputes).
* Before anything is computed, a study whose estimated time (pending points x replicates x the target's typical
  seconds per point / workers) exceeds ``time_limit_s`` is refused, naming the estimate and ``--time-limit-s``.
* Ctrl-C (SIGINT) stops a study within seconds: a point being written is finished first, the embedded cluster's
  workers are killed, and :class:`StudyInterrupted` (a ``KeyboardInterrupt``) says how many points are kept;
  the same call resumes them bit for bit.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mincam_sim.errors import ConfigError, IgnoredSettingWarning, OutDirLockedError, StaleResultError, StoreError
from mincam_sim.experiments.registry import study_target
from mincam_sim.experiments.study_targets import unit_of
from mincam_sim.progress import progress
from mincam_sim.storage.atomic import atomic_write_json, atomic_write_text
from mincam_sim.storage.identity import build_identity, canonical, diff_identities, fingerprint
from mincam_sim.storage.store import lock_out_dir, remove_if_only_lock, topmost_missing
from mincam_sim.studies.cluster import (
    ENV_THREADS,
    check_scheduler,
    embedded_client,
    held_interrupts,
    raise_if_interrupted,
    scheduler_client,
    watched_interrupts,
    worker_count,
)
from mincam_sim.studies.spec import StudySpec, duration_text

DEFAULT_TIME_LIMIT_S = 24 * 3600.0
STORE_NAME = "results.zarr"
RECORDS_NAME = "points"
HOLDER_NAME = ".study_holder.json"
WORKERS_LOG = "workers.log"  # the embedded cluster's workers' stderr (dask's log, their warnings), appended


def point_seed(study_seed: int, params: dict | None, replicate: int = 0) -> int:
    """The seed of one replicate of a point: a 31-bit hash of the study seed, the replicate and (``params`` not
    None: no common random numbers) the point's parameters."""
    key = {"seed": int(study_seed), "replicate": int(replicate)}
    if params is not None:
        key["params"] = params
    return int(fingerprint(key)[:8], 16) & 0x7FFFFFFF


def point_seeds(spec: StudySpec, params: dict) -> list[int]:
    """The replicate seeds of a point (the same at every point with common random numbers)."""
    return [point_seed(spec.seed, None if spec.common_random_numbers else params, r) for r in range(spec.replicates)]


def variables(spec: StudySpec) -> list[str]:
    """The store's data variables: each metric and its standard error."""
    return [v for m in spec.metrics for v in (m, f"{m}_stderr")]


def compute_point(ref: dict, params: dict, seeds: list[int], quick: bool, metrics: list[str]) -> dict:
    """Run one point's replicates (on a worker or here): ``{metric: mean, metric_stderr: standard error}``.
    Caps Dr.Jit's threads first when the runner asked for it."""
    from mincam_sim.render import backend

    backend.configure_libllvm()  # before Dr.Jit is first imported in this process (Debian's LLVM 15 crashes it)
    threads = os.environ.get(ENV_THREADS)
    if threads:
        backend.cap_threads(int(threads))
    from mincam_sim.estimation.calibration import ExtrapolationWarning

    target = study_target(ref)
    with warnings.catch_warnings():  # studies use calibrations away from their range on purpose: the error shows it
        warnings.simplefilter("ignore", ExtrapolationWarning)
        runs = [target.point(dict(params), int(seed), bool(quick)) for seed in seeds]
    out = {}
    for m in metrics:
        values = np.array([float(r.get(m, np.nan)) for r in runs])
        finite = values[np.isfinite(values)]
        out[m] = float(finite.mean()) if finite.size else np.nan
        if len(runs) >= 2:
            out[f"{m}_stderr"] = float(finite.std(ddof=1) / np.sqrt(finite.size)) if finite.size >= 2 else np.nan
        else:
            out[f"{m}_stderr"] = float(runs[0].get(f"{m}_stderr", np.nan))
    return out


def render_config_inputs(config: str | Path) -> dict:
    """What a render config's numbers are computed from beyond its own text, as ``mincam-sim render``
    identifies them: the ``scene`` (the mincam, each mixel's mask by its content -- ``file:`` images included --
    and the screen) and the ``frames`` (a generated sweep's description, or a ``kind = "npy"`` stack's content).

    Built by the render job's own identity code (:func:`~mincam_sim.runs.jobs.display_job`,
    :meth:`~mincam_sim.render.simulation.Simulation.identity` and
    :meth:`~mincam_sim.render.simulation.Simulation.frames_identity`), so every file that changes a render's
    identity changes a study's; nothing is rendered and Mitsuba is not loaded.

    Parameters
    ----------
    config : str or Path
        The render config file (relative paths in it resolve against its folder).

    Returns
    -------
    dict
        ``{"scene": ..., "frames": ...}`` (JSON-able).

    Raises
    ------
    ConfigError
        The config, or a file it names, is no longer valid (a missing mask image, a malformed frame stack).
    """
    from mincam_sim.configuration.config import load_config
    from mincam_sim.runs.jobs import display_job

    with warnings.catch_warnings():  # its ignored keys were named when the study loaded its target
        warnings.simplefilter("ignore", IgnoredSettingWarning)
        job = display_job(load_config(Path(config)))
    return {"scene": job.sim.identity(), "frames": job.sim.frames_identity(job.frames)}


def study_identity(spec: StudySpec, quick: bool) -> dict:
    """Everything that determines the study's numbers: for a render config, its text and the content of every
    file it names (:func:`render_config_inputs`), not its path."""
    target = dict(spec.experiment.ref)
    if "config" in target:
        path = Path(target["config"])
        target = {"name": target["name"], "config": fingerprint(path.read_text(encoding="utf-8")),
                  **render_config_inputs(path)}
    return canonical(build_identity("study", {
        "experiment": target, "dims": spec.dims, "points": spec.points, "metrics": list(spec.metrics),
        "seed": spec.seed, "replicates": spec.replicates, "common_random_numbers": spec.common_random_numbers,
        "quick": bool(quick)}))


def _label(spec: StudySpec, index: tuple[int, ...]) -> str:
    return ", ".join(f"{d}={spec.dims[d][i]:g}" for d, i in zip(spec.dims, index, strict=True))


def _record_path(records: Path, index: tuple[int, ...]) -> Path:
    return records / ("p_" + "_".join(map(str, index)) + ".json")


def _varying(spec: StudySpec) -> list[str]:
    """Parameters that change across the points of a ``point`` dimension (coordinates along it)."""
    if list(spec.dims) != ["point"]:
        return []
    return [k for k in spec.points[0] if len({repr(p[k]) for p in spec.points}) > 1]


def _empty_dataset(spec: StudySpec, identity: dict):
    import xarray as xr

    dims = tuple(spec.dims)
    shape = tuple(len(v) for v in spec.dims.values())
    coords = {dim: (dim, np.asarray(values), {"units": unit_of(dim), "long_name": dim}) for dim, values in
              spec.dims.items()}
    for key in _varying(spec):
        coords[key] = ("point", np.asarray([p[key] for p in spec.points]), {"units": unit_of(key)})
    data = {}
    for m in spec.metrics:
        data[m] = (dims, np.full(shape, np.nan), {"units": unit_of(m), "long_name": m,
                                                  "ancillary_variables": f"{m}_stderr"})
        data[f"{m}_stderr"] = (dims, np.full(shape, np.nan), {
            "units": unit_of(m), "long_name": f"standard error of {m}",
            "method": (f"spread of {spec.replicates} replicates / sqrt(n)" if spec.replicates >= 2 else
                       "the point's own Monte Carlo standard error (NaN where it reports none)")})
    data["done"] = (dims, np.zeros(shape, dtype=bool), {"units": "1", "long_name": "point computed"})
    ds = xr.Dataset(data, coords=coords)
    ds.attrs.update({"metrics_json": json.dumps(list(spec.metrics)), "study": spec.name,
                     "experiment": spec.experiment.name, "seed": spec.seed, "replicates": spec.replicates,
                     "common_random_numbers": int(spec.common_random_numbers),
                     "description": spec.experiment.description, "identity_json": json.dumps(identity),
                     "fixed_parameters_json": json.dumps(spec.fixed),
                     "units_json": json.dumps({k: unit_of(k) for k in spec.fixed})})
    return ds


def _wrap_os_error(err: OSError, what: str, path: Path) -> StoreError:
    name = err.filename or path
    return StoreError(f"cannot write {what} {name}: {err.strerror or err}; the point is not marked complete (it "
                      "is computed again on the next run): free space or choose another --out")


def _create(spec: StudySpec, store: Path, identity: dict) -> None:
    tmp = store.with_name(f".{store.name}.tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        ds = _empty_dataset(spec, identity)
        ds.chunk({dim: 1 for dim in spec.dims}).to_zarr(tmp, mode="w", consolidated=True, zarr_format=2)
        os.replace(tmp, store)  # the store appears whole or not at all
    except BaseException as err:  # a full disk (or a Ctrl-C outside the main thread): no half-written store is left
        shutil.rmtree(tmp, ignore_errors=True)
        if not isinstance(err, OSError):
            raise
        raise StoreError(f"cannot create the study store {store}: {err.strerror or err} ({err.filename or tmp}); "
                         "free space or choose another --out") from None


def _open(store: Path):
    import xarray as xr

    try:
        ds = xr.open_zarr(store, consolidated=True)
        return ds, json.loads(ds.attrs["identity_json"])
    except Exception as err:  # noqa: BLE001 - any unreadable store gets the same advice
        raise StoreError(f"{store} is not a readable study store ({type(err).__name__}: {err}); delete it or rerun "
                         "with --overwrite") from None


def _check_layout(spec: StudySpec, store: Path, ds) -> None:
    """Refuse a store that lacks a variable or a coordinate on disk, or whose coordinates changed (a lost chunk
    reads as fill values: the points would be plotted at the wrong coordinates)."""
    coords = {dim: np.asarray(values) for dim, values in spec.dims.items()}
    coords.update({key: np.asarray([p[key] for p in spec.points]) for key in _varying(spec)})

    def lost(names) -> list[str]:
        return [n for n in names if not (store / n / ".zarray").is_file() or n not in ds.variables]

    for kind, names in (("variable(s)", [*variables(spec), "done"]), ("coordinate(s)", list(coords))):
        if lost(names):
            raise StoreError(f"{store} lacks {kind} {', '.join(lost(names))} (deleted from the store); rerun with "
                             "--overwrite to recompute the study, or use another --out")
    for name, values in coords.items():
        try:
            same = np.array_equal(np.asarray(ds[name].values), values)
        except Exception:  # noqa: BLE001 - an unreadable coordinate is a changed one
            same = False
        if not same:
            raise StoreError(f"{store}: coordinate {name} no longer holds the study's values (a chunk was lost or "
                             "changed); rerun with --overwrite to recompute the study, or use another --out")


def _verified(spec: StudySpec, ds, records: Path, say: Callable[[str], None]) -> np.ndarray:
    """Which points are complete: a completion record whose values every store variable still holds."""
    missing_vars = [v for v in [*variables(spec), "done"] if v not in ds.data_vars]
    if missing_vars:
        raise StoreError(f"{records.parent / STORE_NAME} lacks variable(s) "
                         f"{', '.join(missing_vars)}; rerun with --overwrite to recompute the study")
    names = variables(spec)
    stored = {}
    for v in names:
        try:
            stored[v] = np.asarray(ds[v].values, dtype=float)
        except Exception as err:  # noqa: BLE001 - unreadable chunks: every point of that variable is redone
            say(f"study {spec.name}: variable {v} cannot be read ({type(err).__name__}); its points are recomputed")
            stored[v] = np.full(tuple(len(x) for x in spec.dims.values()), np.inf)  # matches no record
    shape = tuple(len(v) for v in spec.dims.values())
    try:
        done = np.asarray(ds["done"].values, dtype=bool)
    except Exception as err:  # noqa: BLE001 - unreadable chunks: every point is redone (and its mark written again)
        say(f"study {spec.name}: variable done cannot be read ({type(err).__name__}); its points are recomputed")
        done = np.zeros(shape, dtype=bool)
    complete = np.zeros(shape, dtype=bool)
    damaged: list[str] = []
    for index, params in zip(spec.indices, spec.points, strict=True):
        path = _record_path(records, index)
        if not path.is_file():
            continue
        try:
            record = json.loads(path.read_text(encoding="utf-8"))
            values = record["values"]
            ok_record = record["params"] == canonical(params) and record["seeds"] == point_seeds(spec, params)
        except (OSError, ValueError, KeyError, TypeError):
            ok_record, values = False, {}
        bad = [] if ok_record else ["its completion record"]
        if ok_record and not done[index]:  # written before the record: a lost or changed chunk of the store
            bad.append("done")
        for v in names if ok_record else []:
            want = values.get(v)
            want = np.nan if want is None else float(want)
            got = stored[v][index]
            if not (got == want or (np.isnan(got) and np.isnan(want))):
                bad.append(v)
        if bad:
            damaged.append(f"({_label(spec, index)}): {', '.join(bad[:4])}{' ...' if len(bad) > 4 else ''}")
            path.unlink(missing_ok=True)
        else:
            complete[index] = True
    if damaged:
        say(f"study {spec.name}: {len(damaged)} point(s) of {records.parent / STORE_NAME} are damaged (missing or "
            f"changed values) and are computed again: " + "; ".join(damaged[:5]) + (" ..." if len(damaged) > 5 else ""))
    return complete


def _write_point(spec: StudySpec, store: Path, records: Path, index: tuple[int, ...], params: dict,
                 result: dict) -> None:
    import xarray as xr

    region = {dim: slice(i, i + 1) for dim, i in zip(spec.dims, index, strict=True)}
    one = (1,) * len(spec.dims)
    names = variables(spec)
    values = {v: (tuple(spec.dims), np.full(one, result.get(v, np.nan))) for v in names}
    try:
        xr.Dataset(values).to_zarr(store, region=region, consolidated=False)
        xr.Dataset({"done": (tuple(spec.dims), np.ones(one, dtype=bool))}).to_zarr(store, region=region,
                                                                                   consolidated=False)
    except OSError as err:
        raise _wrap_os_error(err, "into the study store", store) from None
    record = {"index": list(index), "params": canonical(params), "seeds": point_seeds(spec, params),
              "values": {v: (None if not np.isfinite(result.get(v, np.nan)) else float(result[v])) for v in names}}
    path = _record_path(records, index)
    try:
        atomic_write_json(path, record)  # last: it marks the point complete
    except OSError as err:
        raise _wrap_os_error(err, "the completion record", path) from None


def check_points(spec: StudySpec, quick: bool) -> None:
    """Refuse, before any point is computed, the first point whose parameters the target refuses (its
    ``check``): a bad value late in a grid stopped the study after the points before it had run."""
    check = spec.experiment.check
    if check is None:
        return
    for index, params in zip(spec.indices, spec.points, strict=True):
        try:
            check(dict(params), quick)
        except ValueError as err:  # ConfigError and InputError among them
            raise ConfigError(f"study {spec.name}, point ({_label(spec, index)}): {err}; change the grid (nothing "
                              "was computed)") from None


def _refused_point(spec: StudySpec, index: tuple[int, ...], compute: Callable[[], dict]) -> dict:
    """``compute()``; an experiment's refusal of the point's parameters (a ValueError) names the point."""
    try:
        return compute()
    except ConfigError:
        raise
    except ValueError as err:
        raise ConfigError(f"study {spec.name}, point ({_label(spec, index)}): {err}; change the grid (the points "
                          "computed so far are kept)") from None


def _stderr_say(message: str) -> None:
    print(message, file=sys.stderr)


def _holder(out: Path) -> str:
    try:
        h = json.loads((out / HOLDER_NAME).read_text(encoding="utf-8"))
        return f"study {h['study']!r}, pid {h['pid']}"
    except (OSError, ValueError, KeyError, TypeError):
        return "another run"


class StudyInterrupted(KeyboardInterrupt):
    """Ctrl-C stopped a study; the message says how many points are kept and how to resume.

    Parameters
    ----------
    kept, total : int
        Points complete (kept) and points of the study.
    store : Path or None
        The study's store; None when it was not created yet (the message then names nothing: nothing was
        written, and the same command starts the study).
    """

    def __init__(self, kept: int, total: int, store: Path | None):
        self.kept, self.total, self.store = kept, total, store
        if store is None:
            message = (f"interrupted before the first of {total} points was stored: nothing was written yet; run "
                       "the same command again to start the study")
        else:
            message = (f"interrupted: {kept} of {total} points are complete and kept in {store}; run the same "
                       "command again to resume (the kept points are reused, the numbers are the same)")
        super().__init__(message)


def estimated_seconds(spec: StudySpec, n_points: int, workers: int, quick: bool) -> float:
    """A study's rough wall time [s]: points x replicates x the target's typical seconds per point / workers."""
    per_point = spec.experiment.seconds_per_point[0 if quick else 1] * spec.replicates
    return n_points * per_point / max(1, min(workers, n_points) if n_points else 1)


def check_time(spec: StudySpec, n_points: int, workers: int, quick: bool, limit_s: float, where: str) -> float:
    """Refuse ``n_points`` points whose ``estimated_seconds`` exceed ``limit_s``; return the estimate.

    Raises
    ------
    ConfigError
        Naming the estimate, what it counts and the two fixes (a smaller grid, or ``--time-limit-s``).
    """
    seconds = estimated_seconds(spec, n_points, workers, quick)
    if seconds > limit_s:
        per_point = spec.experiment.seconds_per_point[0 if quick else 1]
        raise ConfigError(
            f"study {spec.name} would take about {duration_text(seconds)} ({n_points:,} points x {spec.replicates} "
            f"replicates x ~{per_point:g} s / {where}), over the limit of {duration_text(limit_s)}: shrink the grid, "
            f"or raise the limit with --time-limit-s {math.ceil(1.5 * seconds)} (time_limit_s)")
    return seconds


def check_time_limit(time_limit_s: float) -> None:
    """Refuse a time limit that is not a positive, finite number of seconds (:class:`ConfigError`)."""
    if isinstance(time_limit_s, bool) or not isinstance(time_limit_s, int | float) or not (
            math.isfinite(time_limit_s) and time_limit_s > 0):
        raise ConfigError(f"--time-limit-s must be a positive number of seconds, got {time_limit_s!r}")


def _kept_points(records: Path) -> int:
    return len(list(records.glob("p_*.json"))) if records.is_dir() else 0


def run_study(spec: StudySpec, workers: int | None = None, scheduler: str | None = None, quick: bool = False,
              out_dir: str | Path | None = None, overwrite: bool = False, show_progress: bool = True,
              say: Callable[[str], None] = _stderr_say, time_limit_s: float = DEFAULT_TIME_LIMIT_S):
    """Compute every pending point; return ``(dataset, summary)``.

    Parameters
    ----------
    workers : int, optional
        1: run here, serially; >= 2: process workers of an embedded cluster (default: min(2, cores)); more than
        the cores this process may use: capped, with a warning.
    scheduler : str, optional
        Address of an existing dask scheduler (``tcp://host:8786``), checked within a few seconds; not together
        with ``workers``.
    say : callable
        Where notices go (a damaged point being recomputed); default: standard error.
    time_limit_s : float
        Refuse a study whose estimated time (``estimated_seconds`` of its pending points) is longer [s].

    Raises
    ------
    ConfigError
        ``workers`` < 1 or with ``scheduler``, an unreachable scheduler, a bad ``time_limit_s``, or a study
        estimated to take longer than it.
    OutDirLockedError
        Another study runs in the output directory (the message names it).
    StaleResultError, StoreError
        A different study's store, an unreadable or incomplete one, or a failed write (naming the file).
    StudyInterrupted
        Ctrl-C: the points completed so far are kept; the same call resumes.
    """
    n_workers = worker_count(workers, scheduler)
    check_time_limit(time_limit_s)
    where = f"{n_workers} worker{'s' if n_workers > 1 else ''}"
    if scheduler is not None:
        n_workers = max(1, check_scheduler(scheduler))
        where = f"the scheduler's {n_workers} worker{'s' if n_workers > 1 else ''}"
    out = Path(out_dir) if out_dir is not None else spec.out_dir
    check_points(spec, quick)
    if overwrite or not (out / STORE_NAME).exists():  # before the lock creates the out dir: nothing is left behind
        check_time(spec, len(spec.points), n_workers, quick, time_limit_s, where)
    created = topmost_missing(out)
    try:
        lock = lock_out_dir(out)
    except OutDirLockedError as err:
        raise OutDirLockedError(f"{err} [{_holder(out)}]") from None
    stored = True
    try:
        plan = _Plan(n_workers, scheduler, quick, overwrite, show_progress, time_limit_s, where)
        with watched_interrupts():
            try:
                result = _run_locked(spec, out, plan, say)
            except Exception:
                raise_if_interrupted()  # a Ctrl-C a library turned into another error: the interrupt all the same
                raise
            raise_if_interrupted()  # one swallowed during the last point: still an interrupted run (rc 130)
        return result
    except KeyboardInterrupt:
        stored = (out / STORE_NAME).exists()
        if not stored:  # stopped before the store was created: no point is kept, whatever old records say
            raise StudyInterrupted(0, len(spec.points), None) from None
        raise StudyInterrupted(_kept_points(out / RECORDS_NAME), len(spec.points), out / STORE_NAME) from None
    finally:
        (out / HOLDER_NAME).unlink(missing_ok=True)
        lock.release()
        if not stored and created is not None:
            remove_if_only_lock(out, created)


@dataclass(frozen=True)
class _Plan:
    """How a study runs (validated options)."""

    workers: int
    scheduler: str | None
    quick: bool
    overwrite: bool
    show_progress: bool
    time_limit_s: float
    where: str


def _run_locked(spec: StudySpec, out: Path, plan: _Plan, say: Callable[[str], None]):
    import xarray as xr

    atomic_write_json(out / HOLDER_NAME, {"study": spec.name, "pid": os.getpid()})
    store, records = out / STORE_NAME, out / RECORDS_NAME
    identity = study_identity(spec, plan.quick)
    if plan.overwrite:
        shutil.rmtree(store, ignore_errors=True)
        shutil.rmtree(records, ignore_errors=True)
    if store.exists():
        ds, old = _open(store)
        if old != identity:
            # deep enough to name a render config's changed file: experiment.scene.masks, experiment.frames...
            changed = ", ".join(diff_identities(old, identity, depth=3)) or "its identity"
            raise StaleResultError(f"{store} holds a different study (changed: {changed}); use another --out or "
                                   "--overwrite to replace it")
        _check_layout(spec, store, ds)
    else:
        shutil.rmtree(records, ignore_errors=True)  # records of a store that is gone describe nothing
        with held_interrupts():  # zarr writes from a thread of its own: a Ctrl-C waits for the store to be whole
            _create(spec, store, identity)
        ds, _ = _open(store)
    records.mkdir(parents=True, exist_ok=True)
    complete = _verified(spec, ds, records, say)
    pending = [(idx, p) for idx, p in zip(spec.indices, spec.points, strict=True) if not complete[idx]]
    check_time(spec, len(pending), plan.workers, plan.quick, plan.time_limit_s, plan.where)
    reused = len(spec.points) - len(pending)
    t0 = time.perf_counter()
    if pending and plan.scheduler is None and plan.workers == 1:
        for idx, params in progress(pending, desc=f"study {spec.name}", disable=not plan.show_progress):
            raise_if_interrupted()
            result = _refused_point(spec, idx, lambda p=params: compute_point(
                spec.experiment.ref, p, point_seeds(spec, p), plan.quick, list(spec.metrics)))
            with held_interrupts():  # a point's values and its completion record are written whole
                _write_point(spec, store, records, idx, params, result)
    elif pending:
        _run_distributed(spec, store, records, pending, plan, out)
    wall = time.perf_counter() - t0
    result = xr.open_zarr(store, consolidated=True).load()
    summary = {"points_total": len(spec.points), "points_computed": len(pending), "points_reused": reused,
               "replicates": spec.replicates, "common_random_numbers": spec.common_random_numbers,
               "workers": plan.workers if plan.scheduler is None else f"scheduler {plan.scheduler}",
               "wall_seconds": wall, "store": str(store)}
    path = out / "summary.json"
    try:
        atomic_write_text(path, json.dumps(summary, indent=1))
    except OSError as err:
        raise StoreError(f"cannot write {err.filename or path}: {err.strerror or err}; the results are complete in "
                         f"{store}") from None
    return result, summary


def _run_distributed(spec: StudySpec, store: Path, records: Path, pending: list, plan: _Plan, out: Path) -> None:
    from distributed import as_completed

    opened = (scheduler_client(plan.scheduler) if plan.scheduler is not None
              else embedded_client(plan.workers, out / WORKERS_LOG))
    with opened as client:
        futures = {client.submit(compute_point, spec.experiment.ref, params, point_seeds(spec, params), plan.quick,
                                 list(spec.metrics), pure=False): (idx, params) for idx, params in pending}
        try:
            for future in progress(as_completed(futures), desc=f"study {spec.name}", total=len(futures),
                                   disable=not plan.show_progress):
                idx, params = futures[future]
                result = _refused_point(spec, idx, future.result)
                with held_interrupts():  # a point's values and its completion record are written whole
                    _write_point(spec, store, records, idx, params, result)
                raise_if_interrupted()
        except BaseException:
            if plan.scheduler is not None:  # an existing cluster stops computing them (an embedded one is killed)
                with held_interrupts(), contextlib.suppress(Exception):
                    client.cancel(list(futures), force=True)
            raise
