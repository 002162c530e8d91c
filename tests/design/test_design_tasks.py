"""Design tasks as data: the registry, the counting and depth task records, their frames and labels, the
decoders (fit, rounding), the optimiser's loss gradient for the new decoders against finite differences, bit-for-bit
repeatable training, the Zarr training dataset, a tiny end-to-end run and the CLI's errors. The ``--quick`` runs
are ``slow``."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from mincam_sim.design import scene_tasks as st
from mincam_sim.design.counting import COUNTING
from mincam_sim.design.depth import DEPTH
from mincam_sim.design.tasks import TASK_NAMES, get_task
from mincam_sim.errors import ConfigError

TINY = dict(frames_per_depth=12, strata=4, iterations=4, suite_frames=8)


def _needs_jit():
    from mincam_sim.render import backend

    if not backend.is_jit():
        pytest.skip("needs a vectorised Mitsuba variant (llvm_ad_mono or cuda_ad_mono)")


def _camera(spec: st.TaskSpec, **sizes):
    from mincam_sim.design import scene_design as sd
    from mincam_sim.design.scene_run import make_sizes

    s = make_sizes(spec, True, 0, **{**TINY, **sizes})
    frames = st.draw_frames(spec.train, s.frames_per_depth * len(spec.train.depths_m), [0, 11])
    return s, frames, sd.build_problem(spec, s, frames, st.traced_rows(s, frames, 0))


def test_registry_holds_every_task_as_data():
    assert TASK_NAMES == ("tracking", "counting", "depth")
    for name in TASK_NAMES:
        t = get_task(name)
        assert t.name == name and t.suite and t.metric and isinstance(t.lower_is_better, bool)
    assert get_task("counting").spec is COUNTING and not get_task("counting").lower_is_better
    assert get_task("depth").spec is DEPTH and get_task("depth").lower_is_better
    assert get_task("tracking").spec is None and "ramps" in get_task("tracking").hand
    with pytest.raises(ValueError, match="unknown design task 'juggling'.*tracking, counting, depth"):
        get_task("juggling")


def test_task_records_stay_within_the_brief():
    """Counting: 0-3 objects, <= 8 mixels (4); depth: 0.3-1.0 m with 4 mixels, error in % of the depth."""
    assert set(COUNTING.train.counts) == {0, 1, 2, 3} and COUNTING.metric == "accuracy_pct"
    assert min(DEPTH.train.depths_m) == pytest.approx(0.3) and max(DEPTH.train.depths_m) == pytest.approx(1.0)
    assert DEPTH.metric == "abs_rel_error_pct" and DEPTH.output == "exp" and DEPTH.target == "log_depth"
    held = {d for c in DEPTH.suite for d in c.scenes.depths_m}
    assert not held & set(DEPTH.train.depths_m), "the depth suite must hold out the training planes"


@pytest.mark.parametrize("field, value, match", [
    ("counts", (0, 12), "Distribution.counts"),
    ("contrast_range", (0.5, 2.0), "Distribution.contrast_range"),
    ("shape", "blob", "Distribution.shape"),
    ("depths_m", (0.05,), "Distribution.depths_m"),
])
def test_bad_distribution_names_the_field(field, value, match):
    with pytest.raises(ConfigError, match=match):
        replace(COUNTING.train, **{field: value})


def test_bad_sizes_name_the_field():
    from mincam_sim.design.scene_run import make_sizes

    with pytest.raises(ConfigError, match="Sizes.iterations"):
        make_sizes(DEPTH, True, 0, iterations=0)
    with pytest.raises(ConfigError, match="unknown field.*object_size_range_m"):
        make_sizes(DEPTH, True, 0, object_size_range_m=(0.01, 0.02))


@pytest.mark.parametrize("overrides, fields", [
    ({"frames_per_depth": 20000}, "frames_per_depth and dpi"),  # 160,000 training frames x 2,209 dots: 10.5 GiB
    ({"suite_frames": 10000, "dpi": 4800}, "suite_frames and dpi"),  # 10,000 x 142,884 dots: 42.6 GiB
    ({"frames_per_depth": 12000, "strata": 64}, "frames_per_depth and strata"),  # 49 M samples a plane: 9.2 GiB
])
def test_sizes_that_do_not_fit_in_memory_are_refused_before_anything_runs(overrides, fields):
    from mincam_sim.design.scene_run import make_sizes

    with pytest.raises(ConfigError, match=f"^Sizes.{fields}.* GiB .at most 8 GiB.: lower them"):
        make_sizes(DEPTH, True, 0, **overrides)
    make_sizes(DEPTH, True, 0, dpi=4800)  # the largest printer: 768 frames x 142,884 dots, 3.3 GiB, runs
    make_sizes(COUNTING, False, 0, strata=64)  # 512 frames x 3 objects x 4,096 samples: 1.2 GiB


def test_frames_carry_their_labels_and_repeat():
    _needs_jit()
    a = st.draw_frames(COUNTING.train, 60, [3, 11])
    b = st.draw_frames(COUNTING.train, 60, [3, 11])
    assert np.array_equal(a.count, b.count) and np.array_equal(a.depth_m, b.depth_m)
    assert [len(f) for f in a.planes.frame_atoms] == a.count.tolist()
    assert set(a.count.tolist()) <= {0, 1, 2, 3} and len(set(a.count.tolist())) > 1
    assert np.array_equal(a.targets("count")[:, 0], a.count)
    d = st.draw_frames(DEPTH.train, 16, [0, 11])
    assert np.allclose(np.exp(d.targets("log_depth")[:, 0]), d.depth_m)
    assert set(np.round(d.depth_m, 4)) == set(DEPTH.train.depths_m)


def test_decoder_recovers_a_polynomial_and_rounds_counts():
    rng = np.random.default_rng(0)
    dn = rng.uniform(0, 3000, (200, 4))
    target = (1.0 + 2.0 * dn[:, 0] / 4095 - 0.5 * (dn[:, 1] / 4095) ** 2)[:, None]
    dec = st.fit_decoder(COUNTING, dn, target)
    assert np.allclose(dec.regress(dn), target[:, 0], atol=1e-9)
    exact = st.SceneDecoder("raw", 1, np.array([[0.0, 1.0, 0.0, 0.0, 0.0]]), "count", 3)
    counts = exact(np.array([[0.4, 0, 0, 0], [1.6, 0, 0, 0], [9.0, 0, 0, 0], [-2.0, 0, 0, 0]]) * 4095)
    assert counts.tolist() == [0.0, 2.0, 3.0, 0.0]


def test_scores_follow_the_metric():
    frames = st.Frames(None, np.array([0, 1, 2, 3]), np.array([0.5, 0.5, 1.0, 1.0]))
    assert st.metric(COUNTING, st.score(COUNTING, np.array([0.0, 1.0, 1.0, 3.0]), frames)) == pytest.approx(75.0)
    err = st.score(DEPTH, np.array([0.55, 0.45, np.nan, 3.0]), frames)
    assert err == pytest.approx([0.1, 0.1, 1.0, 1.0])


@pytest.mark.parametrize("spec", [COUNTING, DEPTH], ids=["counting", "depth"])
def test_loss_gradient_of_the_new_decoders_matches_finite_differences(spec):
    """Reverse-mode AD of the optimiser's loss (float32) against central differences of its float64 twin,
    the noise draw and the fitted decoder held fixed: relative error <= 1 % (observed ~1e-5 counting, ~1e-3
    depth: float32 rounding)."""
    _needs_jit()
    from mincam_sim.design import scene_design as sd

    sizes, _, camera = _camera(spec)
    r = sd.check_loss_gradient(camera.problem, sd.initial_logits(spec.starts[0], sizes), seed=0)
    assert r["n_checked"] == 6 and np.linalg.norm(r["fd"]) > 0
    assert r["rel_error"] <= 0.01, r


def test_training_is_repeatable_bit_for_bit():
    _needs_jit()
    from mincam_sim.design import scene_design as sd

    runs = []
    for _ in range(2):
        sizes, frames, camera = _camera(DEPTH)
        runs.append(sd.train(DEPTH, sizes, camera, frames))
    a, b = runs
    assert a.start == b.start
    for k in a.histories:
        assert np.array_equal(a.histories[k], b.histories[k])
    for ma, mb in zip(a.printer_masks, b.printer_masks, strict=True):
        assert np.array_equal(ma.transmission, mb.transmission)


def test_training_data_is_a_zarr_dataset(tmp_path):
    import zarr

    from mincam_sim.design.scene_design import write_dataset

    frames = st.Frames(None, np.array([0, 2, 3]), np.array([0.5, 0.5, 0.53]))
    dn = np.arange(12.0).reshape(3, 4)
    write_dataset(tmp_path / "t.zarr", {"designed": dn}, frames, {"task": "counting"})
    write_dataset(tmp_path / "t.zarr", {"designed": dn + 1}, frames, {"task": "counting"})  # replaces
    g = zarr.open_group(str(tmp_path / "t.zarr"), mode="r")
    assert np.array_equal(g["measurements_dn/designed"][:], dn + 1)
    assert g["count"][:].tolist() == [0, 2, 3] and np.allclose(g["depth_m"][:], frames.depth_m)
    assert g.attrs["task"] == "counting" and g.attrs["units"]["depth_m"] == "m"


def test_tiny_counting_run_writes_the_summary(tmp_path):
    """End to end with tiny sizes (seconds): every baseline in ``suite.summary``, the outputs on disk, and a
    second run of another set-up in the same folder refused."""
    _needs_jit()
    from mincam_sim.design.run import run_design
    from mincam_sim.errors import StaleResultError

    out = tmp_path / "c"
    r = run_design("counting", out, quick=True, **TINY)
    sm = r["suite"]["summary"]
    assert sm["metric"] == "accuracy_pct" and sm["lower_is_better"] is False
    assert set(sm["baselines"]) == {"hand", "random", "pca", "ideal_trained"}
    assert sm["n_cases"] == len(COUNTING.suite)
    means = {k: np.mean([c["accuracy_pct"][k] for c in r["suite"]["cases"]]) for k in sm["baselines"]}
    assert means == pytest.approx(sm["baselines"])
    assert r["gradient_check"]["max_rel_error"] <= 0.01
    stored = json.loads((out / "design.json").read_text())["suite"]["summary"]
    assert stored["designed"] == pytest.approx(sm["designed"]) and stored["baselines"] == pytest.approx(sm["baselines"])
    for name in ("suite.png", "decoder.json", "mask_designed_left.png", "training.zarr"):
        assert (out / name).exists()
    with pytest.raises(StaleResultError):
        run_design("counting", out, quick=True, **{**TINY, "iterations": 5})


def test_cli_refuses_tracking_options_for_other_tasks(tmp_path):
    from typer.testing import CliRunner

    from mincam_sim.cli import app

    r = CliRunner().invoke(app, ["design", "depth", "--object-size-cm", "1,2", "--out", str(tmp_path / "d")])
    assert r.exit_code == 2
    assert "--object-size-cm only apply to the tracking task" in r.output and "Traceback" not in r.output
    r = CliRunner().invoke(app, ["design", "counting", "--film-t-min", "0.95", "--out", str(tmp_path / "e")])
    assert r.exit_code == 2 and "--film-t-min and film_t_max (default) must satisfy" in r.output


@pytest.mark.slow
@pytest.mark.parametrize("task", ["counting", "depth"])
def test_cli_design_quick(tmp_path, task):
    """The ``--quick`` run (about 2-3 minutes on 2 cores): summary with every baseline, the figure, the dataset."""
    _needs_jit()
    from typer.testing import CliRunner

    from mincam_sim.cli import app

    out = tmp_path / task
    r = CliRunner().invoke(app, ["--quiet", "design", task, "--quick", "--out", str(out)])
    assert r.exit_code == 0, r.output
    d = json.loads((out / "design.json").read_text())
    assert set(d["suite"]["summary"]["baselines"]) >= {"random", "pca", "ideal_trained"}
    assert "suite mean" in r.output and (out / "suite.png").stat().st_size > 0 and (out / "training.zarr").is_dir()


def test_frame_rows_equal_the_per_atom_design_matrix():
    """Binning the samples per frame (textured planes) gives each frame's sum of its atoms' design-matrix rows
    times their radiance, with the same samples."""
    _needs_jit()
    from mincam_sim.design.tracking import paper_masks
    from mincam_sim.render.gradients import differentiable as dz

    sizes = st.Sizes.quick(strata=4)
    frames = st.draw_frames(replace(COUNTING.train, depths_m=(0.5,)), 6, [1, 2])
    rows = st.traced_rows(sizes, frames, 0)
    cam = sizes.mincam(paper_masks(8))
    sc = frames.planes.atoms[0]
    per_atom = dz.design_matrix(dz.mixel_samples(cam, 1, sc, strata=4, seed=0), sizes.dot_shape())
    expect = np.zeros_like(rows[1])
    for f, atoms in enumerate(frames.planes.frame_atoms):
        for _, ai, radiance in atoms:
            expect[f] += radiance * per_atom[ai]
    assert np.allclose(rows[1], expect, rtol=1e-12, atol=1e-15) and rows[1].sum() > 0


def test_texture_fraction_mixes_textured_planes_in():
    _needs_jit()
    f = st.draw_frames(replace(DEPTH.train, texture_fraction=0.5), 40, [0, 11])
    textured = [all(f.patch[di][ai] for di, ai, _ in atoms) and len(atoms) > 20 for atoms in f.planes.frame_atoms]
    assert 5 < sum(textured) < 35
    assert all(c == 0 for c, t in zip(f.count, textured, strict=True) if t)


def test_the_tasks_idea_of_the_suite_is_the_suite():
    """``tracking`` checks sizes against the suite's case count and depths without importing it (no cycle)."""
    from mincam_sim.design import tracking
    from mincam_sim.design.suite import SUITE

    assert tracking.SUITE_CASES == len(SUITE)
    assert tracking.SUITE_MOST_DEPTHS == max(len(case.depths_m) for case in SUITE)
