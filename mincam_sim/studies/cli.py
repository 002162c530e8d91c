"""What ``mincam-sim study run STUDY.toml [--workers N | --scheduler ADDRESS] [--out DIR] [--quick]
[--time-limit-s S]`` does; Ctrl-C ends it with exit code 130 and one line saying what is kept."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import typer


def run_study_command(study_file: Path, workers: int | None, scheduler: str | None, out_dir: Path | None,
                      quick: bool, overwrite: bool, quiet: bool = False, max_points: int | None = None,
                      time_limit_s: float | None = None) -> None:
    """Run a parameter study on dask.distributed; results.zarr (xarray), summary.json and a plot in --out.

    Ctrl-C: one line ``error: interrupted: K of N points are complete and kept in ...; run the same command
    again to resume ...`` on stderr and exit code 130 (the generic Ctrl-C line of the CLI is not added); before
    the study's store exists (its modules still loading, its file being read, its store not created yet), the
    line says that nothing was written and names no file."""
    from mincam_sim import interrupts
    from mincam_sim.errors import StoreError
    from mincam_sim.studies.cluster import check_workers, mute_dask_for_exit, watched_interrupts
    from mincam_sim.studies.plots import plot_study
    from mincam_sim.studies.runner import DEFAULT_TIME_LIMIT_S, StudyInterrupted, check_time_limit, run_study
    from mincam_sim.studies.spec import DEFAULT_MAX_POINTS, load_study

    check_workers(workers, scheduler)  # before anything is read or started
    limit_s = DEFAULT_TIME_LIMIT_S if time_limit_s is None else time_limit_s
    check_time_limit(limit_s)
    # an interrupt swallowed while the study loads still stops it; from the first one, this process only ends
    try:
        with watched_interrupts(on_interrupt=mute_dask_for_exit):
            spec = load_study(study_file, quick=quick,
                              max_points=DEFAULT_MAX_POINTS if max_points is None else max_points)
            out = out_dir or spec.out_dir
            ds, summary = run_study(spec, workers=workers, scheduler=scheduler, quick=quick, out_dir=out,
                                    overwrite=overwrite, show_progress=not quiet,
                                    say=lambda m: typer.echo(m, err=True), time_limit_s=limit_s)
    except StudyInterrupted as stop:
        mute_dask_for_exit()  # muted by the first SIGINT already, unless it came by another way
        typer.echo(f"error: {stop}", err=True)
        raise SystemExit(130) from None
    except KeyboardInterrupt:  # any other comes before the study starts writing (run_study converts the rest)
        mute_dask_for_exit()
        typer.echo(f"error: {interrupts.STUDY_NOT_STARTED}", err=True)
        raise SystemExit(130) from None
    try:
        plot = plot_study(ds, list(spec.metrics), Path(out) / "study.png")
    except OSError as err:
        raise StoreError(f"cannot write {err.filename or Path(out) / 'study.png'}: {err.strerror or err}; the "
                         f"results are complete in {out}/results.zarr") from None
    typer.echo(f"study {spec.name}: {summary['points_total']} points x {spec.replicates} replicates "
               f"({summary['points_computed']} computed, {summary['points_reused']} reused) on {summary['workers']} "
               f"workers in {summary['wall_seconds']:.1f} s")
    for metric in spec.metrics:
        values, se = ds[metric].values, ds[f"{metric}_stderr"].values
        unit = ds[metric].attrs.get("units", "")
        worst = np.nanmax(se) if np.any(np.isfinite(se)) else float("nan")
        typer.echo(f"  {metric} [{unit}]: min {np.nanmin(values):.3g}, max {np.nanmax(values):.3g} "
                   f"(standard error up to {worst:.2g})")
    typer.echo(f"# {out}/results.zarr, summary.json, {plot.name}")
