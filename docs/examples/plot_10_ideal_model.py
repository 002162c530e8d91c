"""
What an idealised model gets wrong
==================================

Learned-mask simulators model a mixel as its mask dotted with an image of what it sees (Klotz & Nayar,
"Minimalist Vision with Freeform Pixels", ECCV 2024: ``F.linear(image, M)``). ``ms.DotProduct()`` is that model
mapped onto this project's geometry: each mixel's mask stretched over the field it sees from the mincam's
centre, dotted with the frame, exact (no Monte Carlo). Its options add the physics one effect at a time:
``parallax`` (each mixel's own position: the field-of-view offset between mixels), ``vignetting`` (cos⁴ about
each mixel's axis) and ``detector_blur`` (the detector's size).

The tasks: the paper's two screen calibrations, fitted **on the model**, then used **on the physics**
(``ResponseMap``, the Monte Carlo response maps) at the same depth: 0.3, 0.5 and 1.0 m.

* the **pair**: the 1D intrusion pair (band ramps ``y`` and ``1 − y``, 3.3 cm apart), a cubic calibrated on a
  white 3 cm square swept along the boundary (Eq. 4);
* the **cross**: the tracking cross (ramps ``x``, ``1 − x``, ``y``, ``1 − y``, each 3.3 cm from the centre), a
  bivariate cubic calibrated on a grid of white squares clipped to the field's disc (Eq. 7).

Both run through one function, ``mincam_sim.experiments.ideal_model.calibrated_on_models`` (the spacing
study's boundary sweep and scoring for the pair, the tracking experiment's grid and 2D fit for the cross),
keeping the squares every mixel sees whole, as the screen calibration does; errors are % of the calibrated field
at each depth (50 cm at 0.5 m, scaled with depth, as are the band and the squares).
"""

# %%
# Measure the sweeps
# ------------------
# At each depth: the physics (response maps, 64 samples per texel) and every model, each calibrated and the
# calibration applied to the physics' own sweep; "physics" is the physics calibrated on itself (the floor).
import time

import matplotlib.pyplot as plt
import numpy as np

import mincam_sim as ms
from mincam_sim.experiments.ideal_model import PHYSICS, SweepSize, calibrated_on_models

start = time.perf_counter()
DEPTHS_M = (0.3, 0.5, 1.0)
SIZE = SweepSize(positions=31, samples_per_texel=64, screen_texels=160)  # the cross: a 16 x 16 grid in the disc
MODELS = {
    "bare": ms.DotProduct(),
    "+ parallax": ms.DotProduct(parallax=True),
    "+ parallax + vignetting": ms.DotProduct(parallax=True, vignetting=True),
}  # + detector_blur=True: the same numbers to 0.001 point for these ramps (a linear mask blurred stays linear)

rows, curves = [], {}
for layout in ("pair", "cross"):
    for spacing_m in (0.033, 0.0):
        errors: dict = {label: [] for label in (PHYSICS, *MODELS)}
        for depth in DEPTHS_M:
            found = calibrated_on_models(layout, spacing_m, depth, MODELS, SIZE)
            for label, rates in found.errors.items():
                errors[label].append((rates["avg_error_pct"], rates["max_error_pct"]))
            if layout == "pair" and spacing_m > 0 and depth == 0.5:
                curves = found.curves
        rows += [(layout, spacing_m, label, errs) for label, errs in errors.items()]

print(f"{'layout':<6} {'spacing':>7}  {'calibrated on':<24}" + "".join(f"{f'{d:g} m: mean / max %':>22}"
                                                                       for d in DEPTHS_M))
for layout, spacing_m, label, errors in rows:
    print(f"{layout:<6} {100 * spacing_m:5.1f}cm  {label:<24}" + "".join(f"{a:>13.3f} / {m:<7.3f}"
                                                                          for a, m in errors))
print(f"({time.perf_counter() - start:.0f} s)")

# %%
# The calibration curves of both models
# -------------------------------------
# The ratio of Eq. 4 against the square's true position, as each model predicts it at 0.5 m, pair 3.3 cm
# apart. The physics' curve is steeper: from the mincam's centre both mixels see the same field, while in the
# physics each sees it shifted by its offset, so the ratio changes faster with position (Eq. 4's slope is
# ``1 / (L − 2 s)`` for mixels ``± s`` from the centre, not ``1 / L``), and a calibration fitted on the bare
# model reads the physics' positions too far from the centre. Parallax moves the curve onto the physics;
# vignetting bends its ends.
fig, (ax, ax_err) = plt.subplots(1, 2, figsize=(11, 4.0), constrained_layout=True)
for label, (observed, true_m) in curves.items():
    style = {"color": "k", "lw": 2.5} if label == PHYSICS else {"lw": 1.2}
    ax.plot(100 * true_m, observed, label=label, **style)
ax.set_xlabel("true position along the boundary [cm]")
ax.set_ylabel("x_obs = P_y / (P_y + P_1−y)")
ax.set_title("calibration curves at 0.5 m (pair 3.3 cm apart)")
ax.legend(fontsize=8)
spaced = [(layout, label, errors) for layout, spacing_m, label, errors in rows if spacing_m > 0]
labels = [f"{layout}: {label}" for layout, label, _ in spaced]
for i, depth in enumerate(DEPTHS_M):
    means = [errors[i][0] for _, _, errors in spaced]
    ax_err.bar(np.arange(len(labels)) + 0.25 * (i - 1), means, width=0.25, label=f"tested at {depth:g} m")
ax_err.set_xticks(np.arange(len(labels)), labels, rotation=25, ha="right", fontsize=8)
ax_err.set_yscale("log")
ax_err.set_ylabel("mean error on the physics [% of field]")
ax_err.set_title("calibrated on ..., tested on the physics")
ax_err.legend(fontsize=8)
plt.show()
