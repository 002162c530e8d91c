"""Matplotlib figures (Agg backend: no display needed). Pure numpy + matplotlib."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .measurements import Measurements  # noqa: E402
from .screen import Screen  # noqa: E402


def _save(fig, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return path


def plot_sweep(positions_m: np.ndarray, m: Measurements, path: str | Path, xlabel: str = "square position x [cm]"):
    """Measurements (with 2-sigma error bars) against a 1D sweep position."""
    fig, ax = plt.subplots(figsize=(6, 3.6))
    x = 100 * np.asarray(positions_m)
    for k, name in enumerate(m.mixel_names):
        ax.errorbar(x, m.irradiance_w_m2[:, k], yerr=2 * m.stderr_w_m2[:, k], marker="o", ms=3, capsize=2,
                    label=f"mixel {name}")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("irradiance on detector [W/m$^2$]")
    ax.set_title("white square swept across the screen")
    ax.legend()
    ax.grid(alpha=0.3)
    return _save(fig, path)


def plot_response_maps(maps, screen: Screen, path: str | Path):
    """Each mixel's response map W (what it sees on the screen), in screen coordinates [cm]."""
    n = len(maps.mixel_names)
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.2), squeeze=False)
    extent = [-50 * screen.width_m, 50 * screen.width_m, -50 * screen.height_m, 50 * screen.height_m]
    vmax = float(maps.weights_sr.max()) or 1.0
    for k, ax in enumerate(axes[0]):
        im = ax.imshow(maps.weights_sr[k], extent=extent, cmap="magma", vmin=0, vmax=vmax)
        ax.set_title(f"mixel {maps.mixel_names[k]}: W [sr]")
        ax.set_xlabel("screen x [cm]")
        ax.set_ylabel("screen y [cm]")
    fig.colorbar(im, ax=axes[0].tolist(), shrink=0.8)
    return _save(fig, path)
