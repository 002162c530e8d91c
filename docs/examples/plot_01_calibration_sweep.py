"""
A calibration sweep and its response maps
=========================================

The paper's 1D mincam (two mixels 3.3 cm apart, masks ``x`` and ``1 − x``) looks at a 50″ screen 0.5 m away.
A white 3 cm square is swept along the boundary; each mixel's measurement of each position is rendered with
its Monte Carlo standard error, and the ratio of Eq. 4, ``x_obs = P_x / (P_x + P_1−x)``, is mapped to the
square's true position by a cubic calibration, as the paper does on its screen.

The response-map form traces each mixel's map over the screen's texels once; every frame is then one scalar
product, so the sweep's 21 positions cost no more than one.
"""

# %%
# Render the sweep
# ----------------
# ``Simulation.measure`` with the ``ResponseMap`` solver returns the measurements (irradiance averaged over each
# detector, W/m², with its standard error), and ``m.maps`` the response maps it traced. The budget's
# ``samples_per_texel`` sets the noise; ``target_rel_stderr=1e-3`` would pick it for a target instead.
import matplotlib.pyplot as plt
import numpy as np

import mincam_sim as ms
from mincam_sim import Screen, line_sweep, pair_layout
from mincam_sim.estimation.calibration import Calibration1D
from mincam_sim.estimation.estimators import intrusion_position

# mixel "x" on the right, "1-x" on the left, looking along -z
cam = pair_layout(spacing_m=0.033)
screen = Screen()  # 50" 16:9 display at z = -0.5 m, 256 x 144 texels
# screen coordinates: x right, y up [m]
sweep = line_sweep((-0.2, 0.0), (0.2, 0.0), n=21, size_m=0.03)
sim = ms.Simulation(cam, screen=screen)
m = sim.measure(
    sweep.frame_source(screen),
    solver=ms.ResponseMap(),
    budget=ms.Budget(samples_per_texel=64, seed=0),
)
maps = m.maps
print(
    f"{m.n_frames} positions x {len(m.mixel_names)} mixels ({m.mixel_names}); "
    f"worst relative standard error {np.nanmax(m.relative_stderr()):.1e}"
)

# %%
# What each mixel sees: its response map
# --------------------------------------
# ``W`` is the irradiance on the detector per unit radiance of each texel [sr]: the mask projected onto the
# screen through the aperture, blurred by the detector, vignetted, and cut off where the housing hides the
# screen. The two maps are offset by the mixels' 3.3 cm spacing.
extent_cm = [
    -50 * screen.width_m,
    50 * screen.width_m,
    -50 * screen.height_m,
    50 * screen.height_m,
]
fig, axes = plt.subplots(1, 2, figsize=(9, 2.9), constrained_layout=True)
vmax = maps.weights_sr.max()
for ax, w, name in zip(axes, maps.weights_sr, maps.mixel_names, strict=True):
    im = ax.imshow(w, extent=extent_cm, cmap="magma", vmin=0, vmax=vmax)
    ax.set_title(f"mixel {name}")
    ax.set_xlabel("screen x [cm]")
    ax.set_ylabel("screen y [cm]")
fig.colorbar(im, ax=axes, shrink=0.85, label="W per texel [sr]")

# %%
# The sweep, with 2σ error bars
# -----------------------------
x_cm = 100 * sweep.positions_m[:, 0]
fig, ax = plt.subplots(figsize=(6.4, 3.4), constrained_layout=True)
for k, name in enumerate(m.mixel_names):
    ax.errorbar(
        x_cm,
        1e3 * m.irradiance_w_m2[:, k],
        yerr=2e3 * m.stderr_w_m2[:, k],
        marker="o",
        ms=3,
        capsize=2,
        label=f"mixel {name}",
    )
ax.set_xlabel("square position x [cm]")
ax.set_ylabel("irradiance on detector [mW/m²]")
ax.legend()
ax.grid(alpha=0.3)

# %%
# Calibrate Eq. 4 against the true position
# -----------------------------------------
# The ratio is not the position: the masks' projections are offset by the spacing and blurred, so the paper
# fits a cubic from the observed ratio to the true position. Squares that a mixel does not see whole would bend
# the cubic: the sweep stays within ±20 cm, inside both mixels' fields of view (±25 cm about each axis).
x_obs = intrusion_position(m.irradiance_w_m2[:, 0], m.irradiance_w_m2[:, 1])
cal = Calibration1D.fit(x_obs, sweep.positions_m[:, 0], degree=3)
residual_mm = 1e3 * (cal.apply(x_obs) - sweep.positions_m[:, 0])
print(
    f"cubic calibration: rms residual {1e3 * cal.rms_residual_m:.2f} mm "
    f"over {cal.n_points} positions"
)

fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(9, 3.2), constrained_layout=True)
ax0.plot(x_cm, x_obs, "o", ms=3, label="observed ratio (Eq. 4)")
ax0.plot(
    x_cm,
    (sweep.positions_m[:, 0] + 0.25) / 0.5,
    "k--",
    lw=1,
    label="ideal (co-located, sharp)",
)
ax0.set_xlabel("true position x [cm]")
ax0.set_ylabel("x_obs")
ax0.legend()
ax0.grid(alpha=0.3)
ax1.plot(x_cm, residual_mm, "o-", ms=3)
ax1.set_xlabel("true position x [cm]")
ax1.set_ylabel("calibrated − true [mm]")
ax1.grid(alpha=0.3)
