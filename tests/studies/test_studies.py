"""Studies on dask: the same numbers on 1 or N workers, resume after a kill, clear errors, stores that never lie."""

from __future__ import annotations

import errno
import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from study_fixtures import TINY, run_quick

from mincam_sim.errors import ConfigError, OutDirLockedError, StaleResultError, StoreError
from mincam_sim.studies import load_study, plot_study, run_study
from mincam_sim.studies import runner as runner_mod
from mincam_sim.studies.plots import display_scale

ROOT = Path(__file__).resolve().parents[2]


def test_two_workers_equal_one(tmp_path):
    import xarray as xr

    spec = load_study(TINY, quick=True)
    serial, s1 = run_quick(spec, tmp_path / "one", workers=1)
    parallel, s2 = run_quick(spec, tmp_path / "two", workers=2)
    assert s1["points_computed"] == s2["points_computed"] == 4 and s2["workers"] == 2
    for var in runner_mod.variables(spec):
        assert np.all(np.isfinite(serial[var].values)), var
    xr.testing.assert_identical(serial, parallel)  # values, coordinates, units and the study's identity
    assert serial["avg_after_pct"].dims == ("spacing_m", "depth_m")
    assert (tmp_path / "two" / "summary.json").is_file()
    assert not (tmp_path / "two" / "drjit_cache").exists()  # the workers' kernel caches are not left in OUT


def test_units_on_every_variable_and_coordinate_and_consolidated_metadata(tmp_path):
    import xarray as xr

    spec = load_study(TINY, quick=True)
    ds, _ = run_quick(spec, tmp_path, workers=1)
    for name in [*ds.data_vars, *ds.coords]:
        assert ds[name].attrs.get("units"), name
    assert ds["spacing_m"].attrs["units"] == "m" and ds["avg_after_pct_stderr"].attrs["units"] == "%"
    assert (tmp_path / "results.zarr" / ".zmetadata").is_file()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the README's plain xr.open_zarr: no warning about metadata
        xr.open_zarr(tmp_path / "results.zarr").load()
    png = plot_study(ds, list(spec.metrics), tmp_path / "study.png")
    assert png.stat().st_size > 10_000
    assert display_scale([0.0, 0.1], "m") == (100.0, "cm") and display_scale([0.001, 0.004], "m") == (1e3, "mm")
    assert display_scale([0.3, 1.0], "m") == (1.0, "m")


def test_common_random_numbers_keep_the_noiseless_metric_flat_along_bit_depth(tmp_path):
    """The bit depth cannot enter a noiseless read-out: with common random numbers its metric is identical
    along the axis; without them (a seed per point) it is seed noise that looks like an effect."""
    raw = {"study": {"name": "crn", "experiment": "spacing", "seed": 0, "replicates": 2},
           "fixed": {"d_f_m": 1e-3}, "grid": {"bit_depth": [8, 12]},
           "metrics": {"keep": ["avg_after_pct", "noisy_avg_after_pct"]}}
    crn, _ = run_quick(load_study(raw, quick=True), tmp_path / "crn", workers=1)
    np.testing.assert_array_equal(crn["avg_after_pct"].values[0], crn["avg_after_pct"].values[1])
    assert np.all(crn["avg_after_pct_stderr"].values > 0)  # the replicates differ: a real spread, stored beside
    indep = {**raw, "study": {**raw["study"], "common_random_numbers": False}}
    own, _ = run_quick(load_study(indep, quick=True), tmp_path / "own", workers=1)
    assert own["avg_after_pct"].values[0] != own["avg_after_pct"].values[1]


def test_killed_study_resumes_with_finished_points(tmp_path, monkeypatch):
    spec = load_study(TINY, quick=True)
    clean, _ = run_quick(spec, tmp_path / "clean", workers=1)
    original = runner_mod.compute_point
    calls = []

    def dying(*args):
        calls.append(args)
        if len(calls) == 3:
            raise KeyboardInterrupt  # killed while computing the third point
        return original(*args)

    monkeypatch.setattr(runner_mod, "compute_point", dying)
    with pytest.raises(KeyboardInterrupt):
        run_quick(spec, tmp_path / "killed", workers=1)
    monkeypatch.setattr(runner_mod, "compute_point", original)
    resumed, summary = run_quick(spec, tmp_path / "killed", workers=1)
    assert summary["points_reused"] == 2 and summary["points_computed"] == 2
    for var in runner_mod.variables(spec):
        np.testing.assert_array_equal(resumed[var].values, clean[var].values)


def test_a_damaged_store_is_named_and_recomputed(tmp_path):
    spec = load_study(TINY, quick=True)
    clean, _ = run_quick(spec, tmp_path, workers=1)
    chunks = sorted(p for p in (tmp_path / "results.zarr" / "noisy_avg_after_pct").iterdir()
                    if not p.name.startswith("."))
    assert len(chunks) == 4
    chunks[1].unlink()  # one metric's chunk of one point is lost
    notices = []
    again, summary = run_quick(spec, tmp_path, workers=1, say=notices.append)
    assert summary["points_reused"] == 3 and summary["points_computed"] == 1
    assert len(notices) == 1 and "noisy_avg_after_pct" in notices[0] and "1 point(s)" in notices[0]
    for var in runner_mod.variables(spec):
        np.testing.assert_array_equal(again[var].values, clean[var].values)


def test_a_store_without_a_variable_is_refused(tmp_path):
    import shutil

    import zarr

    spec = load_study(TINY, quick=True)
    run_quick(spec, tmp_path, workers=1)
    shutil.rmtree(tmp_path / "results.zarr" / "avg_after_pct_stderr")
    zarr.consolidate_metadata(str(tmp_path / "results.zarr"))
    with pytest.raises(StoreError, match="lacks variable.*avg_after_pct_stderr"):
        run_quick(spec, tmp_path, workers=1)


def test_a_full_disk_names_the_file_and_leaves_nothing_half_written(tmp_path, monkeypatch):
    spec = load_study(TINY, quick=True)
    original = runner_mod.atomic_write_json
    writes = []

    def full(path, obj, **kw):
        writes.append(path)
        if Path(path).parent.name == "points" and len([w for w in writes if Path(w).parent.name == "points"]) == 2:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return original(path, obj, **kw)

    monkeypatch.setattr(runner_mod, "atomic_write_json", full)
    with pytest.raises(StoreError, match=r"No space left on device.*not marked complete") as err:
        run_quick(spec, tmp_path, workers=1)
    assert "points/p_0_1.json" in str(err.value)
    assert sorted(p.name for p in (tmp_path / "points").iterdir()) == ["p_0_0.json"]
    monkeypatch.setattr(runner_mod, "atomic_write_json", original)
    _, summary = run_quick(spec, tmp_path, workers=1)
    assert summary["points_reused"] == 1 and summary["points_computed"] == 3


def test_a_second_study_in_a_locked_out_dir_is_refused_naming_its_holder(tmp_path):
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; from mincam_sim.storage.store import lock_out_dir; "
         f"lock = lock_out_dir({str(tmp_path)!r}); print('locked', flush=True); time.sleep(60)"],
        stdout=subprocess.PIPE, text=True, cwd=ROOT, env={"PYTHONPATH": str(ROOT), "PATH": ""})
    try:
        assert holder.stdout.readline().strip() == "locked"
        with pytest.raises(OutDirLockedError, match=f"in use by another run.*{holder.pid}"):
            run_quick(load_study(TINY, quick=True), tmp_path, workers=1)
    finally:
        holder.kill()
        holder.wait()


def test_a_different_study_in_the_same_dir_is_refused(tmp_path):
    run_quick(load_study(TINY, quick=True), tmp_path, workers=1)
    other = {**TINY, "study": {**TINY["study"], "seed": 4}}
    with pytest.raises(StaleResultError, match="different study.*seed"):
        run_quick(load_study(other, quick=True), tmp_path, workers=1)


def _render_study(tmp_path: Path) -> dict:
    """A one-point study over a render config whose mixel's mask is a ``file:`` PNG and whose frames are a
    ``kind = "npy"`` stack (both beside the config)."""
    from mincam_sim.storage.imageio import write_png

    write_png(tmp_path / "m.png", np.tile(np.linspace(0.0, 1.0, 16), (16, 1)))
    frames = np.full((2, 18, 32), 0.5)
    frames[0, :, :8] = frames[1, :, 8:16] = 2.0  # bright on the left: a mirrored mask sees other numbers
    np.save(tmp_path / "frames.npy", frames)
    (tmp_path / "cfg.toml").write_text(
        '[run]\nsolver = "dot_product"\n[mincam]\nlayout = "custom"\n'
        '[[mixel]]\nname = "a"\nmask = "file:m.png"\nposition_m = [0.0, 0.0, 0.0]\n'
        '[screen]\nresolution = [32, 18]\ndistance_m = 0.5\n[frames]\nkind = "npy"\npath = "frames.npy"\n')
    return {"study": {"name": "files", "experiment": "render", "config": str(tmp_path / "cfg.toml"), "seed": 0},
            "grid": {"mincam": {"d_f_m": [0.001, 0.002]}}}


@pytest.mark.filterwarnings("ignore:.*seed is ignored.*dot_product")  # the study sets each point's run seed
def test_a_changed_file_of_a_render_config_refuses_the_store_and_an_unchanged_one_reuses_it(tmp_path):
    """The study's identity holds what every file its render config names holds (a ``file:`` mask, an ``npy``
    frame stack), as ``mincam-sim render`` identifies them: a changed file refuses the store naming what changed,
    like a changed seed; ``overwrite`` computes the new numbers; an unchanged rerun reuses every point."""
    from mincam_sim.storage.imageio import write_png

    raw = _render_study(tmp_path)
    out = tmp_path / "out"

    def run(**kw):
        return run_study(load_study(raw), workers=1, out_dir=out, show_progress=False, **kw)

    first, summary = run()
    metric = "a.mean_irradiance_w_m2"
    assert summary["points_computed"] == 2 and np.all(np.isfinite(first[metric].values))
    assert run()[1]["points_reused"] == 2  # nothing changed: reused

    write_png(tmp_path / "m.png", np.tile(np.linspace(1.0, 0.0, 16), (16, 1)))  # the mask file, mirrored
    with pytest.raises(StaleResultError, match=r"different study \(changed: experiment\.scene\.masks.*--overwrite"):
        run()
    mirrored, summary = run(overwrite=True)
    assert summary["points_computed"] == 2 and not np.allclose(mirrored[metric].values, first[metric].values)
    assert run()[1]["points_reused"] == 2

    np.save(tmp_path / "frames.npy", 2.0 * np.load(tmp_path / "frames.npy"))  # the frame stack, brighter
    with pytest.raises(StaleResultError, match=r"changed: experiment\.frames\.content_sha256\)"):
        run()
    brighter, _ = run(overwrite=True)
    np.testing.assert_allclose(brighter[metric].values, 2.0 * mirrored[metric].values, rtol=1e-9)


REFUSED = [
    ({"study": {"experiment": "nope"}, "grid": {"depth_m": [0.5]}}, "experiment = 'nope' is not one of"),
    ({"study": {"experiment": "spacing"}, "grid": {"depth": [0.5]}}, "depth: not a parameter"),
    ({"study": {"experiment": "intrusion"}, "grid": {"calibration_depth_m": [0.5]}}, "is experiment \"spacing\""),
    ({"study": {"experiment": "spacing"}, "grid": {"depth_m": []}}, "non-empty list"),
    ({"study": {"experiment": "spacing"}}, "exactly one of"),
    ({"study": {"experiment": "spacing"}, "points": {"depth_m": [0.5], "spacing_m": [0, 1]}}, "equal lengths"),
    ({"study": {"experiment": "spacing", "seed": True}, "grid": {"depth_m": [0.5]}}, "seed must be"),
    ({"study": {"experiment": "spacing"}, "grid": {"depth_m": [0.5]}, "metrics": {"keep": ["x"]}}, "keep"),
    ({"study": {"experiment": "spacing"}, "grid": {"bit_depth": [12.5]}}, r"bit_depth is an integer.*12\.5"),
    ({"study": {"experiment": "spacing"}, "fixed": {"bit_depth": 12.0}, "grid": {"depth_m": [0.5]}},
     "bit_depth is an integer"),
    ({"study": {"experiment": "spacing"}, "fixed": {"depth_m": 0.7}, "grid": {"depth_m": [0.5, 1.0]}},
     r"depth_m is both in \[fixed\] and in \[grid\]"),
    ({"study": {"experiment": "spacing"}, "grid": {"depth_m": [0.5, 1.0, 0.5]}}, "lists 0.5 more than once"),
    ({"study": {"experiment": "spacing"}, "points": {"depth_m": [0.5, 0.5]}}, "same point more than once"),
    ({"study": {"experiment": "spacing", "replicates": 0}, "grid": {"depth_m": [0.5]}}, "replicates must be"),
    ({"study": {"experiment": "spacing", "common_random_numbers": 1}, "grid": {"depth_m": [0.5]}},
     "common_random_numbers must be true or false"),
    ({"study": {"experiment": "render"}, "grid": {"mincam": {"d_f_m": [0.002]}}}, "needs config"),
    ({"study": {"experiment": "spacing", "config": "x.toml"}, "grid": {"depth_m": [0.5]}}, "render\" only"),
    ({"study": {"experiment": "spacing"}, "grid": {k: list(np.linspace(0.1, 1, 20).tolist()) for k in
                                                   ("spacing_m", "depth_m", "calibration_depth_m", "d_f_m",
                                                    "detector_size_m", "read_noise_e")}},
     r"64,000,000 points \(limit 10,000\): about .* h of one worker .*--max-points 64000000"),
]


@pytest.mark.parametrize(("raw", "message"), REFUSED)
def test_bad_study_files_get_one_clear_line(raw, message):
    with pytest.raises(ConfigError, match=message) as err:
        load_study(raw)
    assert "\n" not in str(err.value)


def test_workers_below_one_are_refused(tmp_path):
    spec = load_study(TINY, quick=True)
    for workers in (0, -1):
        with pytest.raises(ConfigError, match="--workers must be an integer >= 1"):
            run_quick(spec, tmp_path, workers=workers)
    assert not (tmp_path / "results.zarr").exists()


def test_cli_refuses_bad_workers_and_big_grids_in_one_line(tmp_path):
    from typer.testing import CliRunner

    from mincam_sim.cli import app

    study = tmp_path / "big.toml"
    study.write_text('[study]\nexperiment = "spacing"\n[grid]\n'
                     + "".join(f"{k} = [{', '.join(str(0.1 + 0.01 * i) for i in range(40))}]\n"
                               for k in ("spacing_m", "depth_m", "calibration_depth_m", "d_f_m", "read_noise_e")))
    runner = CliRunner()
    r = runner.invoke(app, ["study", "run", str(study), "--workers", "-1"])
    assert r.exit_code == 2 and "--workers must be an integer >= 1" in r.output
    r = runner.invoke(app, ["study", "run", str(study), "--out", str(tmp_path / "o")])
    assert r.exit_code == 2 and "102,400,000 points" in r.output and "--max-points" in r.output
    assert not (tmp_path / "o").exists()


def test_every_registry_experiment_render_and_design_can_be_a_study():
    from mincam_sim.experiments import REGISTRY
    from mincam_sim.studies import study_target, target_names

    assert set(REGISTRY) <= set(target_names())
    for name in target_names():
        if name == "render":
            continue
        target = study_target({"name": name})
        assert target.metrics and target.parameters
    assert {"spacing_m", "toy_size_m", "bit_depth", "frames_per_toy"} <= set(study_target({"name": "tracking"})
                                                                             .parameters)
    spec = load_study(ROOT / "scenes" / "studies" / "render_d_f.toml")
    assert list(spec.dims) == ["mincam.d_f_m"] and spec.fixed["run.samples_per_texel"] == 64


def test_shipped_study_files_load():
    paths = sorted((ROOT / "scenes" / "studies").glob("*.toml"))
    assert {p.stem for p in paths} >= {"spacing", "tracking_spacing_toy", "tracking_spacing_albedo", "render_d_f"}
    for path in paths:
        for quick in (False, True):
            assert load_study(path, quick=quick).points


# the two tracking studies take ~40 s each even with --quick: they run with the slow tests
@pytest.mark.parametrize("name", [pytest.param("tracking_spacing_toy", marks=pytest.mark.slow),
                                  pytest.param("tracking_spacing_albedo", marks=pytest.mark.slow), "render_d_f"])
def test_shipped_studies_run_with_quick_from_the_command_line(tmp_path, name):
    from typer.testing import CliRunner

    from mincam_sim.cli import app

    out = tmp_path / name
    r = CliRunner().invoke(app, ["--quiet", "study", "run", str(ROOT / "scenes" / "studies" / f"{name}.toml"),
                                 "--quick", "--workers", "1", "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert (out / "study.png").is_file() and "standard error up to" in r.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["points_computed"] == summary["points_total"] >= 2
    import xarray as xr

    ds = xr.open_zarr(out / "results.zarr").load()
    spec = load_study(ROOT / "scenes" / "studies" / f"{name}.toml", quick=True)
    for metric in spec.metrics:
        assert np.any(np.isfinite(ds[metric].values)) and np.any(np.isfinite(ds[f"{metric}_stderr"].values))


def test_a_design_point_reads_the_design_result(monkeypatch):
    """The design target's plumbing (a real design point takes minutes: not run here): the point calls
    ``run_design`` with its dpi and seed and returns the baseline's and the design's error rates."""
    import mincam_sim.design as design_mod
    from mincam_sim.studies import study_target

    seen = {}

    def fake(task, out_dir, quick=False, seed=0, dpi=600.0, show_progress=False, baselines=True):
        seen.update(task=task, quick=quick, seed=seed, dpi=dpi, baselines=baselines)
        return {"baseline": {"avg_error_pct": 3.0, "max_error_pct": 7.0},
                "designed": {"avg_error_pct": 1.5, "max_error_pct": None}}

    monkeypatch.setattr(design_mod, "run_design", fake)
    target = study_target({"name": "design"})
    out = target.point({"dpi": 1200.0}, 5, True)
    assert seen == {"task": "tracking", "quick": True, "seed": 5, "dpi": 1200.0, "baselines": False}
    assert out["baseline_avg_error_pct"] == 3.0 and out["designed_avg_error_pct"] == 1.5
    assert np.isnan(out["designed_max_error_pct"]) and set(out) == set(target.metrics)


def test_a_point_the_experiment_refuses_is_named_and_the_others_kept(tmp_path, monkeypatch):
    spec = load_study(TINY, quick=True)
    original = runner_mod.compute_point

    def refusing(ref, params, *args):
        if params["spacing_m"] == 0.05 and params["depth_m"] == 0.8:
            raise ValueError("only 6 of 8 calibration squares lie inside every mixel's field of view")
        return original(ref, params, *args)

    monkeypatch.setattr(runner_mod, "compute_point", refusing)
    with pytest.raises(ConfigError, match=r"point \(spacing_m=0.05, depth_m=0.8\): only 6 of 8"):
        run_quick(spec, tmp_path, workers=1)
    assert len(list((tmp_path / "points").iterdir())) == 3


@pytest.mark.parametrize("experiment, grid, said", [
    ("spacing", {"bit_depth": [12, 0]}, r"point \(bit_depth=0\): Setup.bit_depth must be 2 to 32"),
    ("tracking", {"spacing_m": [0.03, -1.0]}, r"point \(spacing_m=-1\): Setup.spacing_m must be >= 0"),
    ("intrusion", {"depth_m": [0.5, 3.0]}, r"point \(depth_m=3\): .*depth_m .* at or above the table's light"),
    ("design", {"dpi": [600.0, 0.0]}, r"point \(dpi=0\): TrackingTask.dpi must be a number from 50 to 4800"),
])
def test_every_point_is_checked_before_the_first_runs(tmp_path, experiment, grid, said):
    """A bad value late in a grid stopped the study after the points before it had run (a design point takes
    minutes): every point is now checked first, and nothing is computed or written."""
    spec = load_study({"study": {"experiment": experiment, "replicates": 1}, "grid": grid}, base_dir=tmp_path)
    with pytest.raises(ConfigError, match=f"{said}.*change the grid \\(nothing was computed\\)"):
        run_quick(spec, tmp_path / "out")
    assert not (tmp_path / "out").exists()
