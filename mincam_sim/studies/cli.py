"""What ``mincam-sim study run STUDY.toml [--workers N | --scheduler ADDRESS] [--out DIR] [--quick]`` does."""

from __future__ import annotations

from pathlib import Path

import typer


def run_study_command(study_file: Path, workers: int | None, scheduler: str | None, out_dir: Path | None,
                      quick: bool, overwrite: bool, quiet: bool = False) -> None:
    """Run a parameter study on dask.distributed; results.zarr (xarray), summary.json and a plot in --out."""
    from .plots import plot_study
    from .runner import run_study
    from .spec import load_study

    spec = load_study(study_file, quick=quick)
    out = out_dir or spec.out_dir
    ds, summary = run_study(spec, workers=workers, scheduler=scheduler, quick=quick, out_dir=out,
                            overwrite=overwrite, show_progress=not quiet)
    plot = plot_study(ds, list(spec.metrics), Path(out) / "study.png")
    typer.echo(f"study {spec.name}: {summary['points_total']} points ({summary['points_computed']} computed, "
               f"{summary['points_reused']} reused) on {summary['workers']} workers in "
               f"{summary['wall_seconds']:.1f} s")
    for metric in spec.metrics:
        values = ds[metric].values
        typer.echo(f"  {metric}: min {values.min():.3g}, max {values.max():.3g}")
    typer.echo(f"# {out}/results.zarr, summary.json, {plot.name}")
