"""Reading a result file back: what ``save_npz`` wrote loads as it was; anything else (another kind of result, a
foreign npz, a torn or changed file) is one ``StoreError`` naming the file and the loader to use, never a numpy
or zipfile traceback."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mincam_sim.changes import Changes, RunInfo
from mincam_sim.errors import StoreError
from mincam_sim.measurements import Measurements


def _changes() -> Changes:
    names = ["x", "y"]
    dp = Measurements(np.array([[0.1, -0.2], [0.3, 0.4]]), np.full((2, 2), 0.01), names, {"seed": 3})
    p = Measurements(np.array([[1.1, 0.8], [1.3, 1.4]]), np.full((2, 2), 0.02), names, {"seed": 3})
    info = RunInfo(solver="stratified_change", seed=3, replicates=8, rays_per_mixel_per_frame=100,
                   spp_per_mixel_per_frame=64, target_rel_stderr=0.0, reached_rel_stderr=0.1, retried_frames=(1,),
                   heavy_tailed=((1, 0),), fallbacks=(), guided_frames=2, launches="frozen")
    return Changes(dp, p, info, {"time_s": np.array([0.0, 0.5])})


def test_a_saved_change_run_loads_as_it_was(tmp_path):
    path = _changes().save_npz(tmp_path / "c.npz")
    back = Changes.load_npz(path)
    np.testing.assert_array_equal(back.dp.irradiance_w_m2, _changes().dp.irradiance_w_m2)
    np.testing.assert_array_equal(back.p.stderr_w_m2, _changes().p.stderr_w_m2)
    assert back.info == _changes().info and list(back.frame_columns) == ["time_s"]


def test_measurements_read_as_a_change_run_name_the_right_loader(tmp_path):
    path = Measurements(np.ones((2, 2)), np.zeros((2, 2)), ["a", "b"], {}).save_npz(tmp_path / "m.npz")
    with pytest.raises(StoreError, match=r"m\.npz is not a file written by Changes\.save_npz.*lacks "
                                         r"delta_irradiance_w_m2"):
        Changes.load_npz(path)
    np.savez(tmp_path / "no_info.npz", **{k: np.ones((2, 2)) for k in ("irradiance_w_m2", "stderr_w_m2",
                                                                        "delta_irradiance_w_m2",
                                                                        "delta_stderr_w_m2")},
             mixel_names=np.array(["a", "b"]), meta_json=np.array(json.dumps({"seed": 1})))
    with pytest.raises(StoreError, match="no run_info.*Measurements.load_npz"):
        Changes.load_npz(tmp_path / "no_info.npz")


@pytest.mark.parametrize("loader", [Changes.load_npz, Measurements.load_npz])
def test_foreign_files_are_one_store_error_naming_the_file(tmp_path, loader):
    np.savez(tmp_path / "other.npz", a=np.arange(3))
    (tmp_path / "text.npz").write_text("not an npz")
    np.savez(tmp_path / "list_meta.npz", irradiance_w_m2=np.ones((2, 2)), stderr_w_m2=np.ones((2, 2)),
             delta_irradiance_w_m2=np.ones((2, 2)), delta_stderr_w_m2=np.ones((2, 2)),
             mixel_names=np.array(["a", "b"]), meta_json=np.array("[1, 2]"))
    np.savez(tmp_path / "shapes.npz", irradiance_w_m2=np.ones((2, 3)), stderr_w_m2=np.ones((2, 2)),
             delta_irradiance_w_m2=np.ones((2, 3)), delta_stderr_w_m2=np.ones((2, 2)),
             mixel_names=np.array(["a", "b"]), meta_json=np.array(json.dumps({"run_info": {}})))
    for name, why in (("other", "lacks irradiance_w_m2"), ("text", "cannot be read as an npz"),
                      ("list_meta", "meta_json is not a JSON object"), ("shapes", "do not fit together")):
        with pytest.raises(StoreError, match=rf"{name}\.npz is not a file written by .*{why}"):
            loader(tmp_path / f"{name}.npz")
    with pytest.raises(FileNotFoundError):
        loader(tmp_path / "absent.npz")


def test_a_torn_or_changed_change_run_is_a_store_error_at_every_length(tmp_path):
    """Cut short at every length, and one byte changed at each of many places: the file loads as it was, or
    gives a StoreError; no other exception gets out."""
    whole = _changes().save_npz(tmp_path / "c.npz").read_bytes()
    torn = tmp_path / "torn.npz"
    outcomes = set()
    cuts = list(range(0, len(whole), 7)) + [len(whole) - 1]
    changed = [whole[:i] + bytes([whole[i] ^ 0x5A]) + whole[i + 1:] for i in range(0, len(whole), 11)]
    for data in [whole[:n] for n in cuts] + changed:
        torn.write_bytes(data)
        try:
            back = Changes.load_npz(torn)
        except StoreError:
            outcomes.add("store error")
            continue
        outcomes.add("loaded")
        assert back.info == _changes().info or back.dp.irradiance_w_m2.shape == (2, 2)
    assert "store error" in outcomes
