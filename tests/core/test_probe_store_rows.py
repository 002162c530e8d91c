"""A resumed run's store whose rows marked done were changed on disk (a NaN value, a negative or NaN standard
error): those rows are computed again, with one warning naming them. Before, they were taken for results, and the
run ended after its last frame with a traceback (``ValueError: stderr_w_m2 must be standard errors >= 0 W/m^2``)
or handed back the NaN."""

from __future__ import annotations

import numpy as np
import pytest

import mincam_sim  # noqa: F401  (before Dr.Jit / Mitsuba)
from mincam_sim.storage.store import ResultStore, StoreWarning

IDENTITY = {"seed": 0, "form": "fast"}


@pytest.mark.parametrize(("array", "bad"), [("values", np.nan), ("values", np.inf), ("stderr", -1.0),
                                            ("stderr", np.nan)])
def test_damaged_done_rows_are_pending_again_with_one_warning(tmp_path, array, bad):
    with ResultStore(tmp_path, 4, ["a", "b"], IDENTITY) as store:
        store.write([0, 1, 2], np.ones((3, 2)), np.full((3, 2), 0.1))
    damaged = np.lib.format.open_memmap(tmp_path / f"{array}.npy", mode="r+")
    damaged[1, 0] = bad
    damaged.flush()
    del damaged
    with pytest.warns(StoreWarning, match=r"1 frame\(s\) marked done hold numbers no run writes .*frames 1\)"), \
            ResultStore(tmp_path, 4, ["a", "b"], IDENTITY) as again:
        assert list(again.pending()) == [1, 3]
    assert not np.load(tmp_path / "done.npy")[1]  # on disk too: a kill now still recomputes it


def test_a_whole_store_resumes_without_a_warning(tmp_path, recwarn):
    with ResultStore(tmp_path, 2, ["a"], IDENTITY) as store:
        store.write([0], np.zeros((1, 1)), np.zeros((1, 1)))  # zero is a value, and a standard error
    with ResultStore(tmp_path, 2, ["a"], IDENTITY) as again:
        assert list(again.pending()) == [1]
    assert not [w for w in recwarn if issubclass(w.category, StoreWarning)]
