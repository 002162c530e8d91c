"""
The paper's experiments, in quick mode
======================================

*The Minimalist Camera* tested three estimators on hardware: the position of an intrusion across a line
(two mixels, Sec. 4.1), the position of toys moving on a table (four mixels, Sec. 4.2) and the speed of a
textured road (one sinusoid mixel, Sec. 4.3). ``reproduce`` runs all three in simulation, each with its
calibration on the screen, its rendered scene, the 12-bit sensor, and the paper's scoring against a
ground truth rendered by a pinhole camera. Quick mode uses fewer frames and samples than
``mincam-sim reproduce all`` (a few minutes on two cores); its numbers are noisier, not different in kind.
"""

# %%
# Run the three experiments
# -------------------------
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt

from mincam_sim.experiments import (
    EXPERIMENTS,
    REGISTRY,
    load_reproduce_config,
    reproduce,
)

setup, params = load_reproduce_config(None, quick=True)
out_dir = Path(tempfile.mkdtemp(prefix="mincam_repro_"))
results = reproduce(list(EXPERIMENTS), setup, out_dir, params=params)


# %%
# Simulated against the paper
# ---------------------------
# Position errors are % of the calibrated range (50 cm); speed errors % of the true speed. *n* counts the
# frames scored (a ground truth and a mincam position).
def pct(value) -> str:
    return "   -  " if value is None else f"{value:6.2f}"


print(
    f"{'experiment':<11} {'section':<8} {'simulated max / avg [%]':>24} "
    f"{'paper max / avg [%]':>21} {'n':>5}"
)
for name in EXPERIMENTS:
    r, paper = results[name], results[name]["paper"]
    print(
        f"{name:<11} {REGISTRY[name].paper_section:<8} "
        f"{pct(r['max_error_pct']):>12} / {pct(r['avg_error_pct'])}"
        f" {pct(paper['max_error_pct']):>11} / {pct(paper['avg_error_pct'])} {r['n']:>5}"
    )

fig, ax = plt.subplots(figsize=(6.4, 3.2), constrained_layout=True)
names = list(EXPERIMENTS)
x = range(len(names))
ax.bar(
    [i - 0.2 for i in x],
    [results[n]["avg_error_pct"] or 0 for n in names],
    0.4,
    label="simulated (quick)",
)
ax.bar(
    [i + 0.2 for i in x],
    [results[n]["paper"]["avg_error_pct"] or 0 for n in names],
    0.4,
    label="paper (hardware)",
)
ax.set_xticks(list(x), names)
ax.set_ylabel("average error [%]")
ax.legend()
ax.grid(alpha=0.3, axis="y")

# %%
# The figures each experiment writes
# ----------------------------------
# ``reproduce`` draws the calibration, the frames with their estimated and true positions, and the speed
# spectrum into its output folder, next to ``results.json``.
for png in sorted(out_dir.glob("*.png")):
    image = plt.imread(png)
    fig, ax = plt.subplots(
        figsize=(9, 9 * image.shape[0] / image.shape[1]), constrained_layout=True
    )
    ax.imshow(image)
    ax.set_axis_off()
    ax.set_title(png.name, fontsize=9)
