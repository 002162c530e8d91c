"""Figures of a design run (matplotlib, constrained layout, written atomically). Pure numpy + matplotlib."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from mincam_sim.masks import Mask  # noqa: E402
from mincam_sim.storage.atomic import atomic_path  # noqa: E402


def _save(fig, path: Path) -> Path:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)
    return path


def plot_loss(histories: dict[str, np.ndarray], kept: str, path: Path) -> Path:
    """Training RMS position error against the optimiser step, one curve per start (the kept one bold)."""
    fig, ax = plt.subplots(figsize=(6.0, 3.6), layout="constrained")
    for label, loss in histories.items():
        ax.plot(np.arange(1, len(loss) + 1), 100 * np.asarray(loss), lw=1.8 if label == kept else 0.8,
                label=f"start: {label}" + (" (kept)" if label == kept else ""))
    ax.legend(fontsize=8)
    ax.set_xlabel("optimiser step")
    ax.set_ylabel("training RMS position error [% of field]")
    ax.set_title("mask design: loss (noisy read-out, calibration in the loop)")
    ax.grid(alpha=0.3)
    return _save(fig, path)


def plot_masks(rows: dict[str, list[Mask]], names: list[str], path: Path) -> Path:
    """Masks as printed (transmission), one row per design, one column per mixel."""
    fig, axes = plt.subplots(len(rows), len(names), figsize=(2.6 * len(names), 2.5 * len(rows)),
                             layout="constrained", squeeze=False)
    image = None
    for r, (label, masks) in enumerate(rows.items()):
        for c, (mask, name) in enumerate(zip(masks, names, strict=True)):
            ax = axes[r, c]
            extent = (-mask.width_m / 2 * 1e3, mask.width_m / 2 * 1e3, -mask.height_m / 2 * 1e3,
                      mask.height_m / 2 * 1e3)
            image = ax.imshow(mask.transmission, cmap="gray", vmin=0.0, vmax=1.0, extent=extent,
                              interpolation="nearest")
            ax.set_title(f"{label}: {name}", fontsize=9)
            ax.set_xlabel("x on mask [mm]", fontsize=8)
            if c == 0:
                ax.set_ylabel("y on mask [mm]", fontsize=8)
    fig.colorbar(image, ax=axes, shrink=0.8, label="transmission (as printed on film)")
    return _save(fig, path)


def plot_error_vs_depth(results: dict[str, dict], path: Path) -> Path:
    """Per-object position error against depth, and the per-depth averages, for each mincam."""
    fig, ax = plt.subplots(figsize=(6.4, 3.8), layout="constrained")
    for (label, res), colour in zip(results.items(), ("tab:red", "tab:blue", "tab:gray"), strict=False):
        a = res["arrays"]
        ax.scatter(100 * a["depth_m"], a["error_pct"], s=6, alpha=0.35, color=colour)
        depths = np.unique(a["depth_m"])
        avg = [np.nanmean(a["error_pct"][a["depth_m"] == d]) for d in depths]
        ax.plot(100 * depths, avg, "-o", color=colour, ms=4,
                label=f"{label}: avg {res['avg_error_pct']:.2f} %, max {res['max_error_pct']:.1f} %")
    ax.axvline(50, color="k", lw=0.8, ls=":", label="calibration depth")
    ax.set_yscale("log")
    ax.set_xlabel("object depth [cm]")
    ax.set_ylabel("position error [% of field]")
    ax.set_title("held-out objects, physical simulator (response maps), 12-bit sensor")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    return _save(fig, path)


def plot_suite(suite: dict, path: Path) -> Path:
    """The held-out suite: average position error per case for every mincam (bars, log scale), the designed
    masks' ratio to the baseline above each case."""
    cases = suite["cases"]
    labels = list(cases[0]["rows"])
    colours = {lab: c for lab, c in zip(labels, SUITE_COLOURS, strict=False)}
    fig, ax = plt.subplots(figsize=(11.0, 4.4), layout="constrained")
    width = 0.8 / len(labels)
    x = np.arange(len(cases))
    for j, lab in enumerate(labels):
        avg = [c["rows"][lab]["avg_error_pct"] for c in cases]
        ax.bar(x + (j - (len(labels) - 1) / 2) * width, avg, width, color=colours[lab],
               label=lab + (" (baseline)" if lab == suite["baseline"] else ""))
    designed = suite.get("designed")
    top = max(max(r["avg_error_pct"] for r in c["rows"].values()) for c in cases)
    low = min(min(r["avg_error_pct"] for r in c["rows"].values()) for c in cases)
    ax.set_yscale("log")
    ax.set_ylim(low / 2, top * 6)
    if designed:
        for i, c in enumerate(cases):
            r = c["ratio_to_baseline"][designed]
            ax.text(i, top * 1.5, f"{r:.2f}x", ha="center", fontsize=8,
                    color="tab:green" if r < 1 else "tab:red")
    ax.set_xticks(x, [c["name"] for c in cases], rotation=35, ha="right", fontsize=8)
    ax.set_ylabel("avg position error [% of field]")
    ax.set_title("held-out suite: physical simulator, 12-bit sensor with noise "
                 "(designed / baseline above each case)", fontsize=10)
    ax.legend(fontsize=8, ncol=4, loc="upper left")
    ax.grid(alpha=0.3, which="both", axis="y")
    return _save(fig, path)


SUITE_COLOURS = ("tab:red", "tab:blue", "tab:orange", "tab:gray", "tab:purple", "tab:olive", "tab:cyan", "tab:brown")


def plot_summary(summary: dict, path: Path) -> Path:
    """The suite's summary: the designed masks' mean error beside every baseline's (lower is better), each
    with how many cases the designed masks beat it in."""
    labels = ["designed", *summary["baselines"]]
    values = [summary["designed"], *summary["baselines"].values()]
    fig, ax = plt.subplots(figsize=(6.4, 3.6), layout="constrained")
    bars = ax.bar(labels, values, color=["tab:blue"] + ["tab:gray"] * (len(labels) - 1))
    wins = summary.get("n_cases_designed_better", {})
    for bar, lab, v in zip(bars, labels, values, strict=True):
        text = f"{v:.2f}" + (f"\ndesigned better\nin {wins[lab]}/{summary['n_cases']}" if lab in wins else "")
        ax.text(bar.get_x() + bar.get_width() / 2, v, text, ha="center", va="bottom", fontsize=8)
    ax.set_ylim(0, 1.35 * max(values))
    ax.set_ylabel(f"mean over the suite of {summary['metric']} (lower is better)", fontsize=8)
    ax.set_title("held-out suite (physical simulator): designed masks against the baselines", fontsize=9)
    ax.grid(alpha=0.3, axis="y")
    return _save(fig, path)


def plot_scene_task(task: str, metric: str, lower_is_better: bool, cases: list[dict], masks: dict[str, Mask],
                    path: Path) -> Path:
    """A scene task's figure: the masks of every set as printed (top rows) and the suite's metric per case for
    every set (bars)."""
    labels = list(masks)
    fig = plt.figure(figsize=(max(8.0, 1.3 * len(cases) + 3), 5.6), layout="constrained")
    top, bottom = fig.subfigures(2, 1, height_ratios=[0.35, 1.0])
    axes = top.subplots(1, len(labels) * 4, squeeze=False)[0]
    for j, label in enumerate(labels):
        for c, mask in enumerate(masks[label]):
            ax = axes[4 * j + c]
            ax.imshow(mask.transmission, cmap="gray", vmin=0.0, vmax=1.0, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if c == 0:
                ax.set_title(label, fontsize=8, loc="left")
    ax = bottom.subplots()
    x = np.arange(len(cases))
    width = 0.8 / len(labels)
    for j, label in enumerate(labels):
        ax.bar(x + (j - (len(labels) - 1) / 2) * width, [c[metric][label] for c in cases], width, label=label)
    ax.set_xticks(x, [c["name"] for c in cases], rotation=20, fontsize=8)
    ax.set_ylabel(f"{metric.replace('_pct', '')} [%] ({'lower' if lower_is_better else 'higher'} is better)")
    ax.set_title(f"{task}: held-out suite, traced physics, 12-bit read-out; masks as printed above", fontsize=9)
    ax.legend(fontsize=7, ncols=3)
    ax.grid(alpha=0.3, axis="y")
    return _save(fig, path)


__all__ = ["SUITE_COLOURS", "plot_error_vs_depth", "plot_loss", "plot_masks", "plot_scene_task", "plot_suite",
           "plot_summary"]
