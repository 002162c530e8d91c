"""Figures of the README: mixel geometry, masks, response maps, wave vs geometric optics (``mincam-sim figures``)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from mincam_sim import masks, wave
from mincam_sim.model.optics import Mixel, cross_layout, pair_layout
from mincam_sim.plotting.plots import _save, plot_mask, plot_mixel_geometry, plot_render, plot_response_maps, plt
from mincam_sim.scene.display import Screen
from mincam_sim.wave.report import DEFAULT_PERIOD_M, print_deviation, rim_profile


def make_figures(out_dir: str | Path) -> list[Path]:
    """Write the README's figures into ``out_dir``."""
    from mincam_sim.budget import Budget
    from mincam_sim.render.simulation import Simulation

    out_dir = Path(out_dir)
    paths = [plot_mixel_geometry(Mixel(masks.ramp("x")), 0.5, out_dir / "mixel_geometry.png")]
    library = [masks.ramp("x"), masks.sinusoid(2 * np.pi / 0.4e-3), masks.circular_ramp()]
    fig, axes = plt.subplots(1, len(library), figsize=(4.2 * len(library), 3.4))
    for ax, mask in zip(axes, library, strict=True):
        plot_mask(mask, ax=ax, title=mask.name)
    paths.append(_save(fig, out_dir / "masks.png"))
    screen = Screen()
    maps = Simulation(pair_layout(), screen=screen).response_maps(Budget(samples_per_texel=64, seed=0))
    paths.append(plot_response_maps(maps, screen, out_dir / "response_maps.png"))
    paths.append(render_figure(maps, screen, out_dir / "render_measurements.png"))
    paths.append(print_sheet_figure(out_dir / "print_sheet.png")[0])
    return paths


def render_figure(maps, screen: Screen, path: str | Path) -> Path:
    """What ``mincam-sim render`` draws (``measurements.png``) for the default config's sweep, from ``maps``."""
    from mincam_sim.scene.display import line_sweep

    sweep = line_sweep((-0.25, 0.0), (0.25, 0.0), 26, 0.03, 1.0)
    m = maps.measure(np.stack(list(sweep.frame_source(screen, 0.0))))
    return plot_render(m, path, sweep.positions_m, "line_sweep")


def print_sheet_figure(path: str | Path, dpi: float = 300.0) -> tuple[Path, Path]:
    """The print sheet of the paper's tracking mincam (four ramps 3.3 cm from the centre) on the default film,
    as ``masks export`` / ``design`` write it (here at ``dpi`` to keep the file small)."""
    from mincam_sim.masks.sheet import write_print_sheet

    cam = cross_layout()
    positions = [(float(m.pose.position_m[0]), float(m.pose.position_m[1])) for m in cam]  # world +x: right
    return write_print_sheet([m.mask for m in cam], positions, dpi, masks.PrintedFilm(dpi=dpi), path,
                             names=cam.names, title="the paper's tracking mincam (cross layout), default film")


def make_wave_figure(path: str | Path, halftone_dpi: float = 600, n_print: int = 31) -> Path:
    """Wave vs geometric response: the default 0.2 mm sinusoid, the rim, and a halftone print (README figure)."""
    fig, axes = plt.subplots(1, 3, figsize=(14, 3.6))
    mixel = Mixel(masks.sinusoid(2 * np.pi / DEFAULT_PERIOD_M))
    hx = mixel.half_fov_tan()[0]
    t = np.linspace(-hx, hx, 1201)
    pts = np.column_stack([t, 0 * t])
    deg = np.degrees(np.arctan(t))
    ax = axes[0]
    ax.plot(deg, wave.geometric_response(mixel, pts), color="0.6", lw=2.5, label="geometric")
    ax.plot(deg, wave.angular_response(mixel, pts), color="C0", lw=1, label="wave, 550 nm")
    ax.set_title("default sinusoid (period 0.2 mm, u = 0.03)")
    ax.set_xlabel("incidence angle θx [deg]")
    ax.set_ylabel("detector power (open = 1)")
    ax.legend(loc="lower center")
    rim = rim_profile()
    ax = axes[1]
    d = np.degrees(np.arctan(rim["tan"]))
    ok = rim["geometric"] > 0.1
    ax.plot(d[ok], 100 * (rim["wave"][ok] / rim["geometric"][ok] - 1), color="C3", lw=1)
    inner = (mixel.mask.width_m / 2 - mixel.detector_size_m / 2) / mixel.d_f_m
    ax.axvline(math.degrees(math.atan(inner)), color="0.6", ls=":", label="rim enters the detector's view")
    ax.set_ylim(-30, 15)
    ax.legend(loc="lower left", fontsize=8)
    ax.set_title("open aperture: (wave - geometric) / geometric")
    ax.set_xlabel("incidence angle θx [deg]")
    ax.set_ylabel("[%]")
    pr = print_deviation(halftone_dpi, n_print)
    ax = axes[2]
    d = np.degrees(np.arctan(np.array(pr["tan"])))
    ax.plot(d, pr["geometric"], "o-", color="0.6", ms=3, lw=1.5, label="geometric (printed dots)")
    ax.plot(d, pr["wave"], "s-", color="C2", ms=3, lw=1, label="wave, 550 nm")
    ax.set_title(f"{halftone_dpi:g}-dpi halftone print of it: rms diff {100 * pr['rms_rel_diff']:.1f} %")
    ax.set_xlabel("incidence angle θx [deg] (θy = -0.37 θx)")
    ax.set_ylabel("detector power (open = 1)")
    ax.legend(loc="lower center", fontsize=8)
    return _save(fig, path)
