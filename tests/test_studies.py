"""Studies on dask: the same numbers on 1 or N workers, resume after a kill, clear errors."""

from __future__ import annotations

import numpy as np
import pytest

from mincam_sim.errors import ConfigError, StaleResultError
from mincam_sim.studies import load_study, run_study
from mincam_sim.studies import runner as runner_mod

TINY = {
    "study": {"name": "tiny", "experiment": "intrusion", "seed": 3},
    "grid": {"spacing_m": [0.0, 0.05], "depth_m": [0.5, 0.8]},
    "metrics": {"keep": ["avg_after_pct", "noisy_avg_after_pct"]},
}


def test_two_workers_equal_serial(tmp_path):
    spec = load_study(TINY, quick=True)
    serial, s1 = run_study(spec, workers=0, quick=True, out_dir=tmp_path / "serial", show_progress=False)
    parallel, s2 = run_study(spec, workers=2, quick=True, out_dir=tmp_path / "two", show_progress=False)
    assert s1["points_computed"] == s2["points_computed"] == 4 and s2["workers"] == 2
    for metric in spec.metrics:
        assert np.all(np.isfinite(serial[metric].values))
        np.testing.assert_array_equal(serial[metric].values, parallel[metric].values)
    assert serial["avg_after_pct"].dims == ("spacing_m", "depth_m")
    assert (tmp_path / "two" / "summary.json").is_file()


def test_killed_study_resumes_with_finished_points(tmp_path, monkeypatch):
    spec = load_study(TINY, quick=True)
    clean, _ = run_study(spec, workers=0, quick=True, out_dir=tmp_path / "clean", show_progress=False)
    original = runner_mod.compute_point
    calls = []

    def dying(*args):
        calls.append(args)
        if len(calls) == 3:
            raise KeyboardInterrupt  # killed while computing the third point
        return original(*args)

    monkeypatch.setattr(runner_mod, "compute_point", dying)
    with pytest.raises(KeyboardInterrupt):
        run_study(spec, workers=0, quick=True, out_dir=tmp_path / "killed", show_progress=False)
    monkeypatch.setattr(runner_mod, "compute_point", original)
    resumed, summary = run_study(spec, workers=0, quick=True, out_dir=tmp_path / "killed", show_progress=False)
    assert summary["points_reused"] == 2 and summary["points_computed"] == 2
    for metric in spec.metrics:
        np.testing.assert_array_equal(resumed[metric].values, clean[metric].values)


def test_a_different_study_in_the_same_dir_is_refused(tmp_path):
    run_study(load_study(TINY, quick=True), workers=0, quick=True, out_dir=tmp_path, show_progress=False)
    other = {**TINY, "study": {**TINY["study"], "seed": 4}}
    with pytest.raises(StaleResultError, match="different study.*seed"):
        run_study(load_study(other, quick=True), workers=0, quick=True, out_dir=tmp_path, show_progress=False)


@pytest.mark.parametrize(
    ("raw", "message"),
    [
        ({"study": {"experiment": "nope"}, "grid": {"depth_m": [0.5]}}, "experiment = 'nope' is not one of"),
        ({"study": {"experiment": "intrusion"}, "grid": {"depth": [0.5]}}, "depth: not a parameter"),
        ({"study": {"experiment": "intrusion"}, "grid": {"depth_m": []}}, "non-empty list"),
        ({"study": {"experiment": "intrusion"}}, "exactly one of"),
        ({"study": {"experiment": "intrusion"}, "points": {"depth_m": [0.5], "spacing_m": [0, 1]}}, "equal lengths"),
        ({"study": {"experiment": "intrusion", "seed": True}, "grid": {"depth_m": [0.5]}}, "seed must be"),
        ({"study": {"experiment": "intrusion"}, "grid": {"depth_m": [0.5]}, "metrics": {"keep": ["x"]}}, "keep"),
    ],
)
def test_bad_study_files_name_the_field(raw, message):
    with pytest.raises(ConfigError, match=message):
        load_study(raw)


def test_shipped_study_files_load():
    from pathlib import Path

    for path in sorted((Path(__file__).resolve().parents[1] / "scenes" / "studies").glob("*.toml")):
        spec = load_study(path, quick=True)
        assert spec.points
