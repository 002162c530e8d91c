"""Plots drawn from a study's xarray Dataset."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def plot_study(ds, metrics: list[str] | None = None, path: str | Path = "study.png", x: str | None = None) -> Path:
    """One panel per metric: the metric against dimension ``x`` (default: the first), one line per value of
    the next dimension (other dimensions at their first value)."""
    import matplotlib

    matplotlib.use("Agg")
    import json

    import matplotlib.pyplot as plt

    metrics = metrics or json.loads(ds.attrs.get("metrics_json", "null")) or [v for v in ds.data_vars if v != "done"]
    dims = list(ds["done"].dims)
    x = x or dims[0]
    others = [d for d in dims if d != x]
    fig, axes = plt.subplots(1, len(metrics), figsize=(4.2 * len(metrics), 3.4), squeeze=False)
    for ax, metric in zip(axes[0], metrics, strict=True):
        da = ds[metric]
        for d in others[1:]:
            da = da.isel({d: 0})
        if others:
            for value in da[others[0]].values:
                line = da.sel({others[0]: value})
                ax.plot(line[x].values, line.values, marker="o", label=f"{others[0]} = {value:g}")
            ax.legend(fontsize=8)
        else:
            ax.plot(da[x].values, da.values, marker="o")
        ax.set_xlabel(x)
        ax.set_ylabel(metric)
        ax.grid(alpha=0.3)
        if np.all(np.isnan(da.values)):
            ax.text(0.5, 0.5, "no finished points", transform=ax.transAxes, ha="center")
    fig.suptitle(f"study {ds.attrs.get('study', '')} ({ds.attrs.get('experiment', '')})")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
