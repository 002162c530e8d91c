"""The baselines the field uses beside a designed mincam: random and PCA masks through the design's film, and
masks trained through the idealised model, whose linear model is built from DotProduct response maps."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mincam_sim.design import baselines as bl
from mincam_sim.design import tracking as tr


def _small_task(**kw) -> tr.TrackingTask:
    return replace(tr.TrackingTask.quick(), train_depths_m=(0.35, 0.7), frames_per_depth=12, **kw)


def _printed_ok(task: tr.TrackingTask, masks) -> None:
    film = task.film()
    assert len(masks) == 4
    for m in masks:
        assert m.shape == task.dot_shape() and m.interpolation == "nearest"
        assert 0.0 <= m.transmission.min() and m.transmission.max() <= 1.0  # printer input (grey values)
        t = film.print(m).transmission
        assert film.t_min - 1e-12 <= t.min() and t.max() <= film.t_max + 1e-12  # printable range


def test_dot_maps_are_the_dot_product_maps_of_any_dot_mask():
    """The linear model on the dots is exact: for a random nearest-neighbour dot mask, ``T[dot(t)] * W_open[t]``
    equals the DotProduct maps of that mask on the dot screen, for every mixel."""
    from mincam_sim.render.solvers import DotProduct

    task = tr.TrackingTask.quick()
    n_dots = int(np.prod(task.dot_shape()))
    weights, dot_of_texel = bl.dot_maps(task, 0.5)
    assert weights.shape == (4, n_dots) and np.all(weights > 0)
    assert sorted(dot_of_texel.tolist()) == list(range(n_dots))  # one texel per dot
    rng = np.random.default_rng(3)
    t = rng.uniform(0.02, 0.9, (4, n_dots))
    cam = task.mincam([bl._dot_mask(task, t[k], f"r{k}") for k in range(4)])
    maps = DotProduct().maps(cam, bl.dot_screen(task, 0.5)).weights_sr.reshape(4, -1)
    np.testing.assert_allclose(maps, (t * weights)[:, dot_of_texel], rtol=1e-12, atol=0)
    # the bare model: the open aperture's weights sum to its view factor (pi F), and the dots' share is uniform
    np.testing.assert_allclose(weights.sum(axis=1), bl_view_factor(task), rtol=1e-9)
    np.testing.assert_allclose(weights, weights.mean(), rtol=1e-9)


def bl_view_factor(task: tr.TrackingTask) -> float:
    from mincam_sim.render.solvers.dot_product import aperture_view_factor_pi

    return aperture_view_factor_pi(task.mincam(tr.paper_masks(8))[0])


def test_ideal_problem_is_built_from_dot_product_maps():
    """``build_problem(model="ideal")``: each frame's row is its image on the dots times the DotProduct weights
    (not the traced physics, which differs: parallax, vignetting, bodies); the background rows are the open
    maps; a one-square frame's ideal reading is the DotProduct measurement of that square on the dot screen."""
    from mincam_sim.design.optimise import build_problem, training_set
    from mincam_sim.render.simulation import Simulation
    from mincam_sim.scene.display import coverage

    task = _small_task()
    ideal = build_problem(task, model="ideal")
    assert ideal.model == "ideal"
    frames, targets = training_set(task)
    np.testing.assert_array_equal(ideal.targets, targets)
    weights = [bl.dot_maps(task, d)[0] for d in task.train_depths_m]
    for k in range(4):
        np.testing.assert_allclose(ideal.background_rows[k], np.stack([w[k] for w in weights]), rtol=1e-12)
    # a frame with a single object: its reading through random printed dots equals the DotProduct solver's
    f = next(i for i, objs in enumerate(frames.frame_atoms) if len(objs) == 1)
    di, ai, change = frames.frame_atoms[f][0]
    scenes = frames.atoms[di]
    screen = bl.dot_screen(task, scenes.depth_m)
    (cx, cy), w, h = scenes.centers_m[ai], scenes.sizes_m[ai], scenes.heights_m[ai]
    frame = change * coverage(screen, cx - w / 2, cx + w / 2, cy - h / 2, cy + h / 2)
    from mincam_sim.render.solvers import DotProduct

    rng = np.random.default_rng(5)
    t = rng.uniform(0.02, 0.9, (4, int(np.prod(task.dot_shape()))))
    cam = task.mincam([bl._dot_mask(task, t[k], f"r{k}") for k in range(4)])
    measured = Simulation(cam, screen=screen).measure(frame[None], solver=DotProduct()).irradiance_w_m2[0]
    np.testing.assert_allclose([ideal.matrices[k][f] @ t[k] for k in range(4)], measured, rtol=1e-10)


def test_random_masks_are_printable_and_repeatable():
    task = tr.TrackingTask.quick()
    a, b = bl.random_masks(task), bl.random_masks(task)
    _printed_ok(task, a)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.transmission, y.transmission)
    other = bl.random_masks(replace(task, seed=1))
    assert not np.array_equal(a[0].transmission, other[0].transmission)
    assert len({m.transmission.tobytes() for m in a}) == 4  # four different masks
    assert all(m.transmission.std() > 0.2 for m in a)  # spread over the grey range, not a flat grey


def test_pca_components_are_orthonormal_signed_and_printable():
    """Before mapping: orthonormal, each orthogonal to the mean (centred data), ordered by variance, signed so
    that the largest entry is positive; after: grey 0.5 + 0.5 p / max|p| on the 256 levels, within the film."""
    from mincam_sim.design.optimise import training_set

    task = _small_task()
    frames, _ = training_set(task)
    _, _, images = bl.ideal_rows(task, frames)
    assert images.shape == (len(frames.frame_atoms), int(np.prod(task.dot_shape())))
    comps = bl.principal_components(images)
    np.testing.assert_allclose(comps @ comps.T, np.eye(4), atol=1e-10)
    centred = images - images.mean(axis=0)
    var = np.sum((centred @ comps.T) ** 2, axis=0)
    assert np.all(np.diff(var) <= 1e-9 * var[0])  # leading components first
    for c in comps:
        assert c[np.argmax(np.abs(c))] > 0
    masks = bl.pca_masks(task, images)
    _printed_ok(task, masks)
    for m, c in zip(masks, comps, strict=True):
        grey = m.transmission.ravel()
        np.testing.assert_allclose(grey, 0.5 + 0.5 * c / np.abs(c).max(), atol=0.5 / 255 + 1e-12)
        assert grey.max() == 1.0


def test_suite_summary_has_every_baseline_and_its_direction():
    """``suite.summary``: metric, lower_is_better, the designed mean and the four baselines' means over the
    cases, and the count of cases the designed masks beat each in."""
    from mincam_sim.design.run import BASELINE, DESIGNED, IDEAL_TRAINED, PCA, RANDOM, suite_summary

    def row(v):
        return {"avg_error_pct": v}

    cases = [{"rows": {DESIGNED: row(1.0), BASELINE: row(2.0), RANDOM: row(9.0), PCA: row(4.0),
                       IDEAL_TRAINED: row(0.5)}},
             {"rows": {DESIGNED: row(3.0), BASELINE: row(1.0), RANDOM: row(7.0), PCA: row(5.0),
                       IDEAL_TRAINED: row(4.0)}}]
    s = suite_summary({"cases": cases})
    assert s["metric"] == "avg_error_pct" and s["lower_is_better"] is True
    assert s["designed"] == pytest.approx(2.0)
    assert s["baselines"] == pytest.approx({"hand": 1.5, "random": 8.0, "pca": 4.5, "ideal_trained": 2.25})
    assert s["n_cases_designed_better"] == {"hand": 1, "random": 2, "pca": 2, "ideal_trained": 1}
    assert s["n_cases"] == 2


def test_suite_entries_carry_the_baselines():
    from mincam_sim.design.run import BASELINE, DESIGNED, PCA, RANDOM, suite_entries

    task = tr.TrackingTask.quick()
    film = task.film()
    rnd = [film.print(m) for m in bl.random_masks(task)]
    entries = {e.label: e for e in suite_entries(task, tr.paper_masks(), None, baselines={RANDOM: (rnd, "dec")})}
    assert {BASELINE, DESIGNED, RANDOM} <= set(entries) and PCA not in entries
    assert entries[RANDOM].decoder == "dec"
    for mixel, mask in zip(entries[RANDOM].cam, rnd, strict=True):
        np.testing.assert_array_equal(mixel.mask.transmission, mask.transmission)


def test_field_baselines_train_through_the_ideal_model_and_refit_on_the_physics():
    """``ideal_trained`` runs the design's optimiser on the DotProduct linear model; every baseline's decoder is
    the one ``fit_decoder`` gives on the physical model for its printed masks; the same seed gives the same
    masks bit for bit."""
    from types import SimpleNamespace

    from mincam_sim.render import backend

    if not backend.is_jit():
        pytest.skip("needs a vectorised Mitsuba variant (llvm_ad_mono or cuda_ad_mono)")
    from mincam_sim.design.optimise import build_problem, fit_decoder
    from mincam_sim.design.run import IDEAL_TRAINED, PCA, RANDOM, field_baselines

    task = _small_task(strata=4, grid=6, iterations=4)
    physical = build_problem(task)
    assert physical.model == "physical"
    a = field_baselines(task, SimpleNamespace(problem=physical))
    b = field_baselines(task, SimpleNamespace(problem=physical))
    assert a.ideal.problem.model == "ideal"
    assert set(a.printer_masks) == {RANDOM, PCA, IDEAL_TRAINED}
    film = task.film()
    for label, masks in a.printer_masks.items():
        _printed_ok(task, masks)
        for x, y in zip(masks, b.printer_masks[label], strict=True):
            np.testing.assert_array_equal(x.transmission, y.transmission)
        again = fit_decoder(physical, [film.print(m).transmission.ravel() for m in masks], task, 0)
        np.testing.assert_array_equal(a.decoders[label].coefficients, again.coefficients)
    for m, kept in zip(a.printer_masks[IDEAL_TRAINED], a.ideal.printer_masks, strict=True):
        assert m is kept


def test_a_design_without_baselines_has_its_own_identity():
    from mincam_sim.design.run import design_identity

    task = tr.TrackingTask.quick()
    with_baselines = design_identity("tracking", task, True, 0)
    assert with_baselines == design_identity("tracking", task, True, 0, baselines=True)
    assert with_baselines != design_identity("tracking", task, True, 0, baselines=False)
    assert "field_baselines" not in str(with_baselines)  # the default's identity is the task's alone
