"""Content identity, the verified and locked result store, atomic writes and the content cache (no Mitsuba)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from mincam_sim import Pose, Screen, masks, pair_layout
from mincam_sim.errors import MincamError, OutDirLockedError, StaleResultError, StoreError
from mincam_sim.model.optics import Mixel
from mincam_sim.storage.atomic import (
    atomic_path,
    atomic_save_npy,
    atomic_save_npz,
    atomic_write_bytes,
    atomic_write_text,
    leftover_temporaries,
)
from mincam_sim.storage.identity import (
    StreamingHash,
    canonical,
    diff_identities,
    fingerprint,
    frames_fingerprint,
    library_versions,
)
from mincam_sim.storage.store import CacheWarning, ContentCache, ResultStore, check_identity, clear_store

ROOT = Path(__file__).resolve().parents[2]


# ------------------------------------------------------------------------------------------------ identity


def test_fingerprint_follows_content_not_names():
    a = masks.sinusoid(3000.0, phase_rad=0.0, resolution=32)
    b = masks.sinusoid(3000.0, phase_rad=1.0, resolution=32)
    assert a.name == b.name and a.shape == b.shape  # what the old identity recorded
    assert fingerprint(a) != fingerprint(b)
    assert fingerprint(a) == fingerprint(masks.sinusoid(3000.0, phase_rad=0.0, resolution=32))
    assert fingerprint(pair_layout()) == fingerprint(pair_layout())
    assert fingerprint(pair_layout(0.033)) != fingerprint(pair_layout(0.034))
    assert fingerprint(Screen()) != fingerprint(Screen(resolution=(128, 72)))
    assert fingerprint(Mixel(a)) != fingerprint(Mixel(a, pose=Pose((0.001, 0.0, 0.0))))
    assert len(fingerprint(a)) >= 16 and int(fingerprint(a), 16) >= 0


def test_fingerprint_of_mask_ignores_where_its_file_was():
    t = np.linspace(0, 1, 16).reshape(4, 4)
    one = masks.Mask(t, name="m", meta={"source": "/a/m.png", "format": "png"})
    two = masks.Mask(t, name="m", meta={"source": "../b/m.png", "format": "png"})
    assert fingerprint(one) == fingerprint(two)


def test_canonical_numbers_arrays_and_types():
    assert fingerprint({"x": 2}) == fingerprint({"x": 2.0})
    assert fingerprint({"x": True}) != fingerprint({"x": 1})
    assert fingerprint({"a": 1, "b": [1, 2]}) == fingerprint({"b": (1, 2), "a": 1})
    assert fingerprint(np.zeros(3)) != fingerprint(np.zeros(3, dtype=np.float32))
    assert fingerprint(np.zeros((2, 3))) != fingerprint(np.zeros((3, 2)))
    assert fingerprint(Path("a/b")) == fingerprint("a/b")
    assert fingerprint(float("nan")) == fingerprint(np.nan)
    assert fingerprint(np.float64(0.1)) == fingerprint(0.1)
    with pytest.raises(TypeError, match="fingerprint"):
        fingerprint(object())


def test_fingerprint_parts_opt_in_and_dataclasses():
    class Thing:
        def __init__(self, v):
            self.v = v

        def fingerprint_parts(self):
            return {"v": self.v}

    @dataclass(frozen=True)
    class Box:
        size_m: float
        data: np.ndarray

    assert fingerprint(Thing(1)) == fingerprint(Thing(1)) != fingerprint(Thing(2))
    assert fingerprint(Box(1.0, np.ones(2))) != fingerprint(Box(1.0, np.zeros(2)))
    assert json.dumps(canonical(Box(1.0, np.ones(2))))  # JSON-serialisable


def test_streaming_hash_does_not_depend_on_chunking():
    rng = np.random.default_rng(0)
    frames = rng.random((10, 4, 5))
    whole = StreamingHash().update(frames).hexdigest()
    chunked = StreamingHash()
    for a, b in ((0, 3), (3, 7), (7, 10)):
        chunked.update(frames[a:b])
    by_frame = StreamingHash()
    for f in frames:
        by_frame.update(f)
    assert whole == chunked.hexdigest() == by_frame.hexdigest() == frames_fingerprint(frames)
    assert frames_fingerprint(iter(frames)) == whole
    assert frames_fingerprint(frames[:9]) != whole
    changed = frames.copy()
    changed[5, 2, 2] += 1e-12
    assert frames_fingerprint(changed) != whole
    with pytest.raises(ValueError, match="shape"):
        StreamingHash().update(frames).update(np.zeros((3, 3)))


def test_library_versions_without_importing_mitsuba():
    code = ("import sys; from mincam_sim.storage.identity import library_versions; v = library_versions(); "
            "assert 'mitsuba' not in sys.modules and 'drjit' not in sys.modules; print(sorted(v))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "mitsuba" in out and "drjit" in out and "numpy" in out and "mincam_sim" in out
    assert library_versions()["numpy"] == np.__version__


def test_diff_names_what_changed():
    old = canonical({"seed": 0, "masks": ["a" * 32], "budget": {"spp": 16, "target": 0.0}})
    new = canonical({"seed": 1, "masks": ["b" * 32], "budget": {"spp": 32, "target": 0.0}, "form": "fast"})
    assert diff_identities(old, new) == ["budget.spp 16 -> 32", "form (new)", "masks", "seed 0 -> 1"]


# --------------------------------------------------------------------------------------------- result store


def ident(**kw):
    return {"seed": 0, "masks": [fingerprint(masks.ramp("x", 8))], "form": "fast", **kw}


def test_store_resumes_the_same_run(tmp_path):
    with ResultStore(tmp_path, 5, ["a", "b"], ident()) as store:
        assert not store.resumed and list(store.pending()) == [0, 1, 2, 3, 4]
        store.write([0, 2], np.ones((2, 2)), np.full((2, 2), 0.1))
    with ResultStore(tmp_path, 5, ["a", "b"], ident()) as again:
        assert again.resumed
        assert list(again.pending()) == [1, 3, 4]
        np.testing.assert_array_equal(again.values[2], [1.0, 1.0])
        assert np.isnan(again.values[1]).all()
    info = json.loads((tmp_path / "run.json").read_text())
    assert info["identity"]["seed"] == 0 and info["key"] == again.key


@pytest.mark.parametrize(
    ("change", "named"),
    [({"seed": 1}, "seed 0 -> 1"),
     ({"masks": [fingerprint(masks.ramp("1-x", 8))]}, "masks"),
     ({"form": "reference"}, "form"),
     ({"budget": {"spp": 1}}, "budget (new)")],
)
def test_store_refuses_a_different_run_naming_what_changed(tmp_path, change, named):
    ResultStore(tmp_path, 3, ["a"], ident()).close()
    with pytest.raises(StaleResultError) as err:
        ResultStore(tmp_path, 3, ["a"], ident(**change))
    msg = str(err.value)
    assert "\n" not in msg and str(tmp_path) in msg and named in msg and "--overwrite" in msg
    assert "different run" in msg and isinstance(err.value, ValueError) and isinstance(err.value, MincamError)


def test_store_refuses_other_shape_and_overwrite_replaces(tmp_path):
    with ResultStore(tmp_path, 3, ["a"], ident()) as store:
        store.write([0], np.ones((1, 1)), np.ones((1, 1)))
    with pytest.raises(StaleResultError, match="n_frames 3 -> 4"):
        ResultStore(tmp_path, 4, ["a"], ident())
    with pytest.raises(StaleResultError, match="columns"):
        ResultStore(tmp_path, 3, ["b"], ident())
    with ResultStore(tmp_path, 4, ["a"], ident(seed=5), overwrite=True) as fresh:
        assert not fresh.resumed and len(fresh.pending()) == 4
    with ResultStore(tmp_path, 4, ["a"], ident(seed=5)) as again:
        assert again.resumed


def _make_store(tmp_path):
    with ResultStore(tmp_path, 4, ["a", "b"], ident()) as store:
        store.write([0], np.ones((1, 2)), np.ones((1, 2)))


def _truncate(path: Path, keep: int) -> None:
    data = path.read_bytes()
    path.write_bytes(data[:keep])


TORN = {
    "run.json empty": ("run.json", lambda p: p.write_bytes(b"")),
    "run.json half": ("run.json", lambda p: _truncate(p, 40)),
    "run.json foreign": ("run.json", lambda p: p.write_text('{"hello": 1}')),
    "run.json list": ("run.json", lambda p: p.write_text("[1, 2]")),
    "values.npy empty": ("values.npy", lambda p: p.write_bytes(b"")),
    "values.npy text": ("values.npy", lambda p: p.write_text("this is text, not an array\n")),
    "values.npy header cut": ("values.npy", lambda p: _truncate(p, 20)),
    "values.npy data cut": ("values.npy", lambda p: _truncate(p, p.stat().st_size - 8)),
    "values.npy wrong shape": ("values.npy", lambda p: np.save(p, np.zeros((5, 5)))),
    "values.npy wrong dtype": ("values.npy", lambda p: np.save(p, np.zeros((4, 2), dtype=np.float32))),
    "stderr.npy missing": ("stderr.npy", lambda p: p.unlink()),
    "done.npy pickled": ("done.npy", lambda p: np.save(p, np.array([{}] * 4, dtype=object), allow_pickle=True)),
}


@pytest.mark.parametrize("case", sorted(TORN))
def test_torn_or_foreign_store_is_a_clear_store_error(tmp_path, case):
    _make_store(tmp_path)
    name, damage = TORN[case]
    damage(tmp_path / name)
    with pytest.raises(StoreError) as err:
        ResultStore(tmp_path, 4, ["a", "b"], ident())
    msg = str(err.value)
    assert "\n" not in msg and name in msg
    assert "--overwrite" in msg or "delete" in msg
    assert "allow_pickle" not in msg and "pickle.load" not in msg
    # and the way out works
    with ResultStore(tmp_path, 4, ["a", "b"], ident(), overwrite=True) as fresh:
        assert len(fresh.pending()) == 4


def test_store_of_an_older_mincam_sim_is_refused(tmp_path):
    (tmp_path / "run.json").write_text(json.dumps({"key": "abc", "shape": [3, 1], "columns": ["a"]}))
    with pytest.raises(StaleResultError, match="older mincam_sim"):
        ResultStore(tmp_path, 3, ["a"], ident())


def test_store_directory_that_is_a_file(tmp_path):
    target = tmp_path / "file"
    target.write_text("x")
    with pytest.raises(StoreError, match="is an existing file"):
        ResultStore(target, 3, ["a"], ident())


def test_uncommitted_store_files_are_recreated(tmp_path):
    """Arrays without run.json are a creation that never committed: start afresh, no error."""
    _make_store(tmp_path)
    (tmp_path / "run.json").unlink()
    (tmp_path / "values.npy").write_bytes(b"")
    with ResultStore(tmp_path, 4, ["a", "b"], ident()) as store:
        assert len(store.pending()) == 4


def test_same_process_reopen_supersedes_the_older_store(tmp_path):
    first = ResultStore(tmp_path, 3, ["a"], ident())  # e.g. kept alive by an interrupted run's traceback
    second = ResultStore(tmp_path, 3, ["a"], ident())
    with pytest.raises(StoreError, match="superseded"):
        first.write([0], np.ones((1, 1)), np.ones((1, 1)))
    second.write([0], np.ones((1, 1)), np.ones((1, 1)))
    first.close()  # releases nothing the second one holds
    second.close()
    with pytest.raises(StoreError, match="closed"):
        second.write([1], np.ones((1, 1)), np.ones((1, 1)))


_HOLDER = """
import sys, time
import numpy as np
from mincam_sim.storage.store import ResultStore
store = ResultStore(sys.argv[1], 3, ["a"], {"seed": 0})
print("locked", flush=True)
time.sleep(60)
"""

_OPENER = """
import sys
from mincam_sim.storage.store import ResultStore
from mincam_sim.errors import OutDirLockedError
try:
    ResultStore(sys.argv[1], 3, ["a"], {"seed": 0}).close()
    print("opened")
except OutDirLockedError as err:
    print("refused:", err)
"""


def _spawn(code: str, directory: Path, **kw) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-c", code, str(directory)], stdout=subprocess.PIPE, text=True,
                            env=env, **kw)


def test_second_process_is_refused_while_a_run_holds_the_dir(tmp_path):
    with ResultStore(tmp_path, 3, ["a"], {"seed": 0}):
        out = _spawn(_OPENER, tmp_path).communicate(timeout=60)[0]
        assert out.startswith("refused:")
        assert str(tmp_path) in out and f"PID {os.getpid()}" in out and "\n" not in out.strip()
    out = _spawn(_OPENER, tmp_path).communicate(timeout=60)[0]
    assert out.strip() == "opened"  # released on close


def test_lock_of_a_killed_process_is_released(tmp_path):
    holder = _spawn(_HOLDER, tmp_path)
    try:
        assert holder.stdout.readline().strip() == "locked"
        with pytest.raises(OutDirLockedError, match=f"PID {holder.pid}"):
            ResultStore(tmp_path, 3, ["a"], {"seed": 0})
        holder.send_signal(signal.SIGKILL)
        holder.wait(timeout=30)
    finally:
        if holder.poll() is None:
            holder.kill()
        holder.stdout.close()
    with ResultStore(tmp_path, 3, ["a"], {"seed": 0}) as store:
        assert store.resumed


def test_rows_survive_a_kill(tmp_path):
    code = """
import os, sys, numpy as np
from mincam_sim.storage.store import ResultStore
store = ResultStore(sys.argv[1], 5, ["a"], {"seed": 0})
store.write([0, 1], np.array([[1.0], [2.0]]), np.array([[0.1], [0.2]]))
os.kill(os.getpid(), 9)
"""
    proc = _spawn(code, tmp_path)
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    with ResultStore(tmp_path, 5, ["a"], {"seed": 0}) as store:
        assert list(store.pending()) == [2, 3, 4]
        np.testing.assert_array_equal(store.values[:2, 0], [1.0, 2.0])


# ------------------------------------------------------------------------------------------- atomic writes


class Crash(Exception):
    pass


@pytest.fixture
def crashing_replace(monkeypatch):
    def replace(src, dst):
        raise Crash("simulated crash at rename")

    monkeypatch.setattr(os, "replace", replace)


@pytest.mark.parametrize(
    "write",
    [lambda p: atomic_write_text(p, "new"),
     lambda p: atomic_write_bytes(p, b"new"),
     lambda p: atomic_save_npy(p, np.arange(3)),
     lambda p: atomic_save_npz(p, a=np.arange(3))],
    ids=["text", "bytes", "npy", "npz"],
)
def test_atomic_write_that_crashes_leaves_the_old_file_and_no_partial_file(tmp_path, crashing_replace, write):
    path = tmp_path / "result.dat"
    path.write_bytes(b"old")
    with pytest.raises(Crash):
        write(path)
    assert path.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["result.dat"]


def test_atomic_path_cleans_up_when_the_writer_fails(tmp_path):
    path = tmp_path / "img.exr"
    with pytest.raises(Crash), atomic_path(path) as tmp:
        assert tmp.suffix == ".exr" and tmp.parent == tmp_path
        tmp.write_bytes(b"partial")
        raise Crash
    assert not path.exists() and leftover_temporaries(tmp_path) == []


def test_atomic_writes_round_trip(tmp_path):
    atomic_save_npz(tmp_path / "a.npz", w=np.arange(4.0))
    with np.load(tmp_path / "a.npz") as d:
        np.testing.assert_array_equal(d["w"], np.arange(4.0))
    atomic_save_npy(tmp_path / "b.npy", np.eye(2))
    np.testing.assert_array_equal(np.load(tmp_path / "b.npy"), np.eye(2))
    assert atomic_write_text(tmp_path / "sub" / "c.txt", "hé").read_text(encoding="utf-8") == "hé"


def test_store_creation_that_crashes_is_not_taken_for_a_run(tmp_path, monkeypatch):
    real = os.replace
    calls = {"n": 0}

    def flaky(src, dst):
        calls["n"] += 1
        if str(dst).endswith("run.json"):
            raise Crash("killed before the store was committed")
        return real(src, dst)

    monkeypatch.setattr(os, "replace", flaky)
    with pytest.raises(Crash):
        ResultStore(tmp_path, 3, ["a"], ident())
    monkeypatch.setattr(os, "replace", real)
    assert not (tmp_path / "run.json").exists() and leftover_temporaries(tmp_path) == []
    with ResultStore(tmp_path, 3, ["a"], ident(seed=9)) as store:  # no stale refusal: nothing was committed
        assert not store.resumed


def test_clear_store_removes_only_store_files(tmp_path):
    _make_store(tmp_path)
    (tmp_path / "mine.txt").write_text("keep")
    removed = clear_store(tmp_path, extra=("response_maps.npz",))
    assert sorted(p.name for p in removed) == ["done.npy", "run.json", "stderr.npy", "values.npy"]
    assert (tmp_path / "mine.txt").exists()


# ------------------------------------------------------------------------------------------- identity file


def test_check_identity(tmp_path):
    assert check_identity(tmp_path, {"seed": 0}) is False
    assert check_identity(tmp_path, {"seed": 0}) is True
    with pytest.raises(StaleResultError, match="seed 0 -> 1"):
        check_identity(tmp_path, {"seed": 1})
    assert check_identity(tmp_path, {"seed": 1}, overwrite=True) is False
    (tmp_path / "identity.json").write_text("{")
    with pytest.raises(StoreError, match="identity.json"):
        check_identity(tmp_path, {"seed": 1})


# ------------------------------------------------------------------------------------------- content cache


def test_cache_round_trip_and_compute_once(tmp_path):
    cache = ContentCache(tmp_path / "cache")
    key = fingerprint({"maps": 1})
    assert cache.get(key) is None
    calls = {"n": 0}

    def compute():
        calls["n"] += 1
        return {"weights_sr": np.arange(6.0).reshape(2, 3)}, {"samples_per_texel": 64}

    entry, hit = cache.get_or_compute(key, compute)
    assert not hit and calls["n"] == 1
    entry2, hit2 = cache.get_or_compute(key, compute)
    assert hit2 and calls["n"] == 1
    np.testing.assert_array_equal(entry2.arrays["weights_sr"], entry.arrays["weights_sr"])
    assert entry2.meta == {"samples_per_texel": 64}
    assert leftover_temporaries(tmp_path / "cache") == []


def test_cache_ignores_torn_and_mismatched_files(tmp_path):
    cache = ContentCache(tmp_path)
    key, other = fingerprint("a"), fingerprint("b")
    path = cache.put(key, {"w": np.ones(1000)})
    # a file copied (or renamed) under another key is not trusted
    cache.path(other).write_bytes(path.read_bytes())
    with pytest.warns(CacheWarning, match="holds key"):
        assert cache.get(other) is None
    assert not cache.path(other).exists()
    # a torn file
    _truncate(path, path.stat().st_size // 2)
    with pytest.warns(CacheWarning, match="torn"):
        assert cache.get(key) is None
    # arrays that do not match their digest
    good = cache.put(key, {"w": np.ones(3)})
    with np.load(good) as d:
        payload = {k: d[k] for k in d.files}
    payload["w"] = np.zeros(3)
    with open(good, "wb") as fh:
        np.savez(fh, **payload)
    with pytest.warns(CacheWarning, match="digest"):
        assert cache.get(key) is None


def test_cache_keys_are_checked(tmp_path):
    cache = ContentCache(tmp_path)
    with pytest.raises(ValueError, match="cache key"):
        cache.path("../escape")
    with pytest.raises(ValueError, match="names"):
        cache.put(fingerprint("x"), {"__key__": np.ones(1)})


def test_unreferenced_store_releases_its_lock(tmp_path):
    """A store nobody references any more holds no lock (garbage collection releases it)."""
    store = ResultStore(tmp_path, 3, ["a"], {"seed": 0})
    del store
    out = _spawn(_OPENER, tmp_path).communicate(timeout=60)[0]
    assert out.strip() == "opened"
