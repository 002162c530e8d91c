"""One registry, one implementation, one definition of each paper constant.

* every experiment of the registry runs as a study point with the parameters it declares, and that point is
  the experiment's own run (the parameters reach the set-up or the experiment's dataclass as named);
* the spacing study's point is the spacing experiment's result for the same set-up, bit for bit;
* with the paper's numbers changed in :mod:`mincam_sim.paper` alone, every default that stands for them
  (set-up, sensor, mixel, mask, screen, design task, study targets, paper error rates) follows: no copy left.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from mincam_sim import paper
from mincam_sim.errors import StaleResultError
from mincam_sim.estimation.calibration import ExtrapolationWarning
from mincam_sim.experiments import REGISTRY, Setup, reproduce
from mincam_sim.experiments.spacing import Spacing, SpacingParams
from mincam_sim.studies import load_study, run_study, study_target, target_names

ROOT = Path(__file__).resolve().parents[2]

# the smallest runs each experiment accepts (seconds each); every key is a declared study parameter
TINY = {
    "intrusion": {"spp": 1 << 14, "calibration_positions": 12, "frame_rate_hz": 2.0, "camera_px": 48,
                  "mask_resolution": 64, "spacing_m": 0.03, "calibration_rel_stderr": 1e-2},
    "tracking": {"spp": 1 << 14, "frames_per_toy": 2, "calibration_grid": 9, "camera_px": 48,
                 "mask_resolution": 64, "toy_size_m": 0.06, "calibration_rel_stderr": 1e-2},
    "speed": {"spp": 1 << 14, "video_frames": 16, "vehicle_frames": 16, "turn_frames": 16, "vehicle_spp": 1 << 12,
              "turn_spp": 1 << 12, "video_samples_per_texel": 4, "display_timing_draws": 1, "mask_resolution": 64},
    "spacing": {"spacing_m": 0.02, "depth_m": 1.0},
}


def test_the_registry_is_every_study_target():
    assert set(TINY) == set(REGISTRY), "a registry experiment without a tiny study point here"
    assert target_names() == (*REGISTRY, "render", "design")
    for name, exp in REGISTRY.items():
        target = study_target({"name": name})
        assert target.metrics == exp.study_metrics and target.metrics, name
        assert target.seconds_per_point == exp.study_seconds and target.ref["name"] == name


@pytest.mark.parametrize("name", sorted(TINY))
def test_every_registry_experiment_runs_as_a_study_point(name, tmp_path):
    exp = REGISTRY[name]
    target = study_target({"name": name})
    assert set(TINY[name]) <= set(target.parameters)
    given = {**target.parameters, **TINY[name]}  # a study gives every parameter: the others at their defaults
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ExtrapolationWarning)
        out = target.point(given, 4, True)
        assert set(target.metrics) <= set(out), f"declared metrics missing: {set(target.metrics) - set(out)}"
        assert all(isinstance(out[m], float) for m in target.metrics)
        assert any(np.isfinite(out[m]) for m in target.metrics)
        if name == "spacing":
            return  # its own test below: one (spacing, depth) of the experiment
        # the point is the experiment's run: set-up fields to the set-up, the others to its parameters
        setup_fields = {f.name for f in dataclasses.fields(Setup)}
        setup = Setup(quick=True, seed=4, **{k: v for k, v in given.items() if k in setup_fields})
        params = dataclasses.replace(exp.params(True), **{k: v for k, v in given.items() if k not in setup_fields})
        result = exp.run(setup, params, tmp_path).as_dict()
    for metric in target.metrics:
        expected = np.nan if result[metric] is None else float(result[metric])
        np.testing.assert_equal(out[metric], expected, err_msg=metric)


def test_the_spacing_study_point_is_the_spacing_experiments_result_bit_for_bit(tmp_path):
    """The point's noiseless metrics against the experiment's own run of the same set-up (one spacing, one depth,
    the point's sweep), compared exactly; its noisy read-out is the same sweep through the noisy sensor."""
    target = study_target({"name": "spacing"})
    params = {**target.parameters, "spacing_m": 0.05, "depth_m": 0.8, "calibration_depth_m": 0.45, "d_f_m": 2.2e-3,
              "bit_depth": 10}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ExtrapolationWarning)
        point = target.point(params, 9, True)
        setup = Setup(depth_m=0.45, spacing_m=0.05, d_f_m=2.2e-3, bit_depth=10, seed=9, quick=True)
        sweep = SpacingParams(spacings_m=(0.05,), depths_m=(0.8,), positions=15, samples_per_texel=16,
                              screen_texels=96)
        result = REGISTRY["spacing"].run(setup, sweep, tmp_path).details
    row = result["by_depth"]["0.8"]
    for key in ("avg_before_pct", "max_before_pct", "avg_after_pct", "max_after_pct"):
        assert point[key] == row[key][0], key  # exactly: one implementation
    assert point["noisy_avg_after_pct"] != point["avg_after_pct"]  # the noise is drawn, not the noiseless copied


def test_a_study_point_version_is_part_of_the_study_identity(tmp_path, monkeypatch):
    """Raising a target's ``study_version`` (its point's numbers changed) refuses a store of the older point."""
    raw = {"study": {"name": "v", "experiment": "spacing", "seed": 1, "replicates": 1},
           "grid": {"spacing_m": [0.0]}, "metrics": {"keep": ["avg_after_pct"]}}
    run_study(load_study(raw, quick=True), quick=True, out_dir=tmp_path, show_progress=False, workers=1)
    assert load_study(raw, quick=True).experiment.ref == {"name": "spacing"}  # stores of 0.2.0 stay valid
    monkeypatch.setattr(Spacing, "study_version", 2)
    with pytest.raises(StaleResultError):
        run_study(load_study(raw, quick=True), quick=True, out_dir=tmp_path, show_progress=False, workers=1)


def test_a_reproduction_of_older_experiment_code_is_recomputed_not_reused(tmp_path, monkeypatch):
    """An experiment's ``version`` is part of its results' parameters key."""
    tiny = {"spacing": SpacingParams(spacings_m=(0.02,), depths_m=(0.5,), positions=5, samples_per_texel=4,
                                     screen_texels=8)}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ExtrapolationWarning)
        reproduce(["spacing"], Setup(quick=True), tmp_path, params=tiny)
        assert reproduce(["spacing"], Setup(quick=True), tmp_path, params=tiny)["meta"]["reused"] == ["spacing"]
        monkeypatch.setattr(Spacing, "version", Spacing.version + 1)
        assert reproduce(["spacing"], Setup(quick=True), tmp_path, params=tiny)["meta"]["reused"] == []


# each paper constant replaced by another valid value before the package is imported
PATCHED = {"SPACING_M": 0.041, "PIXELS_AVERAGED": 40 * 40, "DETECTOR_SIZE_M": 1.3e-4, "PIXEL_PITCH_M": 2.7e-6,
           "ADC_BITS": 10, "D_F_M": 2.3e-3, "MASK_SIZE_M": 2.4e-3, "FIELD_M": 0.42, "CALIBRATION_DEPTH_M": 0.55,
           "SCREEN_DIAGONAL_IN": 55.0, "SCREEN_ASPECT": [4, 3], "CALIBRATION_SQUARE_M": 0.027,
           "INTRUSION_BOUNDARY_X_M": -0.11, "INTRUSION_MAX_ERROR_PCT": 1.1, "INTRUSION_AVG_ERROR_PCT": 1.2,
           "TRACKING_MAX_ERROR_PCT": 1.3, "TRACKING_AVG_ERROR_PCT": 1.4, "SPEED_MAX_ERROR_PCT": 1.5,
           "SPEED_AVG_ERROR_PCT": 1.6}

_READ_DEFAULTS = r"""
import importlib.util, json, sys
spec = importlib.util.spec_from_file_location("mincam_sim.paper", sys.argv[1])
paper = importlib.util.module_from_spec(spec)
spec.loader.exec_module(paper)
for key, value in json.loads(sys.argv[2]).items():
    setattr(paper, key, tuple(value) if isinstance(value, list) else value)
sys.modules["mincam_sim.paper"] = paper  # before the package: every module reads the changed values

from mincam_sim import masks
from mincam_sim.configuration.config import load_config
from mincam_sim.design import tracking as tr
from mincam_sim.experiments import REGISTRY, Setup
from mincam_sim.model.optics import Mixel, pair_layout
from mincam_sim.scene.display import Screen
from mincam_sim.model.sensor import SensorModel
from mincam_sim.studies import study_target

s, proto, generic = Setup(), Setup().sensor(), SensorModel()
screen, task, cfg = Screen(), tr.TrackingTask(), load_config({}).mincam[0]  # a render config's default mixel
spacing, intrusion = study_target({"name": "spacing"}).parameters, study_target({"name": "intrusion"}).parameters
seen = {
    "SPACING_M": [s.spacing_m, tr.SPACING_M, task.spacing_m, spacing["spacing_m"], intrusion["spacing_m"],
                  cfg.pose.position_m[0] * 2, abs(pair_layout()[0].pose.position_m[0]) * 2],
    "PIXELS_AVERAGED": [proto.pixels_averaged, tr.sensor().pixels_averaged],
    "DETECTOR_SIZE_M": [s.detector_size_m, proto.detector_area_m2 ** 0.5, tr.DETECTOR_SIZE_M,
                        spacing["detector_size_m"], cfg.detector_size_m,
                        Mixel(masks.ramp("x")).detector_size_m],
    "PIXEL_PITCH_M": [generic.detector_area_m2 ** 0.5],
    "ADC_BITS": [s.bit_depth, proto.bit_depth, generic.bit_depth, tr.BIT_DEPTH, tr.sensor().bit_depth,
                 spacing["bit_depth"], intrusion["bit_depth"]],
    "D_F_M": [s.d_f_m, tr.D_F_M, task.d_f_m, spacing["d_f_m"], cfg.d_f_m,
              Mixel(masks.ramp("x")).d_f_m],
    "MASK_SIZE_M": [s.mask_size_m, tr.MASK_SIZE_M, masks.ramp("x").width_m, cfg.mask.width_m],
    "FIELD_M": [s.field_m, tr.FIELD_M, intrusion["field_m"]],
    "CALIBRATION_DEPTH_M": [s.depth_m, tr.CALIBRATION_DEPTH_M, spacing["depth_m"], spacing["calibration_depth_m"],
                            -Screen().pose.position_m[2], -s.screen().pose.position_m[2]],
    "SCREEN_DIAGONAL_IN": [(screen.width_m ** 2 + screen.height_m ** 2) ** 0.5 / 0.0254],
    "SCREEN_ASPECT": [screen.width_m / screen.height_m],
    "CALIBRATION_SQUARE_M": [tr.CALIBRATION_SQUARE_M, intrusion["calibration_square_m"],
                             REGISTRY["tracking"].Params().calibration_square_m,
                             REGISTRY["spacing"].Params().square_m],
    "INTRUSION_BOUNDARY_X_M": [intrusion["boundary_x_m"]],
}
for name in ("intrusion", "tracking", "speed"):
    numbers = REGISTRY[name].paper
    seen[f"{name.upper()}_MAX_ERROR_PCT"] = [numbers.max_error_pct]
    seen[f"{name.upper()}_AVG_ERROR_PCT"] = [numbers.avg_error_pct]
print(json.dumps(seen))
"""


def test_every_default_reads_the_paper_constants_from_one_place():
    args = [str(ROOT / "mincam_sim" / "paper.py"), json.dumps(PATCHED)]
    run = subprocess.run([sys.executable, "-c", _READ_DEFAULTS, *args], capture_output=True, text=True, timeout=120,
                         cwd=ROOT)
    assert run.returncode == 0, run.stderr[-3000:]
    seen = json.loads(run.stdout.strip().splitlines()[-1])
    assert set(seen) == set(PATCHED)
    for key, values in seen.items():
        want = PATCHED[key][0] / PATCHED[key][1] if key == "SCREEN_ASPECT" else PATCHED[key]
        np.testing.assert_allclose(values, want, rtol=1e-12, err_msg=f"{key}: a default kept its own copy")


def test_the_paper_constants_are_the_papers():
    """The stated values as the paper gives them (a typo here would move every default at once)."""
    assert (paper.SPACING_M, paper.DETECTOR_SIDE_PX, paper.PIXELS_AVERAGED, paper.ADC_BITS) == (0.033, 48, 2304, 12)
    assert (paper.DETECTOR_SIZE_M, paper.FIELD_M, paper.SCREEN_DIAGONAL_IN) == (1e-4, 0.5, 50.0)
    assert paper.INTRUSION_BOUNDARY_X_M == -0.1378
    assert (paper.INTRUSION_MAX_ERROR_PCT, paper.INTRUSION_AVG_ERROR_PCT) == (11.42, 4.83)
    assert (paper.TRACKING_MAX_ERROR_PCT, paper.TRACKING_AVG_ERROR_PCT) == (6.78, 2.82)
    assert (paper.SPEED_MAX_ERROR_PCT, paper.SPEED_AVG_ERROR_PCT) == (7.55, 2.85)
    assert abs(paper.DETECTOR_SIDE_PX * paper.PIXEL_PITCH_M - paper.DETECTOR_SIZE_M) < 0.1 * paper.DETECTOR_SIZE_M
