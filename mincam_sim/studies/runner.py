"""Run a study's points on ``dask.distributed`` and keep the results as an xarray Dataset in Zarr.

* Each point is one task. ``workers = 1`` runs the points in this process; ``workers >= 2`` starts an embedded
  ``LocalCluster`` of *process* workers (spawned, never forked; one Dr.Jit per process, each with its own
  ``DRJIT_CACHE_DIR`` and a thread pool capped so that workers x threads <= cores); ``scheduler=ADDRESS`` uses
  an existing cluster instead (e.g. one started by ``dask-jobqueue`` on Slurm/PBS). ``workers < 1`` is refused.
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
  attributes hold the study's identity; a different study in the same directory is refused unless ``overwrite``.
* A failed write (a full disk) raises :class:`~mincam_sim.errors.StoreError` naming the file; the point then
  has no completion record, so nothing half-written is ever reused.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from mincam_sim.errors import ConfigError, OutDirLockedError, StaleResultError, StoreError
from mincam_sim.experiments.registry import study_target
from mincam_sim.experiments.study_targets import unit_of
from mincam_sim.progress import progress
from mincam_sim.storage.atomic import atomic_write_json, atomic_write_text
from mincam_sim.storage.identity import build_identity, canonical, diff_identities, fingerprint
from mincam_sim.storage.store import lock_out_dir
from mincam_sim.studies.spec import StudySpec

ENV_THREADS = "MINCAM_DRJIT_THREADS"
STORE_NAME = "results.zarr"
RECORDS_NAME = "points"
HOLDER_NAME = ".study_holder.json"


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


def study_identity(spec: StudySpec, quick: bool) -> dict:
    """Everything that determines the study's numbers."""
    target = dict(spec.experiment.ref)
    if "config" in target:  # a render config: its content, not its path
        target = {"name": target["name"], "config": fingerprint(Path(target["config"]).read_text(encoding="utf-8"))}
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
    except OSError as err:
        shutil.rmtree(tmp, ignore_errors=True)
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
    complete = np.zeros(tuple(len(v) for v in spec.dims.values()), dtype=bool)
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


def run_study(spec: StudySpec, workers: int | None = None, scheduler: str | None = None, quick: bool = False,
              out_dir: str | Path | None = None, overwrite: bool = False, show_progress: bool = True,
              say: Callable[[str], None] = _stderr_say):
    """Compute every pending point; return ``(dataset, summary)``.

    Parameters
    ----------
    workers : int, optional
        1: run here, serially; >= 2: process workers of an embedded cluster (default: min(2, cores)).
    scheduler : str, optional
        Address of an existing dask scheduler (``tcp://host:8786``); ``workers`` is then ignored.
    say : callable
        Where notices go (a damaged point being recomputed); default: standard error.

    Raises
    ------
    ConfigError
        ``workers`` < 1.
    OutDirLockedError
        Another study runs in the output directory (the message names it).
    StaleResultError, StoreError
        A different study's store, an unreadable one, or a failed write (naming the file).
    """
    import xarray as xr

    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ConfigError(f"--workers must be an integer >= 1 (1 = in this process), got {workers!r}")
    out = Path(out_dir) if out_dir is not None else spec.out_dir
    try:
        lock = lock_out_dir(out)
    except OutDirLockedError as err:
        raise OutDirLockedError(f"{err} [{_holder(out)}]") from None
    try:
        return _run_locked(spec, workers, scheduler, quick, out, overwrite, show_progress, say, xr)
    finally:
        (out / HOLDER_NAME).unlink(missing_ok=True)
        lock.release()


def _run_locked(spec, workers, scheduler, quick, out, overwrite, show_progress, say, xr):
    atomic_write_json(out / HOLDER_NAME, {"study": spec.name, "pid": os.getpid()})
    store, records = out / STORE_NAME, out / RECORDS_NAME
    identity = study_identity(spec, quick)
    if overwrite:
        shutil.rmtree(store, ignore_errors=True)
        shutil.rmtree(records, ignore_errors=True)
    if store.exists():
        ds, old = _open(store)
        if old != identity:
            changed = ", ".join(diff_identities(old, identity)) or "its identity"
            raise StaleResultError(f"{store} holds a different study (changed: {changed}); use another --out or "
                                   "--overwrite to replace it")
    else:
        shutil.rmtree(records, ignore_errors=True)  # records of a store that is gone describe nothing
        _create(spec, store, identity)
        ds, _ = _open(store)
    records.mkdir(parents=True, exist_ok=True)
    complete = _verified(spec, ds, records, say)
    pending = [(idx, p) for idx, p in zip(spec.indices, spec.points, strict=True) if not complete[idx]]
    reused = len(spec.points) - len(pending)
    cores = os.cpu_count() or 1
    n_workers = workers if workers is not None else min(2, cores)
    t0 = time.perf_counter()
    if pending and scheduler is None and n_workers == 1:
        for idx, params in progress(pending, desc=f"study {spec.name}", disable=not show_progress):
            result = _refused_point(spec, idx, lambda p=params: compute_point(
                spec.experiment.ref, p, point_seeds(spec, p), quick, list(spec.metrics)))
            _write_point(spec, store, records, idx, params, result)
    elif pending:
        _run_distributed(spec, store, records, pending, n_workers, scheduler, quick, show_progress, out)
    wall = time.perf_counter() - t0
    result = xr.open_zarr(store, consolidated=True).load()
    summary = {"points_total": len(spec.points), "points_computed": len(pending), "points_reused": reused,
               "replicates": spec.replicates, "common_random_numbers": spec.common_random_numbers,
               "workers": n_workers if scheduler is None else f"scheduler {scheduler}", "wall_seconds": wall,
               "store": str(store)}
    path = out / "summary.json"
    try:
        atomic_write_text(path, json.dumps(summary, indent=1))
    except OSError as err:
        raise StoreError(f"cannot write {err.filename or path}: {err.strerror or err}; the results are complete in "
                         f"{store}") from None
    return result, summary


def _run_distributed(spec, store, records, pending, n_workers, scheduler, quick, show_progress, out) -> None:
    import dask
    from distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler is None:
        threads = max(1, (os.cpu_count() or 1) // n_workers)
        cache_root = out / "drjit_cache"
        with dask.config.set({"distributed.worker.multiprocessing-method": "spawn",
                              "distributed.worker.daemon": False}):
            cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                                   dashboard_address=None, env={ENV_THREADS: str(threads)})
        client = Client(cluster)
        # one Dr.Jit kernel cache per worker process
        client.run(_set_worker_cache, str(cache_root))
    else:
        client = Client(scheduler)
    try:
        futures = {client.submit(compute_point, spec.experiment.ref, params, point_seeds(spec, params), quick,
                                 list(spec.metrics), pure=False): (idx, params) for idx, params in pending}
        for future in progress(as_completed(futures), desc=f"study {spec.name}", total=len(futures),
                               disable=not show_progress):
            idx, params = futures[future]
            _write_point(spec, store, records, idx, params, _refused_point(spec, idx, future.result))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _set_worker_cache(root: str, dask_worker=None) -> str:
    """Give this worker process its own Dr.Jit kernel cache (before Dr.Jit is first imported there)."""
    name = "".join(c if c.isalnum() else "_" for c in str(getattr(dask_worker, "name", os.getpid())))
    path = Path(root) / f"worker_{name}"
    path.mkdir(parents=True, exist_ok=True)
    os.environ.setdefault("DRJIT_CACHE_DIR", str(path))
    return str(path)
