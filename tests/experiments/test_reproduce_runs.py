"""``reproduce`` runs: an out dir belongs to one set-up. Same set-up: finished experiments are reused (a killed
``reproduce all`` resumes); another set-up, older code or a torn results file: one clear refusal naming the fix,
nothing lost; ``overwrite`` replaces. Uses a stand-in experiment (milliseconds) in place of the real ones."""

from __future__ import annotations

import dataclasses
import json

import pytest

from mincam_sim.errors import ConfigError, StaleResultError, StoreError
from mincam_sim.experiments import Setup, reproduce
from mincam_sim.experiments import registry as reg
from mincam_sim.experiments.base import Experiment, ExperimentResult, PaperNumbers


@dataclasses.dataclass(frozen=True)
class _Params:
    frames: int = 3


class _Counting(Experiment):
    paper_section = "none"
    paper = PaperNumbers(1.0, 0.5)
    Params = _Params

    def __init__(self, name: str, calls: list, dies: bool = False):
        self.name, self.calls, self.dies = name, calls, dies

    def scene(self, setup, params, rng):
        return None

    def run(self, setup, params, out_dir, show_progress=False):
        self.calls.append(self.name)
        if self.dies:
            raise KeyboardInterrupt
        return ExperimentResult(self.name, 1.0 + setup.seed, 0.5, params.frames, self.paper, {"seed": setup.seed})


@pytest.fixture
def fake(monkeypatch):
    calls: list = []
    registry = {"a": _Counting("a", calls), "b": _Counting("b", calls)}
    monkeypatch.setattr(reg, "REGISTRY", registry)
    return registry, calls


def test_same_setup_reuses_finished_experiments_and_a_killed_run_resumes(fake, tmp_path):
    registry, calls = fake
    registry["b"].dies = True
    with pytest.raises(KeyboardInterrupt):
        reproduce(["a", "b"], Setup(quick=True), tmp_path)
    assert calls == ["a", "b"]
    registry["b"].dies = False
    calls.clear()
    results = reproduce(["a", "b"], Setup(quick=True), tmp_path)
    assert calls == ["b"], "the finished experiment should be reused, the killed one run"
    assert results["meta"]["reused"] == ["a"]
    calls.clear()
    reproduce(["a"], Setup(quick=True), tmp_path, params={"a": _Params(frames=5)})
    assert calls == ["a"], "other parameters of the same set-up are run again"
    assert json.loads((tmp_path / "results.json").read_text())["a"]["n"] == 5


def test_another_setup_is_refused_naming_it_and_overwrite_replaces(fake, tmp_path):
    _, calls = fake
    reproduce(["a", "b"], Setup(quick=True, seed=0), tmp_path)
    before = (tmp_path / "results.json").read_text()
    with pytest.raises(StaleResultError, match="seed"):
        reproduce(["a"], Setup(quick=True, seed=3), tmp_path)
    assert (tmp_path / "results.json").read_text() == before, "a refused run must not touch the results"
    results = reproduce(["a"], Setup(quick=True, seed=3), tmp_path, overwrite=True)
    assert set(results) == {"a", "meta"}, "the other set-up's 'b' must not stay under the new set-up's meta"
    assert results["a"]["seed"] == 3 and results["meta"]["setup"]["seed"] == 3


def test_results_of_an_older_version_or_torn_are_clear_errors(fake, tmp_path):
    (tmp_path / "results.json").write_text('{"a": {"max_error_pct": 9.0}}')
    with pytest.raises(StaleResultError, match="older"):
        reproduce(["a"], Setup(quick=True), tmp_path)
    reproduce(["a"], Setup(quick=True), tmp_path, overwrite=True)
    (tmp_path / "results.json").write_text('{"a": ')
    with pytest.raises(StoreError, match="torn"):
        reproduce(["a"], Setup(quick=True), tmp_path)
    with pytest.raises(ConfigError, match="unknown experiment"):
        reproduce(["nope"], Setup(quick=True), tmp_path / "other")
    assert not (tmp_path / "other").exists(), "an unknown name should fail before anything is written"
