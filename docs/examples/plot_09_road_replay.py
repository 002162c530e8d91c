"""
A vehicle's speed over a replayed road
======================================

One mixel with the paper's sinusoid mask (Eq. 9) looks down from 30 cm at a textured road under an overcast
sky; the vehicle moves at 8 m/s, so the road slides under the mixel. Only the road moves, within its own plane,
and nothing else in the scene reflects light, so the :class:`~mincam_sim.render.solvers.PlaneReplay` solver
traces the mixel's rays once and turns every frame into a texture lookup per ray. We check a few frames
against the :class:`~mincam_sim.render.solvers.Aperture` solver, which traces each frame (same seed: the same
numbers to float32 rounding), and read the speed from the FFT peak of the signal's first difference
(Eq. 10-14), as the speed experiment does.
"""

# %%
# The road, the mixel and the frames
# ----------------------------------
# ``textured_plane`` scales its local square [-1, 1]² by the matrix, so the frames set the whole ``to_world``:
# the road's placement and its 6 m x 0.6 m size.
import matplotlib.pyplot as plt
import numpy as np

import mincam_sim as ms
from mincam_sim.estimation.estimators import scene_frequency, speed_from_signal
from mincam_sim.experiments.layouts import sinusoid_mixel
from mincam_sim.experiments.setup import Setup
from mincam_sim.scene import objects

setup = Setup()
period_m, height_m, speed_m_s, rate_hz, n_frames = 0.2e-3, 0.3, 8.0, 2500.0, 256
cam = ms.Mincam((sinusoid_mixel(setup, period_m, ms.Pose((0.0, 0.0, height_m), (0.0, 0.0, -1.0),
                                                          (0.0, 1.0, 0.0))),))
rng = np.random.default_rng(0)
texture = objects.road_texture((256, 2048), rng)  # asphalt grain, patches, lane markings and dashes


def road_at(x_m: float) -> np.ndarray:
    """The road's to_world with its centre at (x, 0, 0) [m]."""
    return ms.Pose((x_m, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0)).matrix() @ np.diag([3.0, 0.3, 1.0, 1.0])


sim = ms.Simulation(cam, world={"road": ms.textured_plane(texture, 2.0, 2.0, road_at(0.0)), "sky": ms.sky(1.0)})
times_s = np.arange(n_frames) / rate_hz
frames = [{"road.to_world": road_at(2.5 - speed_m_s * t)} for t in times_s]  # the road moves -x under the mixel

# %%
# Replay every frame, trace a few
# -------------------------------
budget = ms.Budget(spp=1 << 16, replicates=4, seed=1)
replayed = sim.measure(frames, solver=ms.PlaneReplay("road"), budget=budget)
checked = np.arange(0, n_frames, 32)
traced = sim.measure([frames[i] for i in checked], solver=ms.Aperture(), budget=budget)
difference = np.abs(replayed.irradiance_w_m2[checked] / traced.irradiance_w_m2 - 1).max()
print(f"replayed vs traced, {len(checked)} frames: largest relative difference {difference:.1e}")

# %%
# The speed from the signal
# -------------------------
# The mask's frequency on the road is scaled by the depth (Eq. 10): omega_d = omega_m d_f / d. The peak is
# searched in the band of a speedometer built for 4-16 m/s.
omega_d = float(scene_frequency(2 * np.pi / period_m, setup.d_f_m, height_m))
signal = replayed.irradiance_w_m2[:, 0]
band_hz = (0.5 * omega_d * 4.0 / (2 * np.pi), 1.5 * omega_d * 16.0 / (2 * np.pi))
estimate = speed_from_signal(np.diff(signal), rate_hz, omega_d, min_frequency_hz=band_hz[0],
                             max_frequency_hz=min(band_hz[1], rate_hz / 2))
print(f"true speed {speed_m_s:.2f} m/s, estimated {estimate:.2f} m/s ({100 * (estimate / speed_m_s - 1):+.1f} %)")

fig, (ax, ax_f) = plt.subplots(1, 2, figsize=(9, 3.4), layout="constrained", width_ratios=(3, 2))
ax.plot(1e3 * times_s, 1e3 * signal, lw=1, label="replayed (PlaneReplay), every frame")
ax.errorbar(1e3 * times_s[checked], 1e3 * traced.irradiance_w_m2[:, 0], yerr=1e3 * traced.stderr_w_m2[:, 0],
            fmt="o", ms=4, label="traced (Aperture), ±σ")
ax.set_xlabel("time [ms]")
ax.set_ylabel("mixel irradiance [mW/m²]")
ax.set_title(f"one sinusoid mixel 30 cm over a road at {speed_m_s:g} m/s", fontsize=10)
ax.legend(loc="upper center", bbox_to_anchor=(0.62, 1.0), fontsize=8)
freqs_hz = np.fft.rfftfreq(n_frames - 1, 1 / rate_hz)
power = np.abs(np.fft.rfft(np.diff(signal) * np.hanning(n_frames - 1))) ** 2
ax_f.semilogy(freqs_hz, power, lw=1)
ax_f.axvline(omega_d * speed_m_s / (2 * np.pi), color="k", ls="--", lw=0.8, label="true ω_d v / 2π")
ax_f.axvline(omega_d * estimate / (2 * np.pi), color="C3", ls=":", lw=1.2, label="estimated peak")
ax_f.axvspan(0, band_hz[0], color="0.9")
ax_f.set_xlabel("frequency [Hz]")
ax_f.set_ylabel("power of P(t) − P(t − Δt)")
ax_f.legend(fontsize=8)
plt.show()
