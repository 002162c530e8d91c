"""
What an idealised model gets wrong
==================================

Learned-mask simulators model a mixel as its mask dotted with an image of what it sees (Klotz & Nayar,
"Minimalist Vision with Freeform Pixels", ECCV 2024: ``F.linear(image, M)``). ``ms.DotProduct()`` is that model
mapped onto this project's geometry: each mixel's mask stretched over the field it sees from the mincam's
centre, dotted with the frame, exact (no Monte Carlo). Its options add the physics one effect at a time:
``parallax`` (each mixel's own position: the field-of-view offset between mixels), ``vignetting`` (cos⁴ about
each mixel's axis) and ``detector_blur`` (the detector's size).

The task: the paper's 1D intrusion pair (band ramps ``y`` and ``1 − y``, 3.3 cm apart) is calibrated with a
cubic on a white 3 cm square swept along the boundary, **on the model**, then used **on the physics**
(``ResponseMap``, the Monte Carlo response maps) at the same depth: 0.3, 0.5 and 1.0 m. The sweep and the scoring
are the spacing study's own code (``mincam_sim.experiments.spacing.boundary_sweep_irradiance`` and
``boundary_errors``), keeping the squares both mixels see whole, as the
screen calibration does; errors are % of the calibrated range at each depth (50 cm at 0.5 m, scaled with depth).
"""

# %%
# Measure the sweeps
# ------------------
# At each depth: the physics (response maps, 64 samples per texel) and every model, each calibrated and the
# calibration applied to the physics' own sweep.
import time

import matplotlib.pyplot as plt
import numpy as np

import mincam_sim as ms
from mincam_sim.estimation.estimators import intrusion_position
from mincam_sim.experiments.screen_calibration import fit_calibration_1d
from mincam_sim.experiments.setup import Setup
from mincam_sim.experiments.spacing import boundary_errors, boundary_sweep_irradiance

start = time.perf_counter()
DEPTHS_M = (0.3, 0.5, 1.0)
POSITIONS, SAMPLES_PER_TEXEL, TEXELS = 31, 64, 160
MODELS = {
    "bare": ms.DotProduct(),
    "+ parallax": ms.DotProduct(parallax=True),
    "+ parallax + vignetting": ms.DotProduct(parallax=True, vignetting=True),
}  # + detector_blur=True: the same numbers to 0.001 point for these ramps (a linear mask blurred stays linear)


def sweep(setup: Setup, depth_m: float, solver=None):
    """(positions, 2) irradiance [W/m^2] and the true positions [m]; ``solver`` None: the physics. The band and
    the square are 3 cm at 0.5 m, scaled with depth (the same angles at every depth; only the spacing is not)."""
    size_m = 0.03 * depth_m / 0.5
    return boundary_sweep_irradiance(setup, depth_m, POSITIONS, SAMPLES_PER_TEXEL, TEXELS, band_m=size_m,
                                     square_m=size_m, solver=solver, seen_whole=True)


rows, curves = [], {}
for spacing_m in (0.033, 0.0):
    errors: dict = {label: [] for label in ("physics", *MODELS)}
    for depth in DEPTHS_M:
        # the set-up at this depth: band masks aimed at its boundary, the field (50 cm at 0.5 m) scaled with it
        setup = Setup(spacing_m=spacing_m, depth_m=depth, field_m=depth)
        irradiance, truth = sweep(setup, depth)
        physics = intrusion_position(*irradiance.T)
        calibrations = {"physics": (physics, truth)}
        for label, model in MODELS.items():
            model_irradiance, model_truth = sweep(setup, depth, model)
            calibrations[label] = (intrusion_position(*model_irradiance.T), model_truth)
        for label, (observed, true_m) in calibrations.items():
            cal = fit_calibration_1d(observed, true_m, {"model": label})
            _, after = boundary_errors(setup, cal, physics, truth, depth)
            errors[label].append((after["avg_error_pct"], after["max_error_pct"]))
            if spacing_m > 0 and depth == 0.5:
                curves[label] = (observed, true_m)
    rows += [(spacing_m, label, errs) for label, errs in errors.items()]

print(f"{'spacing':>8}  {'calibrated on':<26}" + "".join(f"{f'{d:g} m: mean / max %':>22}" for d in DEPTHS_M))
for spacing_m, label, errors in rows:
    print(f"{100 * spacing_m:6.1f}cm  {label:<26}" + "".join(f"{a:>13.3f} / {m:<7.3f}" for a, m in errors))
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
fig, (ax, ax_err) = plt.subplots(1, 2, figsize=(10, 3.6), constrained_layout=True)
for label, (observed, true_m) in curves.items():
    style = {"color": "k", "lw": 2.5} if label == "physics" else {"lw": 1.2}
    ax.plot(100 * true_m, observed, label=label, **style)
ax.set_xlabel("true position along the boundary [cm]")
ax.set_ylabel("x_obs = P_y / (P_y + P_1−y)")
ax.set_title("calibration curves at 0.5 m (pair 3.3 cm apart)")
ax.legend(fontsize=8)
labels = [label for spacing_m, label, _ in rows if spacing_m > 0]
for i, depth in enumerate(DEPTHS_M):
    means = [errors[i][0] for spacing_m, _, errors in rows if spacing_m > 0]
    ax_err.bar(np.arange(len(labels)) + 0.25 * (i - 1), means, width=0.25, label=f"tested at {depth:g} m")
ax_err.set_xticks(np.arange(len(labels)), labels, rotation=25, ha="right", fontsize=8)
ax_err.set_yscale("log")
ax_err.set_ylabel("mean error on the physics [% of range]")
ax_err.set_title("calibrated on ..., tested on the physics")
ax_err.legend(fontsize=8)
plt.show()
