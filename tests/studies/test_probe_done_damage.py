"""A study store whose ``done`` marks were damaged on disk (a chunk emptied, overwritten or deleted): the rerun
computes the points whose marks it cannot trust again, saying so, and ends with a whole, readable dataset; before,
an emptied chunk stopped the rerun with a traceback (``RuntimeError: error during blosc decompression``) and a
deleted one left points marked not done that were reused as done."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from study_fixtures import TINY, run_quick

from mincam_sim.studies import load_study


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    out = tmp_path_factory.mktemp("finished")
    ds, _ = run_quick(load_study(TINY, quick=True), out, workers=1)
    return out, ds


def _chunk(out: Path) -> Path:
    return out / "results.zarr" / "done" / "1.0"


@pytest.mark.parametrize(("damage", "computed"), [
    (lambda path: path.write_bytes(b""), 4),  # the whole variable is unreadable: every point is redone
    (lambda path: path.write_bytes(b"not a chunk"), 4),
    (lambda path: path.unlink(), 1),  # reads as not done: that point is redone
], ids=["emptied", "overwritten", "deleted"])
def test_a_damaged_done_chunk_is_recomputed_and_the_numbers_are_the_same(finished, tmp_path, damage, computed):
    source, before = finished
    out = tmp_path / "out"
    shutil.copytree(source, out)
    assert _chunk(out).is_file()
    damage(_chunk(out))
    said: list[str] = []
    ds, summary = run_quick(load_study(TINY, quick=True), out, workers=1, say=said.append)
    assert summary["points_computed"] == computed and summary["points_reused"] == 4 - computed
    assert bool(np.all(ds["done"].values))
    for name in ("avg_after_pct", "noisy_avg_after_pct"):
        np.testing.assert_array_equal(ds[name].values, before[name].values)
    assert any("done" in line for line in said), said
    _, again = run_quick(load_study(TINY, quick=True), out, workers=1)
    assert again["points_reused"] == 4
