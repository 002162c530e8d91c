"""The held-out suite of a design report: its baseline is the layout the package builds, its target is the
centroid of the change (two objects), a background changes the exposure and the noise, and the training set
follows the task's distribution."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mincam_sim.design import suite as su
from mincam_sim.design import tracking as tr
from mincam_sim.errors import ConfigError
from mincam_sim.model.optics import cross_layout
from mincam_sim.scene.display import coverage


def _needs_jit():
    from mincam_sim.render import backend

    if not backend.is_jit():
        pytest.skip("needs a vectorised Mitsuba variant (llvm_ad_mono or cuda_ad_mono)")


def test_baseline_is_the_layout_the_package_builds():
    """Every suite baseline mixel carries, at its position, the ramp that optics.cross_layout puts there (as
    printed on the task's film); the mirrored layout is a separate, labelled row."""
    from mincam_sim.design.run import BASELINE, MIRRORED, suite_entries

    task = tr.TrackingTask.quick()
    film = task.film()
    entries = {e.label: e for e in suite_entries(task, tr.paper_masks(), decoder=None)}
    built = {tuple(np.round(m.pose.position_m, 9)): m for m in cross_layout(tr.SPACING_M, mask_size_m=tr.MASK_SIZE_M)}
    for mixel in entries[BASELINE].cam:
        ref = built[tuple(np.round(mixel.pose.position_m, 9))]
        np.testing.assert_array_equal(mixel.mask.transmission, film.print(ref.mask).transmission)
        assert mixel.d_f_m == ref.d_f_m
    # the x ramp (bright on the right) sits on the right mixel; the old layout had it on the left
    right = next(m for m in entries[BASELINE].cam if m.pose.position_m[0] > 0)
    assert right.mask.transmission[:, -1].mean() > right.mask.transmission[:, 0].mean()
    old_right = next(m for m in entries[MIRRORED].cam if m.pose.position_m[0] > 0)
    assert old_right.mask.transmission[:, -1].mean() < old_right.mask.transmission[:, 0].mean()


def test_target_is_the_centroid_of_the_change_of_two_objects():
    """Two squares of different sizes and radiances: the target is their radiance-times-area centroid, not the
    midpoint; on a grey plane the weights are the radiance *changes*."""
    screen = su.suite_screen(0.5, 200)
    tw = screen.texel_size_m[0]
    c1, c2 = np.array([-20, 10]) * tw, np.array([30, -15]) * tw  # texel-aligned: exact areas
    a1, a2 = 10 * tw, 6 * tw
    for bg_level in (0.0, 0.3):
        bg = np.full(screen.shape, bg_level)
        frame = bg.copy()
        for (cx, cy), a, radiance in ((c1, a1, 1.0), (c2, a2, 0.6)):
            cov = coverage(screen, cx - a / 2, cx + a / 2, cy - a / 2, cy + a / 2)
            frame = frame * (1 - cov) + radiance * cov
        w1, w2 = (1.0 - bg_level) * a1**2, (0.6 - bg_level) * a2**2
        expected = tr.to_field((w1 * c1 + w2 * c2) / (w1 + w2), 0.5)
        np.testing.assert_allclose(su.change_centroid_q(screen, frame, bg), expected, atol=1e-12)
        assert np.linalg.norm(expected - tr.to_field((c1 + c2) / 2, 0.5)) > 0.01  # not the midpoint


def test_suite_two_object_frames_have_two_objects_and_their_centroid():
    case = next(c for c in su.SUITE if c.name == "two_objects")
    blocks = su.draw_case(case, 4, 96, seed=0)
    for b in blocks:
        for frame, q in zip(b.frames, b.q, strict=True):
            lit = frame > 0
            # two separate blobs
            from scipy.ndimage import label

            _, n = label(lit)
            assert n == 2
            np.testing.assert_allclose(q, su.change_centroid_q(b.screen, frame, b.background))


def test_tilted_plane_target_is_the_direction_of_the_object():
    """On the tilted plane a small square's target is the direction of its centre (field units)."""
    screen = su.suite_screen(0.5, 400, tilt_deg=su.TILT_DEG)
    q = np.array([[0.2, -0.1]])
    xy = su._screen_point_of_q(screen, q)[0]
    a = 4 * screen.texel_size_m[0]
    frame = coverage(screen, xy[0] - a / 2, xy[0] + a / 2, xy[1] - a / 2, xy[1] + a / 2)
    np.testing.assert_allclose(su.change_centroid_q(screen, frame, np.zeros(screen.shape)), q[0], atol=2e-3)
    assert abs(screen.pose.axes()[2][0]) == pytest.approx(np.sin(np.deg2rad(su.TILT_DEG)))


def test_background_shortens_the_exposure_and_adds_its_noise():
    """The same change read over a grey background: the exposure that puts the brightest reading at 0.7 of the
    range is shorter, the change's noise (in irradiance) is larger, and the measured spread of read_change
    matches change_sigma_dn (500 draws: within 4 standard errors of the standard deviation), its mean the
    change."""
    change = np.array([2e-3, 1e-3, 1.5e-3, 1.2e-3])
    bg = np.full(4, 6e-3)
    rows = {}
    for name, b in (("black", np.zeros(4)), ("grey", bg)):
        s = tr.sensor().auto_exposed(float((change + b).max()), tr.EXPOSURE_FILL)
        rng = np.random.default_rng(3)
        dn = np.array([su.read_change((change + b)[None], b, s, rng)[0] for _ in range(500)])
        sigma = su.change_sigma_dn(s, change + b, b)
        sd = dn.std(axis=0, ddof=1)
        np.testing.assert_array_less(np.abs(sd - sigma), 4 * sigma / np.sqrt(2 * 499))
        if name == "grey":  # (on black the background readings sit at the floor, clipped: ~0.1 DN of bias)
            np.testing.assert_allclose(dn.mean(axis=0), s.dn_per_irradiance * change,
                                       atol=4 * sigma.max() / np.sqrt(500))
        rows[name] = (s.exposure_s, sigma / s.dn_per_irradiance)
    assert rows["grey"][0] < 0.5 * rows["black"][0]
    assert np.all(rows["grey"][1] > 1.5 * rows["black"][1])


def test_suite_reports_exposure_and_snr_per_case():
    """evaluate_suite on a tiny grid: the grey-background case is read at a shorter exposure and a lower change
    SNR than the same objects on black, and every row holds the baseline ratio."""
    _needs_jit()
    from mincam_sim.design.run import BASELINE, suite_entries

    task = replace(tr.TrackingTask.quick(), calibration_grid=7)
    cases = tuple(c for c in su.SUITE if c.name in ("reference", "grey_background"))
    entries = [e for e in suite_entries(task, tr.paper_masks(), decoder=None) if e.label == BASELINE]
    r = su.evaluate_suite(entries, task, n_frames=4, texels=48, samples_per_texel=4, cases=cases, baseline=BASELINE)
    rows = {c["name"]: c["rows"][BASELINE] for c in r["cases"]}
    assert rows["grey_background"]["exposure_s"] < 0.5 * rows["reference"]["exposure_s"]
    assert rows["grey_background"]["median_change_snr"] < 0.5 * rows["reference"]["median_change_snr"]
    for c in r["cases"]:
        assert c["ratio_to_baseline"][BASELINE] == pytest.approx(1.0)
        assert c["rows"][BASELINE]["n"] == 4 and np.isfinite(c["rows"][BASELINE]["avg_error_pct"])
    assert "grey_background" in su.table(r)


def test_training_set_covers_the_task_distribution():
    """Sizes span 1-15 cm (squares and bars), some frames have two objects whose target is the centroid of
    their change, and some frames have a background."""
    _needs_jit()
    from mincam_sim.design.optimise import training_set

    task = tr.TrackingTask.quick()
    frames, targets = training_set(task)
    sizes = np.concatenate([np.maximum(a.sizes_m, a.heights_m) for a in frames.atoms])
    assert sizes.min() < 0.013 and sizes.max() > 0.12
    assert any(np.any(a.sizes_m > 3 * a.heights_m) or np.any(a.heights_m > 3 * a.sizes_m) for a in frames.atoms)
    two = [f for f, objs in enumerate(frames.frame_atoms) if len(objs) == 2]
    assert 0.2 < len(two) / len(targets) < 0.4
    for f in two[:20]:
        pts, w = [], []
        for di, ai, change in frames.frame_atoms[f]:
            a = frames.atoms[di]
            pts.append(tr.to_field(a.centers_m[ai], a.depth_m))
            w.append(change * a.sizes_m[ai] * a.heights_m[ai])
        np.testing.assert_allclose(targets[f], np.average(pts, axis=0, weights=w), atol=1e-12)
    assert 0.4 < np.mean(frames.background > 0) < 0.8


def test_task_fields_are_checked_and_reach_the_run():
    from mincam_sim.design.run import make_task

    task = make_task(True, 0, object_size_range_m=[0.02, 0.1], depth_range_m=[0.4, 0.9], spacing_m=0.05,
                     d_f_m=0.003, background_radiances=[0.0, 0.2], film_t_max=0.8)
    assert task.train_depths_m[0] == 0.4 and task.train_depths_m[-1] == pytest.approx(0.9)
    assert task.film().t_max == 0.8
    cam = task.mincam(task.baseline_masks())
    assert max(m.pose.position_m[0] for m in cam) == pytest.approx(0.05) and cam[0].d_f_m == 0.003
    with pytest.raises(ConfigError, match="object_size_range_m"):
        make_task(True, 0, object_size_range_m=(0.1, 0.01))
    with pytest.raises(ConfigError, match="unknown design task field"):
        make_task(True, 0, sizes=(1, 2))
    with pytest.raises(ConfigError, match="background_radiances"):
        make_task(True, 0, background_radiances=(-1.0,))


def test_cli_design_options_reach_the_task(tmp_path):
    """A bad option or config field is one line naming it (exit code 2) before anything runs."""
    from typer.testing import CliRunner

    from mincam_sim.cli import app

    r = CliRunner().invoke(app, ["design", "tracking", "--object-size-cm", "15,1", "--out", str(tmp_path / "a")])
    assert r.exit_code == 2 and "object_size_range_m" in r.output
    r = CliRunner().invoke(app, ["design", "tracking", "--depth-range-m", "near", "--out", str(tmp_path / "b")])
    assert r.exit_code == 2 and "--depth-range-m" in r.output
    cfg = tmp_path / "d.toml"
    cfg.write_text("[tracking]\nspacing = 0.05\n")
    r = CliRunner().invoke(app, ["design", "tracking", "--config", str(cfg), "--out", str(tmp_path / "c")])
    assert r.exit_code == 2 and "spacing" in r.output and "spacing_m" in r.output


def test_noiseless_fit_with_capped_loss_is_finite_repeatable_and_bounded():
    """The design loop on the broad distribution: decoder fitted on the noiseless read-out, scored on noisy
    ones with each frame's error capped: finite, same seed same numbers, RMS <= the cap; the NumPy decoder
    fitted without noise reproduces the targets of the noiseless read-out at least as well as one fitted on
    noisy draws, and training_rms scores candidates on fixed draws."""
    _needs_jit()
    from mincam_sim.design import parameterization as par
    from mincam_sim.design.optimise import build_problem, fit_decoder, initial_logits, training_rms
    from mincam_sim.design.optimiser import optimise_masks

    task = replace(tr.TrackingTask.quick(), train_depths_m=(0.4, 0.6), frames_per_depth=48, strata=5, grid=5)
    problem = build_problem(task)
    assert problem.fit_noiseless and problem.error_cap == 0.1
    start = initial_logits(task, swap_x=True)
    a = optimise_masks(problem, start, iterations=8, learning_rate=0.1, seed=1)
    b = optimise_masks(problem, start, iterations=8, learning_rate=0.1, seed=1)
    np.testing.assert_array_equal(a.loss_history, b.loss_history)
    assert np.all(np.isfinite(a.loss_history)) and a.loss_history.max() <= 0.1 + 1e-6
    dots = task.dot_shape()
    film = task.film()
    t = [film.print(par.printable_mask(par.grid_values(m, dots[0]), dots, tr.MASK_SIZE_M, "r")).transmission.ravel()
         for m in task.baseline_masks()]
    clean, noisy = fit_decoder(problem, t, task, draws=0), fit_decoder(problem, t, task, draws=4)
    dn = problem.dn_per_w_m2 * np.array([m @ x for m, x in zip(problem.matrices, t, strict=True)]).T

    def rms(dec):
        return np.sqrt(np.nanmean(np.sum((dec(dn) - problem.targets) ** 2, axis=1)))

    assert rms(clean) <= rms(noisy)
    assert training_rms(problem, t, clean, task) == training_rms(problem, t, clean, task) <= 0.1
