"""``reproduce`` into a folder that holds an earlier run of the same set-up: an experiment whose files (plots,
data) were deleted is run again, saying which files it lacked, instead of being reused while its outputs stay
lost."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import mincam_sim  # noqa: F401  (before Dr.Jit / Mitsuba)
from mincam_sim.experiments import registry
from mincam_sim.experiments.base import ExperimentResult
from mincam_sim.experiments.setup import Setup


@dataclass(frozen=True)
class _Params:
    level: float = 1.0


class _Writes:
    """An experiment that writes a plot and a data file, and counts its runs."""

    name = "writes"
    version = 1
    Params = _Params

    def __init__(self) -> None:
        self.runs = 0

    def params(self, quick: bool = False, table: dict | None = None) -> _Params:
        return _Params()

    def run(self, setup: Setup, params: _Params, out_dir: Path, show_progress: bool = False) -> ExperimentResult:
        self.runs += 1
        (out_dir / "writes_plot.png").write_bytes(b"png")
        (out_dir / "writes_data.npz").write_bytes(b"npz")
        return ExperimentResult(self.name, 1.0, 0.5, 3, None)


def test_an_experiment_whose_files_were_deleted_runs_again_and_one_whose_files_are_there_is_reused(
        tmp_path, monkeypatch):
    fake = _Writes()
    monkeypatch.setitem(registry.REGISTRY, fake.name, fake)
    out = tmp_path / "repro"
    said: list[str] = []

    def run() -> dict:
        return registry.reproduce([fake.name], Setup(quick=True), out, say=said.append)

    first = run()
    assert first[fake.name]["files"] == ["writes_data.npz", "writes_plot.png"]
    (out / "notes.txt").write_text("mine")  # a user's own file: no experiment's
    assert run()["meta"]["reused"] == [fake.name] and fake.runs == 1 and said == []

    (out / "writes_plot.png").unlink()  # before: reused, and the plot stayed lost
    again = run()
    assert fake.runs == 2 and (out / "writes_plot.png").is_file()
    assert again["meta"].get("reused", []) == []
    assert said == [f"{out} lacks writes_plot.png of experiment writes: running it again"]
    assert json.loads((out / "results.json").read_text())[fake.name]["files"] == ["writes_data.npz",
                                                                                   "writes_plot.png"]


def test_an_entry_of_an_older_run_without_a_file_list_is_reused_as_before(tmp_path, monkeypatch):
    fake = _Writes()
    monkeypatch.setitem(registry.REGISTRY, fake.name, fake)
    out = tmp_path / "repro"
    registry.reproduce([fake.name], Setup(quick=True), out, say=print)
    results = json.loads((out / "results.json").read_text())
    del results[fake.name]["files"]
    (out / "results.json").write_text(json.dumps(results))
    (out / "writes_plot.png").unlink()
    assert registry.reproduce([fake.name], Setup(quick=True), out, say=print)["meta"]["reused"] == [fake.name]
    assert fake.runs == 1
