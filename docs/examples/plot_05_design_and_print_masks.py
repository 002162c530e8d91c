"""
Designing and printing masks
============================

A mask is designed as a transmission pattern and made as a print on transparency film. This example prints
the paper's ramps as a 600-dpi printer makes them (and writes the PNG that goes to the printer), then
optimises the four masks of the tracking mincam by differentiable rendering through the real geometry
(``mincam-sim design tracking --quick``), and compares the designed masks with the paper's ramps on held-out
objects, as printed, through the 12-bit sensor.
"""

# %%
# Print a mask
# ------------
# ``PrintedFilm`` maps the printer's grey values onto the film's transmission range (a complementary pair
# sums to ``t_min + t_max``, not 1) on the printer's dot grid. ``export_print_png`` writes the printer's input
# at the physical size: print it at 100 % and the mask is 2 mm wide.
import tempfile
import warnings
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from mincam_sim import masks
from mincam_sim.design import run_design
from mincam_sim.storage.imageio import read_png

out_dir = Path(tempfile.mkdtemp(prefix="mincam_design_"))
ramp = masks.ramp("x")
prints = {
    "600 dpi, 256 grey levels": masks.PrintedFilm(dpi=600),
    "600 dpi, ordered halftone": masks.PrintedFilm(dpi=600, halftone="ordered"),
    "2400 dpi, ordered halftone": masks.PrintedFilm(dpi=2400, halftone="ordered"),
}
fig, axes = plt.subplots(1, 4, figsize=(11, 2.9), constrained_layout=True)
axes[0].imshow(ramp.transmission, cmap="gray", vmin=0, vmax=1, extent=[-1, 1, -1, 1])
axes[0].set_title("designed: ramp x")
for ax, (label, film) in zip(axes[1:], prints.items(), strict=True):
    printed = film.print(ramp)
    ax.imshow(
        printed.transmission,
        cmap="gray",
        vmin=0,
        vmax=1,
        extent=[-1, 1, -1, 1],
        interpolation="nearest",
    )
    ax.set_title(f"{label}\n{printed.shape[1]} × {printed.shape[0]} dots", fontsize=9)
for ax in axes:
    ax.set_xlabel("mask x [mm]")

png = masks.export_print_png(
    ramp, out_dir / "ramp_x_600dpi.png", film=prints["600 dpi, ordered halftone"]
)
pixels, _ = read_png(png)
print(
    f"{png.name}: {pixels.shape[1]} x {pixels.shape[0]} pixels at 600 dpi "
    f"= {pixels.shape[1] / 600 * 25.4:.2f} mm wide"
)

# %%
# Design the tracking masks
# -------------------------
# The optimiser renders, for each training object, rays from the detectors through the (differentiable)
# masks to the object, with the other mixels' bodies in the way; the loss is the position error of a decoder
# refitted at every step, through the noisy 12-bit read-out. ``quick=True`` halves the iterations and uses a
# coarser grid. The run writes ``design.json``, the printer PNGs and its figures into ``out_dir``. Its
# held-out evaluation renders the printed masks with rays, and says (once per mixel) that their 42 µm dots are
# where diffraction matters: see :ref:`sphx_glr_gallery_plot_06_wave_optics_printed_film.py`.
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    report = run_design("tracking", out_dir, quick=True, seed=0)
for message in sorted(
    {str(w.message).split(": check it")[0].split("but ")[-1] for w in caught}
):
    print("warning:", message)
print(
    f"gradient check: max relative error {report['gradient_check']['max_rel_error']:.2e} over "
    f"{report['gradient_check']['n_checked']} parameters (forward-mode AD vs central differences)"
)
for key, label in (
    ("baseline", "paper ramps, Eq. 7"),
    ("designed", "designed, learned decoder"),
):
    r = report[key]
    print(
        f"{label:<28} avg {r['avg_error_pct']:.2f} %  max {r['max_error_pct']:.1f} % "
        f"of the field  (n = {r['n']})"
    )
print(
    f"designed / baseline average error: {report['goal']['designed_over_baseline_avg']:.2f}; "
    f"run time {report['runtime_s']['total']:.0f} s"
)

# %%
# The masks as printed
# --------------------
# The figures below are the ones the design run writes (``masks.png``, ``error_vs_depth.png``): the paper's
# ramps (top) and the designed masks (bottom), as the film transmits them.


def show_png(path: Path) -> None:
    image = plt.imread(path)
    fig, ax = plt.subplots(
        figsize=(9, 9 * image.shape[0] / image.shape[1]), constrained_layout=True
    )
    ax.imshow(image)
    ax.set_axis_off()


show_png(out_dir / "masks.png")

# %%
# Position error against depth, held-out objects
# ----------------------------------------------
show_png(out_dir / "error_vs_depth.png")

# %%
# The designed masks go to the printer as they are
# ------------------------------------------------
designed_pngs = [
    out_dir / f"mask_designed_{p}.png" for p in ("left", "right", "top", "bottom")
]
fig, axes = plt.subplots(
    1, len(designed_pngs), figsize=(10, 2.8), constrained_layout=True
)
for ax, path in zip(np.atleast_1d(axes), designed_pngs, strict=True):
    ax.imshow(read_png(path)[0], cmap="gray", vmin=0, vmax=1, interpolation="nearest")
    ax.set_title(path.name, fontsize=8)
    ax.set_axis_off()
