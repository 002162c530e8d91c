"""Matplotlib figures (Agg backend: no display needed). Pure numpy + matplotlib.

Every figure uses matplotlib's constrained layout (labels never overlap), and every colourbar names its
quantity and unit."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

plt.rcParams["figure.constrained_layout.use"] = True

from mincam_sim.masks import Mask  # noqa: E402
from mincam_sim.measurements import Measurements  # noqa: E402
from mincam_sim.scene.display import Screen  # noqa: E402
from mincam_sim.storage.atomic import atomic_path  # noqa: E402


def _save(fig, path: str | Path) -> Path:
    """Save ``fig`` atomically (a temporary file beside ``path``, moved into place) and close it."""
    path = Path(path)
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=120, bbox_inches="tight", format=path.suffix.lstrip(".") or "png")
    finally:
        plt.close(fig)
    return path


def plot_render(m: Measurements, path: str | Path, positions_m: np.ndarray | None = None,
                kind: str = "line_sweep") -> Path:
    """What a render measured: each mixel's irradiance with 2-sigma error bars against the frame's position
    (a line sweep: the square's x or y on the screen, whichever changes more) or against the frame number; a
    grid sweep adds each mixel's irradiance as an image over the square's positions.

    Parameters
    ----------
    m : Measurements
        The render's measurements (values and standard errors [W/m^2]).
    path : str or Path
        Output image.
    positions_m : (n, 2) array, optional
        The square's centre on the screen per frame [m] (sweeps); None: frames are numbered.
    kind : str
        ``"line_sweep"``, ``"grid_sweep"`` or ``"npy"`` (named in the title).
    """
    n = m.n_frames
    if positions_m is not None and kind == "line_sweep" and n > 1:
        pos = np.asarray(positions_m, dtype=np.float64).reshape(n, -1)
        axis = int(np.ptp(pos[:, 1]) > np.ptp(pos[:, 0]))
        x = 100 * pos[:, axis]
        xlabel = f"square position {'xy'[axis]} on the screen [cm]"
    else:
        x = np.arange(n)
        xlabel = "frame" + (" (grid sweep, row by row)" if kind == "grid_sweep" else "")
    grid = _grid_of(positions_m, n) if kind == "grid_sweep" else None
    if grid is None:
        fig, ax = plt.subplots(figsize=(6.4, 3.8))
    else:
        k_mixels = len(m.mixel_names)
        fig = plt.figure(figsize=(max(6.4, 3.2 * k_mixels), 7.0))
        top = fig.subfigures(2, 1, height_ratios=[1.1, 1])
        maps = top[0].subplots(1, k_mixels, squeeze=False)[0]
        ax = top[1].subplots()
        xs, ys, index = grid
        for k, (name, mx) in enumerate(zip(m.mixel_names, maps, strict=True)):
            img = np.full((len(ys), len(xs)), np.nan)
            img[index[:, 1], index[:, 0]] = m.irradiance_w_m2[:, k]
            im = mx.imshow(img, origin="lower", cmap="magma", aspect="auto", extent=_cell_extent_cm(xs, ys))
            mx.set_title(f"mixel {name}", fontsize=9)
            mx.set_xlabel("square x [cm]")
            mx.set_ylabel("square y [cm]")
            top[0].colorbar(im, ax=mx, label="irradiance [W/m$^2$]")
    for k, name in enumerate(m.mixel_names):
        ax.errorbar(x, m.irradiance_w_m2[:, k], yerr=2 * m.stderr_w_m2[:, k], marker="o", ms=3, capsize=2,
                    lw=1, label=f"mixel {name}")
    worst = float(np.nanmax(m.relative_stderr()[np.isfinite(m.relative_stderr())], initial=0.0))
    ax.set_xlabel(xlabel)
    ax.set_ylabel("irradiance on detector [W/m$^2$]")
    ax.set_title(f"{n} frames ({kind}), error bars 2 sigma (worst relative sigma {worst:.1e})", fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    return _save(fig, path)


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


def _grid_of(positions_m, n: int):
    """(x values, y values, (n, 2) column/row index of each frame) of a grid sweep's positions, or None."""
    if positions_m is None:
        return None
    pos = np.asarray(positions_m, dtype=np.float64).reshape(n, -1)[:, :2]
    xs, ix = np.unique(np.round(pos[:, 0], 12), return_inverse=True)
    ys, iy = np.unique(np.round(pos[:, 1], 12), return_inverse=True)
    if len(xs) * len(ys) != n:
        return None
    return xs, ys, np.column_stack([ix, iy])


def _cell_extent_cm(xs: np.ndarray, ys: np.ndarray) -> list[float]:
    """imshow extent [cm] putting each cell's centre on its grid position (half a step beyond the ends)."""
    def edges(v: np.ndarray) -> tuple[float, float]:
        half = (v[-1] - v[0]) / (2 * (len(v) - 1)) if len(v) > 1 else 0.005
        return 100 * (v[0] - half), 100 * (v[-1] + half)

    return [*edges(xs), *edges(ys)]


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
    fig.colorbar(im, ax=axes[0].tolist(), shrink=0.8, label="response W [sr] per texel")
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
    ax.plot([-det / 2 * mm, det / 2 * mm], [0, 0], color="tab:red", lw=5, solid_capstyle="butt")
    for xd in (-det / 2, det / 2):
        for xm in np.linspace(-w / 2, w / 2, n_rays):
            ax.plot([xd * mm, xm * mm], [0, d_f * mm], color="tab:orange", lw=0.5, alpha=0.6)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("z [mm]")
    ax.set_title(f"mixel: detector {det * mm:.2g} mm, mask {w * mm:.2g} mm at d_f = {d_f * mm:.2g} mm", fontsize=10)
    ax.annotate("mask (gray = transmission)", (0, d_f * mm), xytext=(0, d_f * mm * 1.25), ha="center", fontsize=8)
    ax.text(w / 2 * mm * 0.93, d_f * mm / 2, "black housing", rotation=90, ha="right", va="center", fontsize=8)
    ax.text(0, -0.06 * d_f * mm, "detector", color="tab:red", ha="center", va="top", fontsize=8)
    ax.set_ylim(-0.16 * d_f * mm, 1.45 * d_f * mm)
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


def plot_calibration_1d(true_m, change_dn, observed, calibration, path, names=("1", "2")):
    """Like the paper's Fig. 4b/c: mixel changes along the sweep, and observed position vs truth with f."""
    true_cm = 100 * np.asarray(true_m)
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.6))
    a.plot(true_cm, change_dn[:, 0], "o-", ms=3, label=f"dP ({names[0]})")
    a.plot(true_cm, change_dn[:, 1], "s-", ms=3, label=f"dP ({names[1]})")
    a.plot(true_cm, change_dn[:, 0] + change_dn[:, 1], "k--", lw=1, label="sum")
    a.set_xlabel("white square position [cm]")
    a.set_ylabel("change [DN]")
    a.set_title("calibration sweep on the screen")
    a.legend(fontsize=8)
    a.grid(alpha=0.3)
    b.plot(observed, true_cm, "o", ms=4, label="calibration points")
    grid = np.linspace(np.nanmin(observed), np.nanmax(observed), 200)
    b.plot(grid, 100 * calibration.apply(grid), "r-", label="3rd-degree fit f")
    b.set_xlabel("observed relative position (Eq. 4)")
    b.set_ylabel("true position [cm]")
    b.set_title(f"f: rms residual {100 * calibration.rms_residual_m:.2f} cm")
    b.legend(fontsize=8)
    b.grid(alpha=0.3)
    return _save(fig, path)


def plot_calibration_2d(true_m, observed, calibration, path):
    """Observed (Eq. 7) grid vs truth, and the calibrated prediction of the grid points."""
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 4))
    a.plot(observed[:, 0], observed[:, 1], "o", ms=3)
    a.set_title("observed relative positions (Eq. 7)")
    a.set_xlabel("x_obs")
    a.set_ylabel("y_obs")
    a.set_aspect("equal")
    pred = calibration.apply(observed)
    b.plot(100 * true_m[:, 0], 100 * true_m[:, 1], "k+", label="true")
    b.plot(100 * pred[:, 0], 100 * pred[:, 1], "r.", label="calibrated")
    b.set_title("grid on the screen: truth and calibrated")
    b.set_xlabel("screen x [cm]")
    b.set_ylabel("screen y [cm]")
    b.set_aspect("equal")
    b.legend(fontsize=8)
    return _save(fig, path)


def plot_overlays(images, points, half_extent_m: float, path, frame_numbers=None, boundary_x_m=None, title="",
                  field_m: float | None = None):
    """Ground-truth camera frames with the mincam's prediction (red dot) and the ground-truth centroid (cyan +),
    like the paper's Fig. 5/7. ``points[i] = (predicted (2,), truth (2,))`` in table metres; ``half_extent_m``
    is half the side of the table area each image covers. Each panel names its frame and the position error
    (cm, and % of ``field_m`` when given)."""
    n = max(1, len(images))
    fig, axes = plt.subplots(1, n, figsize=(3.6 * n, 3.9), squeeze=False)
    half = 100 * half_extent_m
    numbers = list(frame_numbers) if frame_numbers is not None else list(range(len(images)))
    for ax, image, (pred, truth), number in zip(axes[0], images, points, numbers, strict=False):
        ax.imshow(image, cmap="gray", extent=[-half, half, -half, half])
        if boundary_x_m is not None:
            ax.axvline(100 * boundary_x_m, color="lime", lw=1)
        ax.plot(100 * truth[0], 100 * truth[1], "c+", ms=12, mew=2, label="ground truth")
        ax.plot(100 * pred[0], 100 * pred[1], "o", color="red", ms=6, label="mincam")
        error_cm = 100 * float(np.hypot(*(np.asarray(pred) - np.asarray(truth))))
        share = f" ({error_cm / field_m:.1f} %)" if field_m else ""
        ax.set_title(f"frame {int(number)}: error {error_cm:.1f} cm{share}", fontsize=9)
        ax.set_xlabel("x [cm]")
        ax.set_ylabel("y [cm]")
    if len(images):
        axes[0][0].legend(fontsize=7, loc="lower left")
    fig.suptitle(title)
    return _save(fig, path)


def tracks_figure(predicted, truth, sequence_ids, frame_numbers=None, label_every: int | None = None):
    """The figure of :func:`plot_tracks` (returned, not saved)."""
    predicted, truth = np.asarray(predicted, dtype=float), np.asarray(truth, dtype=float)
    sequence_ids = np.asarray(sequence_ids)
    numbers = np.arange(len(truth)) if frame_numbers is None else np.asarray(frame_numbers)
    step = label_every or max(1, len(truth) // 12)
    fig, ax = plt.subplots(figsize=(5.6, 5.6))
    for sid in np.unique(sequence_ids):
        sel = np.flatnonzero(sequence_ids == sid)
        line, = ax.plot(100 * truth[sel, 0], 100 * truth[sel, 1], "-", lw=1, label=f"{sid}: ground truth")
        colour = line.get_color()
        ax.plot(100 * predicted[sel, 0], 100 * predicted[sel, 1], "o", ms=3, color=colour,
                label=f"{sid}: mincam (line to its frame's truth)")
        # each estimate joined to the ground truth of its own frame (one artist: hundreds of lines draw in ms)
        linked = sel[np.all(np.isfinite(predicted[sel]) & np.isfinite(truth[sel]), axis=1)]
        ax.add_collection(LineCollection(100 * np.stack([truth[linked], predicted[linked]], axis=1), colors=colour,
                                         linewidths=0.5, alpha=0.6))
        for i in sel[::step]:
            ax.annotate(f"{int(numbers[i])}", 100 * truth[i], fontsize=6, color=colour, xytext=(3, 3),
                        textcoords="offset points")
    ax.set_xlabel("x [cm]")
    ax.set_ylabel("y [cm]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title("paths on the table (numbers: frames)", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return fig


def plot_tracks(predicted, truth, sequence_ids, path, frame_numbers=None):
    """Predicted (calibrated mincam) and ground-truth paths on the table [cm], equal scales on both axes; each
    estimate is joined to the ground truth of its own frame, and every few frames are numbered
    (``frame_numbers``, default 0, 1, ...)."""
    return _save(tracks_figure(predicted, truth, sequence_ids, frame_numbers), path)


def highest_peak_note(spec) -> str | None:
    """Why the detected peak is not the spectrum's highest, or None when it is.

    :func:`~mincam_sim.estimation.estimators.spectrum` takes the largest local maximum inside its search band; a higher
    local maximum therefore lies outside that band (below its lower limit: the DC lobe, or slower than the
    slowest speed searched; above its upper limit otherwise).
    """
    mag, omega = np.asarray(spec.magnitude), 2 * np.pi * np.asarray(spec.freqs_hz)
    is_max = np.zeros(mag.size, dtype=bool)
    is_max[1:-1] = (mag[1:-1] >= mag[:-2]) & (mag[1:-1] >= mag[2:])
    if not is_max.any():
        return None
    k = int(np.flatnonzero(is_max)[np.argmax(mag[is_max])])
    if mag[k] <= spec.peak_magnitude * (1 + 1e-9) or abs(omega[k] - spec.peak_omega_rad_s) < 2 * (omega[1] - omega[0]):
        return None
    where = "below" if omega[k] < spec.peak_omega_rad_s else "above"
    reason = ("the DC lobe, or slower than the slowest speed searched" if where == "below"
              else "faster than the fastest speed searched")
    return (f"highest peak {omega[k]:.2f} rad/s is {where} the search band ({reason}); "
            "the detected peak is the highest inside it")


def plot_spectrum(spec, true_omega, path, title="mixel signal spectrum"):
    """Like the paper's Fig. 9a: the measurement's amplitude spectrum and its detected peak; when a higher peak
    lies outside the search band the figure says so (:func:`highest_peak_note`)."""
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    ax.plot(2 * np.pi * spec.freqs_hz, spec.magnitude, lw=1)
    ax.axvline(spec.peak_omega_rad_s, color="r", ls="--", label=f"detected peak {spec.peak_omega_rad_s:.2f} rad/s")
    ax.axvline(true_omega, color="k", ls=":", label=f"expected {true_omega:.2f} rad/s")
    note = highest_peak_note(spec)
    if note is not None:
        ax.text(0.98, 0.6, note.replace("; ", ";\n"), transform=ax.transAxes, ha="right", va="top", fontsize=7,
                bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "0.7"})
    ax.set_xlabel("omega [rad/s]")
    ax.set_ylabel("amplitude")
    ax.set_title(title)
    ax.legend(fontsize=8)
    return _save(fig, path)


def plot_speed(true_v, pred_v, path, unit="px/s"):
    """Like the paper's Fig. 9b: predicted vs true speed."""
    fig, ax = plt.subplots(figsize=(4.5, 4.2))
    ax.plot(true_v, pred_v, "o", label="mincam")
    lim = [0, 1.1 * max(np.max(true_v), np.nanmax(pred_v))]
    ax.plot(lim, lim, "k--", lw=1, label="ideal")
    ax.set_xlabel(f"true speed [{unit}]")
    ax.set_ylabel(f"predicted speed [{unit}]")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    return _save(fig, path)


def plot_spacing(study: dict, path):
    """Error against mixel spacing, before and after calibration, one line per depth."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharey=False)
    spacing_cm = 100 * np.asarray(study["spacing_m"])
    for depth, rows in study["by_depth"].items():
        axes[0].plot(spacing_cm, rows["avg_before_pct"], "o--", label=f"before, d = {depth} m")
        axes[0].plot(spacing_cm, rows["avg_after_pct"], "o-", label=f"after, d = {depth} m")
        axes[1].plot(spacing_cm, rows["max_before_pct"], "o--", label=f"before, d = {depth} m")
        axes[1].plot(spacing_cm, rows["max_after_pct"], "o-", label=f"after, d = {depth} m")
    for ax, what in zip(axes, ("average", "maximum"), strict=True):
        ax.set_xlabel("mixel spacing [cm]")
        ax.set_ylabel(f"{what} position error [% of range]")
        ax.set_yscale("log")
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"1D intrusion: calibration at {study['calibration_depth_m']} m")
    return _save(fig, path)


def plot_mask(mask: Mask, ax=None, cmap: str = "gray", colorbar: bool = True, title: str | None = None):
    """Show a mask with physical axes in millimetres and a transmission colourbar.

    Parameters
    ----------
    mask : Mask
        Mask to draw (row 0 at the top, +y up, as seen from the detector).
    ax : matplotlib.axes.Axes, optional
        Axes to draw into; by default a new Agg-safe ``matplotlib.figure.Figure`` (no pyplot state) is made,
        reachable as ``ax.figure``.
    cmap : str
        Colormap; transmission 0 to 1 maps to its full range.
    colorbar : bool
        Add a colourbar labelled "transmission".
    title : str, optional
        Axes title; defaults to the mask name.

    Returns
    -------
    matplotlib.axes.Axes
    """
    if ax is None:
        from matplotlib.figure import Figure

        ax = Figure(figsize=(4.2, 3.5), layout="constrained").subplots()
    wmm, hmm = mask.width_m * 1e3, mask.height_m * 1e3
    im = ax.imshow(
        mask.transmission, cmap=cmap, vmin=0.0, vmax=1.0, origin="upper", interpolation="nearest",
        extent=(-wmm / 2, wmm / 2, -hmm / 2, hmm / 2),
    )
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_title(mask.name if title is None else title)
    if colorbar:
        ax.figure.colorbar(im, ax=ax, label="transmission")
    return ax
