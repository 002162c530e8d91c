"""What the study tests share: a tiny spacing study (2 x 2 points) and how it is run in quick mode."""

from __future__ import annotations

from mincam_sim.studies import run_study

TINY = {
    "study": {"name": "tiny", "experiment": "spacing", "seed": 3},
    "grid": {"spacing_m": [0.0, 0.05], "depth_m": [0.5, 0.8]},
    "metrics": {"keep": ["avg_after_pct", "noisy_avg_after_pct"]},
}


def run_quick(spec, out, **kw):
    """``run_study`` in quick mode, quiet, into ``out``."""
    return run_study(spec, quick=True, out_dir=out, show_progress=False, **kw)
