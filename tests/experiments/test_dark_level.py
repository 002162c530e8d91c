"""Frames with nothing in view read the sensor's dark level, not a detection at the centre: a bit-depth sweep
on a scene with empty frames (a 4 mm d_f narrows the view so that a third of the swept squares are outside
it). Before the fix the study's noisy read-out scored them at the centre from 10 bits on (18 % avg / 50 % max
against 1.4 % noiseless) and the spacing experiment's noiseless read-out did so at every bit depth (17 % /
50 %)."""

from __future__ import annotations

import numpy as np
import pytest

from mincam_sim.studies import study_target

SPACING = study_target({"name": "spacing"})


@pytest.mark.parametrize("bit_depth", [8, 10, 12, 16])
def test_study_point_ignores_empty_frames_at_any_bit_depth(bit_depth):
    params = {**SPACING.parameters, "d_f_m": 4e-3, "bit_depth": bit_depth}
    out = SPACING.point(params, 0, True)
    assert out["missing_pct"] > 20  # the scene has empty frames
    assert out["noisy_missing_pct"] == out["missing_pct"]  # they are not detections, and no lit frame is lost
    assert abs(out["noisy_avg_after_pct"] - out["avg_after_pct"]) < 0.2
    assert out["noisy_max_after_pct"] < 1.5 * out["max_after_pct"]


@pytest.mark.parametrize("bit_depth", [8, 12])
def test_spacing_experiment_gives_empty_frames_no_position(bit_depth):
    from mincam_sim.experiments import REGISTRY, Setup

    exp = REGISTRY["spacing"]
    setup = Setup(d_f_m=4e-3, bit_depth=bit_depth, quick=True)
    observed, true = exp._observe(setup, exp.params(True), setup.depth_m)
    lit = np.isfinite(observed)
    assert 0.2 < 1 - lit.mean() < 0.6  # the empty frames have no position (before: 0.5, the centre)
    assert np.all(observed[lit] > -0.1) and np.all(observed[lit] < 1.1)
    # the lit frames' observations run monotonically along the sweep: no centre-valued outliers
    assert np.all(np.diff(observed[lit]) > 0)
