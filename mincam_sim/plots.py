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


def plot_mixel_geometry(mixel, distance_m: float, path: str | Path, n_rays: int = 7):
    """Side view (x-z) of one mixel: detector, black housing, mask at d_f, and rays to a plane at ``distance_m``.

    Two panels: the mixel itself (mm) and the field of view it projects onto the scene plane (cm).
    """
    det, d_f = mixel.detector_size_m, mixel.d_f_m
    w = mixel.mask.width_m
    row = mixel.mask.transmission[mixel.mask.shape[0] // 2]
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(10, 3.8), gridspec_kw={"width_ratios": [1, 1.4]})
    mm = 1e3
    ax.fill_between([-w / 2 * mm, w / 2 * mm], [-0.02 * mm * d_f] * 2, 0, color="0.85")
    for sx in (-1, 1):
        ax.plot([sx * w / 2 * mm] * 2, [0, d_f * mm], color="k", lw=3)
    xs = np.linspace(-w / 2, w / 2, len(row))
    ax.scatter(xs * mm, np.full_like(xs, d_f * mm), c=row, cmap="gray", vmin=0, vmax=1, marker="s", s=12,
               edgecolors="none", zorder=3)
    ax.plot([-det / 2 * mm, det / 2 * mm], [0, 0], color="tab:red", lw=5, solid_capstyle="butt", label="detector")
    for xd in (-det / 2, det / 2):
        for xm in np.linspace(-w / 2, w / 2, n_rays):
            ax.plot([xd * mm, xm * mm], [0, d_f * mm], color="tab:orange", lw=0.5, alpha=0.6)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("z [mm]")
    ax.set_title(f"mixel: detector {det * mm:.2g} mm, mask {w * mm:.2g} mm at d_f = {d_f * mm:.2g} mm")
    ax.annotate("mask (gray = transmission)", (0, d_f * mm), xytext=(0, d_f * mm * 1.25), ha="center", fontsize=8)
    ax.annotate("black housing", (w / 2 * mm, d_f * mm / 2), xytext=(w / 2 * mm * 1.05, d_f * mm / 2), fontsize=8)
    ax.set_ylim(-0.1 * d_f * mm, 1.45 * d_f * mm)
    ax.legend(loc="lower left", fontsize=8)
    cm = 100
    for xd in (-det / 2, 0.0, det / 2):
        for xm in (-w / 2, w / 2):
            x_far = xd + (xm - xd) * distance_m / d_f
            ax2.plot([xd * cm, x_far * cm], [0, distance_m * cm], color="tab:orange", lw=0.8)
    x_scene = np.linspace(-w / 2, w / 2, len(row)) * distance_m / d_f
    ax2.scatter(x_scene * cm, np.full_like(x_scene, distance_m * cm), c=row, cmap="gray", vmin=0, vmax=1, s=10)
    ax2.set_xlabel("x [cm]")
    ax2.set_ylabel("depth [cm]")
    ax2.set_title(f"field of view at d = {distance_m * cm:.0f} cm: the mask seen at scale d / d_f = "
                  f"{distance_m / d_f:.0f}", fontsize=9)
    ax2.grid(alpha=0.3)
    return _save(fig, path)
