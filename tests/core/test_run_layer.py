"""Persistence kept out of the numerics: solvers write rows to a sink, ``Run`` owns the one lock, the identity
records and the stores; one identity builder; identities equal to those of stores written before."""

from __future__ import annotations

import builtins
import io
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

import mincam_sim as ms
import mincam_sim.storage.identity as idm
from mincam_sim.configuration.config import load_config
from mincam_sim.errors import OutDirLockedError, StaleResultError, StoreError
from mincam_sim.frames import MemorySink, collect
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.updates import vertex_update
from mincam_sim.render.solvers import aperture, change
from mincam_sim.render.solvers import response_map as rms
from mincam_sim.runs.jobs import run_render_config
from mincam_sim.scene.display import line_sweep
from mincam_sim.storage import store
from mincam_sim.storage.identity import IDENTITY_KINDS, build_identity, run_key

ROOT = Path(__file__).resolve().parents[2]
SCREEN = ms.Screen(resolution=(32, 18))
FIXED_VERSIONS = {"mincam_sim method": "M", "mitsuba": "m", "drjit": "d", "numpy": "n"}
PARK = np.array([5.0, 5.0, 0.0])


def _frames(n: int = 4) -> np.ndarray:
    return line_sweep((-0.2, 0.0), (0.2, 0.0), n, 0.05).frame_stack(SCREEN)


def _world(replicates: int = 4):
    cam = ms.cross_layout(center=ms.Pose((0, 0, 0.5), (0, 0, -1), (0, 1, 0)))
    box = trimesh.creation.box((0.05, 0.05, 0.05))
    box.apply_translation((0, 0, 0.025))
    elements = {"table": sd.textured_plane(np.full((4, 4), 0.5), 1.0, 1.0, ms.Pose((0, 0, 0), (0, 0, 1)).matrix()),
                "sky": sd.sky(2.0), "box": sd.mesh_object("box", box.vertices + PARK, box.faces, 0.9)}
    world = ms.Simulation(cam, world=elements)
    frames = [vertex_update("box", box.vertices + [x, 0.02, 0.0]) for x in (-0.08, 0.08)]
    return world, frames, vertex_update("box", box.vertices + PARK), box


def _plain(spp: int, seed: int = 0, replicates: int = 4):
    return ms.PlainChange(), ms.Budget(spp=spp, seed=seed, replicates=replicates)


@pytest.fixture(scope="module")
def world_parts():
    return _world()


# ------------------------------------------------------------------------------------- no files without a sink


def _forbid_files(monkeypatch, tmp_path):
    """Every Python-level way to write, create or lock a file, or to open a store or cache, fails the test
    (reading is allowed: the run's identity key reads the installed packages' versions)."""
    def refuse(*args, **kwargs):
        raise AssertionError(f"a solver run without a sink touched the file system: {args[:2]}")

    def read_only(opener, mode_at: int):
        def checked(*args, **kwargs):
            mode = kwargs.get("mode", args[mode_at] if len(args) > mode_at else "r")
            if any(c in str(mode) for c in "wax+"):
                refuse(*args)
            return opener(*args, **kwargs)
        return checked

    def os_read_only(path, flags, *args, **kwargs):
        if flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT):
            refuse(path, flags)
        return real_os_open(path, flags, *args, **kwargs)

    real_os_open = os.open
    monkeypatch.setattr(builtins, "open", read_only(builtins.open, 1))
    monkeypatch.setattr(io, "open", read_only(io.open, 1))
    monkeypatch.setattr(os, "open", os_read_only)
    for owner, name in [(os, "mkdir"), (os, "makedirs"), (os, "replace"), (os, "rename"),
                        (np.lib.format, "open_memmap"), (store.DirLock, "__init__"),
                        (store.ResultStore, "__init__"), (store.ContentCache, "put"), (store.ContentCache, "get")]:
        monkeypatch.setattr(owner, name, refuse)
    monkeypatch.chdir(tmp_path)


def _no_identity(monkeypatch):
    """An in-memory run builds no identity: the builder fails the test."""
    def refuse(*args, **kwargs):
        raise AssertionError("an in-memory run built an identity")

    for name in ("build_identity", "run_identity", "display_frames_identity", "scene_file_digests"):
        monkeypatch.setattr(idm, name, refuse)


@pytest.mark.parametrize("solver", [ms.ResponseMap(), ms.Aperture()], ids=["response_map", "aperture"])
def test_a_display_solver_run_without_a_sink_writes_no_file(solver, tmp_path, monkeypatch):
    budget = ms.Budget(spp=1 << 10, samples_per_texel=16, seed=1)
    reference = ms.Simulation(ms.pair_layout(), screen=SCREEN).measure(_frames(), solver, budget)  # kernels built
    _forbid_files(monkeypatch, tmp_path)
    _no_identity(monkeypatch)
    m = ms.Simulation(ms.pair_layout(), screen=SCREEN).measure(_frames(), solver, budget)
    m2 = ms.Simulation(ms.pair_layout(), screen=SCREEN).measure(_frames(), solver, budget, sink=MemorySink())
    monkeypatch.undo()
    assert list(tmp_path.iterdir()) == []
    np.testing.assert_array_equal(m.irradiance_w_m2, reference.irradiance_w_m2)
    np.testing.assert_array_equal(m2.stderr_w_m2, reference.stderr_w_m2)


def test_a_world_solver_run_without_a_sink_writes_no_file(world_parts, tmp_path, monkeypatch):
    world, frames, background, _ = world_parts
    reference = world.measure_changes(frames, background, *_plain(1 << 10, 2))
    _forbid_files(monkeypatch, tmp_path)
    _no_identity(monkeypatch)
    ch = world.measure_changes(frames, background, *_plain(1 << 10, 2))
    monkeypatch.undo()
    assert list(tmp_path.iterdir()) == []
    np.testing.assert_array_equal(ch.dp.irradiance_w_m2, reference.dp.irradiance_w_m2)


# ------------------------------------------------------------------------------------ resume through ms.Run


def test_display_run_killed_mid_run_resumes_through_run_with_the_same_numbers(tmp_path, monkeypatch):
    sim = ms.Simulation(ms.pair_layout(), screen=SCREEN)
    frames, budget = _frames(5), ms.Budget(spp=1 << 10, seed=3)
    reference = sim.measure(frames, ms.Aperture(), budget)
    calls = []
    original = aperture.Aperture.estimates

    def dying(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt  # killed while measuring the third frame
        return original(self, *args, **kwargs)

    monkeypatch.setattr(aperture.Aperture, "estimates", dying)
    with pytest.raises(KeyboardInterrupt), ms.Run(tmp_path) as run:
        run.measure(sim, frames, ms.Aperture(), budget)
    assert np.load(tmp_path / "measurements" / "done.npy").tolist() == [True, True, False, False, False]
    calls.clear()

    def counting(self, *args, **kwargs):
        calls.append(1)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(aperture.Aperture, "estimates", counting)
    with ms.Run(tmp_path) as run:
        resumed = run.measure(sim, frames, ms.Aperture(), budget)
    assert len(calls) == 3  # only the frames the killed run did not finish
    np.testing.assert_array_equal(resumed.irradiance_w_m2, reference.irradiance_w_m2)
    np.testing.assert_array_equal(resumed.stderr_w_m2, reference.stderr_w_m2)


def test_world_run_killed_mid_run_resumes_through_run_with_the_same_numbers(world_parts, tmp_path, monkeypatch):
    world, frames, background, box = world_parts
    frames = [*frames, vertex_update("box", box.vertices + [0.0, -0.05, 0.0])]
    reference = world.measure_changes(frames, background, *_plain(1 << 10, 4))
    original = change._PlainRun.frame
    calls = []

    kill = [True]

    def dying(self, frames_, i, replicates, purpose):
        calls.append(i)
        if i == 2 and kill[0]:
            raise KeyboardInterrupt  # killed while measuring the last frame
        return original(self, frames_, i, replicates, purpose)

    monkeypatch.setattr(change._PlainRun, "frame", dying)
    with pytest.raises(KeyboardInterrupt), ms.Run(tmp_path) as run:
        run.measure_changes(world, frames, background, *_plain(1 << 10, 4), name="changes")
    assert np.load(tmp_path / "changes" / "done.npy").tolist() == [True, True, False]
    calls.clear()
    kill[0] = False
    with ms.Run(tmp_path) as run:
        ch = run.measure_changes(world, frames, background, *_plain(1 << 10, 4), name="changes")
    assert set(calls) == {2}  # only the frame the killed run did not finish
    np.testing.assert_array_equal(ch.dp.irradiance_w_m2, reference.dp.irradiance_w_m2)
    np.testing.assert_array_equal(ch.dp.stderr_w_m2, reference.dp.stderr_w_m2)
    np.testing.assert_array_equal(ch.p.irradiance_w_m2, reference.p.irradiance_w_m2)
    assert ch.info == reference.info


def test_a_finished_run_is_returned_without_rendering(world_parts, tmp_path, monkeypatch):
    world, frames, background, _ = world_parts
    sim = ms.Simulation(ms.pair_layout(), screen=SCREEN)
    with ms.Run(tmp_path) as run:
        m = run.measure(sim, _frames(2), ms.Aperture(), ms.Budget(spp=1 << 10))
        ch = run.measure_changes(world, frames, background, *_plain(1 << 10), name="changes")

    def refuse(*args, **kwargs):
        raise AssertionError("a finished run was planned again")

    for solver in (ms.Aperture, ms.PlainChange):
        monkeypatch.setattr(solver, "plan", refuse)
    with ms.Run(tmp_path) as run:
        again = run.measure(sim, _frames(2), ms.Aperture(), ms.Budget(spp=1 << 10))
        ch_again = run.measure_changes(world, frames, background, *_plain(1 << 10), name="changes")
    np.testing.assert_array_equal(again.irradiance_w_m2, m.irradiance_w_m2)
    np.testing.assert_array_equal(ch_again.dp.stderr_w_m2, ch.dp.stderr_w_m2)
    assert ch_again.info == ch.info and again.meta["identity_key"] == m.meta["identity_key"]


# ----------------------------------------------------------------------------------- one lock, one store


def _small_config(tmp_path: Path, **run):
    return load_config({"run": {"samples_per_texel": 16, "out_dir": str(tmp_path / "out"), **run},
                        "frames": {"n": 2}, "screen": {"resolution": [32, 18]}})


def test_a_render_job_has_one_lock_file_and_one_store(tmp_path):
    run_render_config(_small_config(tmp_path))
    out = tmp_path / "out"
    assert sorted(out.rglob(store.LOCK_NAME)) == [out / store.LOCK_NAME]
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("run.json")) == ["measurements/run.json"]


def test_a_run_with_several_stores_has_one_lock_file(world_parts, tmp_path):
    world, frames, background, _ = world_parts
    sim = ms.Simulation(ms.pair_layout(), screen=SCREEN)
    with ms.Run(tmp_path) as run:
        run.measure(sim, _frames(2), ms.ResponseMap(), ms.Budget(samples_per_texel=16), name="display")
        run.measure_changes(world, frames, background, *_plain(1 << 10), name="world")
    assert sorted(tmp_path.rglob(store.LOCK_NAME)) == [tmp_path / store.LOCK_NAME]
    assert {p.parent.name for p in tmp_path.rglob("run.json")} == {"display", "world"}


_HOLDER = """
import sys, time
import mincam_sim as ms
with ms.Run(sys.argv[1]):
    print("locked", flush=True)
    time.sleep(60)
"""


def test_a_store_inside_a_run_another_process_holds_is_refused(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    holder = subprocess.Popen([sys.executable, "-c", _HOLDER, str(tmp_path)], stdout=subprocess.PIPE, text=True,
                              env=env)
    try:
        assert holder.stdout.readline().strip() == "locked"
        with pytest.raises(OutDirLockedError, match=f"inside {tmp_path}, in use by another run \\(PID {holder.pid}"):
            store.ResultStore(tmp_path / "run", 2, ["a"], {"seed": 0})
        with pytest.raises(OutDirLockedError, match=f"PID {holder.pid}"), ms.Run(tmp_path):
            pass
    finally:
        holder.kill()
        holder.wait(timeout=30)
        holder.stdout.close()
    with store.ResultStore(tmp_path / "run", 2, ["a"], {"seed": 0}):  # free once the holder is gone
        pass


def test_a_sink_needs_the_runs_lock_held_and_over_its_directory(tmp_path):
    with ms.Run(tmp_path / "a") as run:
        sink = run.sink("x", {"seed": 0})
        assert sink.lock is run._lock
        with pytest.raises(StoreError, match="does not cover"):
            store.StoreSink(tmp_path / "b", {"seed": 0}, lock=run._lock)
        with pytest.raises(StoreError, match="identified run"):
            run.sink("y").open(2, ["a"])
    with pytest.raises(StoreError, match="not held"):
        sink.open(2, ["a"])
    with pytest.raises(ms.InputError, match="with-block"):
        ms.Run(tmp_path / "a").sink("x")


# ------------------------------------------------------------------------------- a changed identity refuses


def test_a_changed_identity_refuses_through_run_and_overwrite_replaces(tmp_path):
    sim = ms.Simulation(ms.pair_layout(), screen=SCREEN)
    frames = _frames(3)
    with ms.Run(tmp_path) as run:
        run.measure(sim, frames, ms.ResponseMap(), ms.Budget(samples_per_texel=16, seed=1))
    before = (tmp_path / "measurements" / "values.npy").read_bytes()
    with ms.Run(tmp_path) as run, pytest.raises(StaleResultError, match=r"changed: .*seed 1 -> 2"):
        run.measure(sim, frames, ms.ResponseMap(), ms.Budget(samples_per_texel=16, seed=2))
    assert (tmp_path / "measurements" / "values.npy").read_bytes() == before  # refused, nothing written
    fresh = sim.measure(frames, ms.ResponseMap(), ms.Budget(samples_per_texel=16, seed=2))
    with ms.Run(tmp_path, overwrite=True) as run:
        replaced = run.measure(sim, frames, ms.ResponseMap(), ms.Budget(samples_per_texel=16, seed=2))
    np.testing.assert_array_equal(replaced.irradiance_w_m2, fresh.irradiance_w_m2)


def test_a_changed_config_refuses_before_anything_is_traced(tmp_path, monkeypatch):
    run_render_config(_small_config(tmp_path))
    monkeypatch.setattr(rms, "response_maps", lambda *a, **k: pytest.fail("traced although refused"))
    with pytest.raises(StaleResultError, match="seed"):
        run_render_config(_small_config(tmp_path, seed=7))


# ------------------------------------------------------------------------------------ one identity builder


def test_every_identity_goes_through_the_builder_and_it_checks_its_kind():
    assert set(IDENTITY_KINDS) == {"run", "render_config", "world_config", "design", "study", "reproduce"}
    with pytest.raises(ValueError, match="unknown identity kind"):
        build_identity("nope", {})
    with pytest.raises(ValueError, match=r"missing \['files'\], unknown \['path'\]"):
        build_identity("world_config", {"config": {}, "path": "x"}, variant="v")
    with pytest.raises(ValueError, match="needs the Mitsuba variant"):
        build_identity("reproduce", {"setup": {}})
    with pytest.raises(ValueError, match="records no variant"):
        build_identity("design", {"task": "t", "quick": True, "seed": 0, "setup": {}}, variant="v")
    identity = build_identity("reproduce", {"setup": {"a": 1}}, variant="v")
    assert identity == {"setup": {"a": 1}, "variant": "v", "versions": idm.library_versions()}


def test_no_module_builds_versions_into_an_identity_by_hand():
    """``library_versions()`` is read by the builder (and the response-map cache key) only."""
    users = sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "mincam_sim").rglob("*.py")
                   if "library_versions()" in p.read_text())
    assert users == ["mincam_sim/render/kernels/map_tracing.py", "mincam_sim/storage/identity.py"]


# Keys of the one identity of a run (kind "run", built by Run; library versions pinned), recorded when Run became
# the only place that builds it: a store written since must resume, so these must not move unless the identity's
# parts change on purpose (then an older store is refused, naming what changed, never reused). The per-solver
# identities written before (kinds "display_frames", "world_changes") are gone: their stores are refused. Moved on
# purpose in 0.6.0: the scene identity lists the masks by mixel (a refusal names them), and the change solvers are
# named plain_change / stratified_change (stores of 0.5.0 are refused, naming what changed).
GOLDEN_KEYS = {
    "display_rm": "0f93b954eab506f9e2917eb40bdca815",
    "display_rm_target": "8721be75fe5de6df31b34d42f7443430",
    "display_fast": "fe124a253823c67936409692c824bfe5",
    "world_plain": "00d73123563bfc654e4f31d577d068ce",
    "world_stratified": "2afe4ce456b4d0fec6648eea7a6b3c2f",
    "render_config": "f643a51f149a87831f372662a32eda53",
    "render_config_fast": "e7520306e0695c9b310545f3377ddb0e",
}


@pytest.fixture
def pinned_versions(monkeypatch, mi_variant):
    if mi_variant != "llvm_ad_mono":
        pytest.skip("golden keys were recorded with the llvm_ad_mono variant")
    monkeypatch.setattr(idm, "library_versions", lambda: dict(FIXED_VERSIONS))


def _stored_identity(directory: Path) -> dict:
    import json

    return json.loads((directory / "run.json").read_text())["identity"]


def test_display_identities_equal_those_of_stores_written_before(pinned_versions, tmp_path):
    sim = ms.Simulation(ms.pair_layout(), screen=SCREEN)
    frames = _frames()
    cases = {"display_rm": (ms.ResponseMap(), ms.Budget(samples_per_texel=16, seed=1)),
             "display_rm_target": (ms.ResponseMap(), ms.Budget(target_rel_stderr=1e-2, seed=2)),
             "display_fast": (ms.Aperture(), ms.Budget(spp=1 << 10, seed=3))}
    with ms.Run(tmp_path) as run:
        for name, (solver, budget) in cases.items():
            run.measure(sim, frames, solver, budget, name=name)
    keys = {name: run_key(_stored_identity(tmp_path / name)) for name in cases}
    assert keys == {name: GOLDEN_KEYS[name] for name in cases}


def test_world_identities_equal_those_of_stores_written_before(pinned_versions, world_parts, tmp_path):
    world, frames, background, _ = world_parts
    budget = ms.Budget(spp=1 << 10, seed=5, replicates=4)
    with ms.Run(tmp_path) as run:
        for est, solver in (("plain", ms.PlainChange()), ("stratified", ms.StratifiedChange())):
            with pytest.warns(change.FallbackWarning) if est == "stratified" else _nothing():
                run.measure_changes(world, frames, background, solver, budget, name=f"world_{est}")
    keys = {f"world_{est}": run_key(_stored_identity(tmp_path / f"world_{est}")) for est in ("plain", "stratified")}
    assert keys == {name: GOLDEN_KEYS[name] for name in keys}


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


# --------------------------------------------------------------------------------------- the sink protocol


def test_collect_writes_every_row_and_closes_the_table_on_an_error():
    class Table:
        def __init__(self):
            self.values, self.stderr = np.full((3, 1), np.nan), np.full((3, 1), np.nan)
            self.written, self.closed = [], False

        def pending(self):
            return np.arange(3)

        def write(self, idx, v, e):
            self.written.append(int(idx[0]))

        def close(self):
            self.closed = True

    def rows():
        yield np.array([0]), np.ones((1, 1)), np.zeros((1, 1))
        raise KeyboardInterrupt

    table = Table()
    with pytest.raises(KeyboardInterrupt):
        collect(rows(), table)
    assert table.written == [0] and table.closed


def test_out_dir_is_gone_and_a_store_needs_the_runs_identity(tmp_path):
    sim = ms.Simulation(ms.pair_layout(), screen=SCREEN)
    with pytest.raises(TypeError, match="out_dir"):
        sim.measure(_frames(2), ms.ResponseMap(), ms.Budget(samples_per_texel=16), out_dir=tmp_path)
    with ms.Run(tmp_path) as run, pytest.raises(StoreError, match="identified run"):
        sim.measure(_frames(2), ms.Aperture(), ms.Budget(spp=1 << 10), sink=run.sink("x"))
    assert not (tmp_path / "x").exists()
