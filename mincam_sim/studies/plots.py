"""Plots drawn from a study's xarray Dataset: error bars from ``<metric>_stderr``, axes in readable units."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from mincam_sim.storage.atomic import atomic_path

_LENGTH_SCALES = ((2e-2, 1e3, "mm"), (0.2, 1e2, "cm"))


def display_scale(values, unit: str) -> tuple[float, str]:
    """A factor and unit that show ``values`` (in ``unit``) readably: metres below 2 cm as mm, below 20 cm as
    cm; everything else as it is."""
    finite = np.abs(np.asarray(values, dtype=float))
    finite = finite[np.isfinite(finite)]
    if unit == "m" and finite.size:
        top = float(finite.max())
        for limit, factor, name in _LENGTH_SCALES:
            if top <= limit:
                return factor, name
    return 1.0, unit


def axis_label(name: str, unit: str) -> str:
    """``name (unit)`` with the unit suffix dropped from the name (``spacing_m`` -> ``spacing (cm)``);
    dimensionless quantities get no unit."""
    from mincam_sim.experiments.study_targets import _SUFFIX_UNITS

    text = name
    for suffix, _ in _SUFFIX_UNITS:
        if text.endswith(suffix):
            text = text.removesuffix(suffix)
            break
    return text if unit in ("1", "") else f"{text} ({unit})"


def plot_study(ds, metrics: list[str] | None = None, path: str | Path = "study.png", x: str | None = None) -> Path:
    """One panel per metric: the metric (with its standard error as error bars) against dimension ``x``
    (default: the first), one line per value of the next dimension (other dimensions at their first value).
    Written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    metrics = metrics or json.loads(ds.attrs.get("metrics_json", "null")) or [
        v for v in ds.data_vars if v != "done" and not v.endswith("_stderr")]
    dims = list(ds["done"].dims)
    x = x or dims[0]
    others = [d for d in dims if d != x]
    x_unit = ds[x].attrs.get("units", "1")
    x_factor, x_shown = display_scale(ds[x].values, x_unit)
    ncols = min(3, len(metrics))
    nrows = -(-len(metrics) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.6 * ncols, 3.6 * nrows), squeeze=False, layout="constrained")
    for ax in axes.flat[len(metrics):]:
        ax.set_visible(False)
    for ax, metric in zip(axes.flat, metrics, strict=False):
        da = ds[metric]
        se = ds[f"{metric}_stderr"] if f"{metric}_stderr" in ds else None
        for d in others[1:]:
            da = da.isel({d: 0})
            se = se.isel({d: 0}) if se is not None else None
        unit = da.attrs.get("units", "1")
        if others:
            other = others[0]
            o_factor, o_unit = display_scale(da[other].values, ds[other].attrs.get("units", "1"))
            for value in da[other].values:
                line = da.sel({other: value})
                err = se.sel({other: value}).values if se is not None else None
                label = f"{axis_label(other, '1')} = {value * o_factor:g}" + ("" if o_unit == "1" else f" {o_unit}")
                ax.errorbar(line[x].values * x_factor, line.values, yerr=err, marker="o", ms=4, capsize=3,
                            label=label)
            ax.legend(fontsize=8)
        else:
            ax.errorbar(da[x].values * x_factor, da.values, yerr=se.values if se is not None else None, marker="o",
                        ms=4, capsize=3)
        ax.set_xlabel(axis_label(x, x_shown))
        ax.set_ylabel(axis_label(metric, unit))
        xs = np.asarray(ds[x].values, dtype=float)
        if np.all(xs > 0) and xs.max() / xs.min() >= 100:  # values over decades (read noise 1 ... 1000 e-)
            ax.set_xscale("log")
        else:
            ax.xaxis.set_major_locator(MaxNLocator(nbins=6))
        ax.grid(alpha=0.3)
        if np.all(np.isnan(da.values)):
            ax.text(0.5, 0.5, "no finished points", transform=ax.transAxes, ha="center")
    reps = ds.attrs.get("replicates", "")
    crn = " common random numbers," if ds.attrs.get("common_random_numbers") else ""
    fig.suptitle(f"study {ds.attrs.get('study', '')} ({ds.attrs.get('experiment', '')}):{crn} error bars = 1 "
                 f"standard error ({reps} replicates)", fontsize=10)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
    return path
