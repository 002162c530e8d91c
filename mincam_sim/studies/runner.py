"""Run a study's points on ``dask.distributed`` and keep the results as an xarray Dataset in Zarr.

* Each point is one task. By default an embedded ``LocalCluster`` of *process* workers (spawned, never forked;
  one Dr.Jit per process, each with its own ``DRJIT_CACHE_DIR`` and a thread pool capped so that
  workers x threads <= cores); ``scheduler=ADDRESS`` uses an existing cluster instead (e.g. one started by
  ``dask-jobqueue`` on Slurm/PBS). ``workers=0`` runs the points in this process (serial reference).
* Seeds are derived from each point's parameters and the study seed, so a point gives the same numbers on any
  worker, in any order: 1 or N workers give identical datasets.
* Results go to ``OUT/results.zarr`` as points finish (one chunk per point, a ``done`` flag written after
  the values): a killed study resumes with its finished points reused. The store's attributes hold the
  study's identity; a different study in the same directory is refused unless ``overwrite``.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path

import numpy as np

from ..errors import StaleResultError
from ..identity import canonical, diff_identities, fingerprint, library_versions
from ..progress import progress
from .points import STUDY_EXPERIMENTS
from .spec import StudySpec

ENV_THREADS = "MINCAM_DRJIT_THREADS"


def point_seed(study_seed: int, params: dict) -> int:
    """The seed of one point: a 31-bit hash of the study seed and the point's parameters."""
    return int(fingerprint({"seed": int(study_seed), "params": params})[:8], 16) & 0x7FFFFFFF


def compute_point(experiment: str, params: dict, seed: int, quick: bool) -> dict:
    """Run one point (on a worker or here). Caps Dr.Jit's threads first when the runner asked for it."""
    from ..render import backend

    backend.configure_libllvm()  # before Dr.Jit is first imported in this process (Debian's LLVM 15 crashes it)
    threads = os.environ.get(ENV_THREADS)
    if threads:
        backend.cap_threads(int(threads))
    result = STUDY_EXPERIMENTS[experiment].point(dict(params), int(seed), bool(quick))
    return {k: float(v) for k, v in result.items()}


def study_identity(spec: StudySpec, quick: bool) -> dict:
    """Everything that determines the study's numbers."""
    return canonical({"experiment": spec.experiment.name, "dims": spec.dims, "points": spec.points,
                      "metrics": list(spec.metrics), "seed": spec.seed, "quick": bool(quick),
                      "versions": library_versions()})


def _empty_dataset(spec: StudySpec, identity: dict):
    import xarray as xr

    shape = tuple(len(v) for v in spec.dims.values())
    coords = {dim: np.asarray(values) for dim, values in spec.dims.items()}
    data = {m: (tuple(spec.dims), np.full(shape, np.nan)) for m in spec.metrics}
    data["done"] = (tuple(spec.dims), np.zeros(shape, dtype=bool))
    ds = xr.Dataset(data, coords=coords)
    ds.attrs.update({"metrics_json": json.dumps(list(spec.metrics)), "study": spec.name,
                     "experiment": spec.experiment.name, "seed": spec.seed,
                     "description": spec.experiment.description, "identity_json": json.dumps(identity),
                     "fixed_parameters_json": json.dumps({k: v for k, v in spec.points[0].items()
                                                          if k not in spec.dims})})
    return ds


def _open_or_create(spec: StudySpec, store: Path, identity: dict, overwrite: bool):
    import xarray as xr

    if store.exists() and overwrite:
        shutil.rmtree(store)
    if store.exists():
        try:
            ds = xr.open_zarr(store, consolidated=False)
            old = json.loads(ds.attrs["identity_json"])
        except Exception as err:  # noqa: BLE001 - any unreadable store gets the same advice
            raise StaleResultError(f"{store} is not a readable study store ({type(err).__name__}); delete it or "
                                   "rerun with --overwrite") from None
        if old != identity:
            changed = ", ".join(diff_identities(old, identity)) or "its identity"
            raise StaleResultError(f"{store} holds a different study (changed: {changed}); use another --out or "
                                   "--overwrite to replace it")
        return ds
    store.parent.mkdir(parents=True, exist_ok=True)
    ds = _empty_dataset(spec, identity)
    chunks = {dim: 1 for dim in spec.dims}
    ds.chunk(chunks).to_zarr(store, mode="w", consolidated=False)
    return xr.open_zarr(store, consolidated=False)


def _write_point(spec: StudySpec, store: Path, index: tuple[int, ...], result: dict) -> None:
    import xarray as xr

    region = {dim: slice(i, i + 1) for dim, i in zip(spec.dims, index, strict=True)}
    one = (1,) * len(spec.dims)
    values = {m: (tuple(spec.dims), np.full(one, result.get(m, np.nan))) for m in spec.metrics}
    xr.Dataset(values).to_zarr(store, region=region, consolidated=False)
    done = {"done": (tuple(spec.dims), np.ones(one, dtype=bool))}  # after the values: a torn point is redone
    xr.Dataset(done).to_zarr(store, region=region, consolidated=False)


def run_study(spec: StudySpec, workers: int | None = None, scheduler: str | None = None, quick: bool = False,
              out_dir: str | Path | None = None, overwrite: bool = False, show_progress: bool = True):
    """Compute every pending point; return ``(dataset, summary)``.

    Parameters
    ----------
    workers : int, optional
        Process workers of the embedded cluster (default: min(2, cores)); 0 = run here, serially.
    scheduler : str, optional
        Address of an existing dask scheduler (``tcp://host:8786``); ``workers`` is then ignored.
    """
    import xarray as xr

    out = Path(out_dir) if out_dir is not None else spec.out_dir
    store = out / "results.zarr"
    identity = study_identity(spec, quick)
    ds = _open_or_create(spec, store, identity, overwrite)
    done = np.asarray(ds["done"].values, dtype=bool)
    pending = [(idx, p) for idx, p in zip(spec.indices, spec.points, strict=True) if not done[idx]]
    reused = len(spec.points) - len(pending)
    cores = os.cpu_count() or 1
    n_workers = 0 if scheduler is None and workers == 0 else (workers or min(2, cores))
    t0 = time.perf_counter()
    if pending and scheduler is None and n_workers == 0:
        for idx, params in progress(pending, desc=f"study {spec.name}", disable=not show_progress):
            _write_point(spec, store, idx, compute_point(spec.experiment.name, params,
                                                         point_seed(spec.seed, params), quick))
    elif pending:
        _run_distributed(spec, store, pending, n_workers, scheduler, quick, show_progress, out)
    wall = time.perf_counter() - t0
    result = xr.open_zarr(store, consolidated=False).load()
    summary = {"points_total": len(spec.points), "points_computed": len(pending), "points_reused": reused,
               "workers": n_workers if scheduler is None else f"scheduler {scheduler}", "wall_seconds": wall,
               "store": str(store)}
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return result, summary


def _run_distributed(spec, store, pending, n_workers, scheduler, quick, show_progress, out) -> None:
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
        futures = {client.submit(compute_point, spec.experiment.name, params, point_seed(spec.seed, params), quick,
                                 pure=False): idx for idx, params in pending}
        for future in progress(as_completed(futures), desc=f"study {spec.name}", total=len(futures),
                               disable=not show_progress):
            _write_point(spec, store, futures[future], future.result())
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
