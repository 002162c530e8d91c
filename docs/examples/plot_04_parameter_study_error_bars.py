"""
A parameter study with error bars
=================================

How does the calibrated intrusion error through the 12-bit sensor grow with the sensor's read noise? A study
is a target (here ``spacing``: the screen boundary sweep of the intrusion experiment, one set-up per point), a
grid over its parameters and the metrics to keep; its result is an xarray ``Dataset`` (dimensions = swept
parameters) in a Zarr store. One study gives one number per point, computed with one seed; the error bars come
from **replicates**: the same study with independent seeds (each point's seed derives from the study's seed
and the point's parameters, so the replicates are independent of each other and of the order the points run
in). Each replicate draws new sensor noise and new rendering noise.

Quick mode (15 positions per sweep, 16 samples per texel) and four replicates keep this to a few seconds; the
command line runs the same studies on a dask cluster (``mincam-sim study run STUDY.toml --workers 2``).
"""

# %%
# The study, as a dict (a TOML file has the same sections)
# --------------------------------------------------------
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from mincam_sim.studies import load_study, run_study

READ_NOISE_E = [1.0, 30.0, 100.0, 300.0, 1000.0]
SEEDS = [0, 1, 2, 3]
root = Path(tempfile.mkdtemp(prefix="mincam_study_"))


def study_spec(seed: int) -> dict:
    return {
        "study": {
            "name": "read_noise",
            "experiment": "spacing",
            "seed": seed,
            "out_dir": str(root / f"seed{seed}"),
        },
        "fixed": {"spacing_m": 0.033, "depth_m": 0.5},
        "grid": {"read_noise_e": READ_NOISE_E},
        "metrics": {
            "keep": ["avg_after_pct", "noisy_avg_after_pct", "noisy_max_after_pct"]
        },
    }


# %%
# Run the replicates
# ------------------
# ``workers=1`` computes the points in this process, one after the other (no cluster); results go to
# ``<out_dir>/results.zarr`` as each point finishes, so a killed study resumes.
datasets = []
for seed in SEEDS:
    ds, summary = run_study(
        load_study(study_spec(seed), quick=True),
        workers=1,
        quick=True,
        show_progress=False,
    )
    datasets.append(ds)
    print(
        f"seed {seed}: {summary['points_computed']} points in {summary['wall_seconds']:.1f} s"
    )
runs = xr.concat(datasets, dim=xr.DataArray(SEEDS, dims="replicate", name="replicate"))
print(runs[["noisy_avg_after_pct"]].to_dataframe().unstack("replicate").round(2))

# %%
# Mean and its standard error over the replicates
# -----------------------------------------------
# The error bar is the standard error of the mean over the replicates, ``std(ddof=1) / sqrt(n)``; the grey
# points are the replicates themselves. The noiseless error (the geometry alone) is the floor.
noisy = runs["noisy_avg_after_pct"]
mean = noisy.mean("replicate")
sem = noisy.std("replicate", ddof=1) / np.sqrt(noisy.sizes["replicate"])
floor = runs["avg_after_pct"].mean("replicate")

fig, ax = plt.subplots(figsize=(6.4, 3.6), constrained_layout=True)
for r in range(noisy.sizes["replicate"]):
    ax.plot(
        READ_NOISE_E,
        noisy.isel(replicate=r),
        "o",
        color="0.7",
        ms=3,
        label="replicates" if r == 0 else None,
    )
ax.errorbar(
    READ_NOISE_E, mean, yerr=sem, fmt="o-", capsize=3, label="mean ± standard error"
)
ax.plot(READ_NOISE_E, floor, "k--", lw=1, label="noiseless read-out")
ax.set_xscale("log")
ax.set_xlabel("read noise per pixel [e⁻ rms]")
ax.set_ylabel("average position error [% of field]")
ax.set_title("intrusion, 12-bit sensor, 48 × 48 pixels averaged")
ax.legend()
ax.grid(alpha=0.3, which="both")

for rn, m_, s_ in zip(READ_NOISE_E, mean.values, sem.values, strict=True):
    print(f"read noise {rn:6.0f} e-: {m_:.2f} ± {s_:.2f} % (n = {len(SEEDS)})")

# %%
# Bigger studies
# --------------
# More replicates shrink the bars as 1 / sqrt(n); full mode (drop ``quick=True``) uses 41 positions and 64
# samples per texel. ``scenes/studies/noise_detector.toml`` crosses read noise with the detector size.
