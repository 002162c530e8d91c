"""Audit of the pure-numpy downstream (estimators, metrics, calibration, sensor, read-out) and of the experiments'
bookkeeping on inputs the other tests do not use. Each test pins one finding of the audit (see its docstring).

Monte Carlo tolerances: Z = 5 standard errors of the compared statistic, fixed seeds.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from mincam_sim.errors import ConfigError
from mincam_sim.estimation.calibration import (
    Calibration1D,
    Calibration2D,
    ExtrapolationWarning,
    NonMonotonicCalibrationWarning,
)
from mincam_sim.estimation.estimators import (
    AliasingError,
    aliased_speed,
    centroid,
    check_below_nyquist,
    intrusion_position,
    nyquist_speed,
    scene_frequency,
    speed_from_signal,
    track_3,
    track_4,
)
from mincam_sim.estimation.metrics import error_rates, speed_error_rates
from mincam_sim.model.forward_model import ideal_measurement, speed_signal
from mincam_sim.model.readout import Readout
from mincam_sim.model.sensor import SensorModel

Z = 5.0


# ----------------------------------------------------------------------------------------- Eq. 4 / 7 / 8 ratios
def _ramp_images(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Normalised texel-centre coordinates x (left -> right) and y (bottom -> top) of an (H, W) grid."""
    h, w = shape
    x = (np.arange(w) + 0.5) / w
    y = ((np.arange(h) + 0.5) / h)[::-1]
    return np.broadcast_to(x, shape), np.broadcast_to(y[:, None], shape)


# values below 1e-200 become 0: products of subnormal numbers with the masks lose their relative precision
# (gradual underflow), which no rounding bound of a physical irradiance covers
_CHANGE = st.floats(-1.0, 1.0, allow_nan=False).map(lambda v: 0.0 if abs(v) < 1e-200 else v)


@settings(deadline=None, max_examples=40)
@given(
    disturbance=hnp.arrays(np.float64, (12, 17), elements=_CHANGE),
    sign=st.sampled_from([1.0, -1.0]),
)
def test_eq4_eq7_eq8_against_the_forward_model_for_signed_changes(disturbance, sign):
    """Eq. 4 / 7 / 8 applied to Eq. 1 measurements give the centroid of a *signed* change (a bright object and
    its shadow), for changes of either overall sign; NaN exactly where the total change is ~0."""
    d = sign * disturbance
    x, y = _ramp_images(d.shape)
    masks = {"x": x, "1-x": 1 - x, "y": y, "1-y": 1 - y, "1": np.ones_like(x)}
    p = {k: float(ideal_measurement(m, d)) for k, m in masks.items()}
    total = d.sum()
    expected = centroid(d, (x, y))
    got4 = track_4(np.array([[p["x"], p["1-x"], p["y"], p["1-y"]]]))[0]
    got3 = track_3(np.array([[p["x"], p["y"], p["1"]]]))[0]
    if abs(total) < 1e-9 * np.abs(d).sum() or not np.abs(d).sum():
        assert np.all(np.isnan(got4)) and np.all(np.isnan(got3))
    else:
        scale = np.abs(d).sum() / abs(total)  # cancellation amplifies rounding
        np.testing.assert_allclose(got4, expected, rtol=0, atol=1e-11 * scale)
        np.testing.assert_allclose(got3, expected, rtol=0, atol=1e-11 * scale)


def test_ratio_nan_rules_and_edge_inputs():
    """NaN where the denominator is within ``min_total`` (inclusive) or not finite; sign invariance; empty and
    one-frame inputs keep their shapes."""
    a = np.array([3.0, -3.0, 1.0, 1.0, np.nan, np.inf, 0.0, 2.0])
    b = np.array([1.0, -1.0, -0.5, -1.0, 1.0, 1.0, 0.0, -1.0])
    out = intrusion_position(a, b, min_total=0.5)
    np.testing.assert_array_equal(out[:2], [0.75, 0.75])  # a dark object gives the same centroid
    assert np.all(np.isnan(out[2:7]))  # |a + b| = 0.5 <= 0.5, 0, NaN, inf, 0
    assert out[7] == 2.0  # a mixed-sign change may leave [0, 1]: not clipped
    assert track_4(np.zeros((0, 4))).shape == (0, 2)
    one = track_4([[1.0, 1.0, 0.2, -0.2]], min_total=0.1)
    assert one.shape == (1, 2) and one[0, 0] == 0.5 and np.isnan(one[0, 1])  # only the y pair cancels
    with pytest.raises(ValueError, match="n_frames, 4"):
        track_4(np.zeros((3, 3)))


# ------------------------------------------------------------------------------------- Eq. 9-14 and Nyquist
def test_eq10_eq14_closed_forms():
    """Eq. 10: omega_d = omega_df d_f / d (halves when the depth doubles); Eq. 14: v = omega_p / omega_d."""
    omega_df = 2 * np.pi / 0.2e-3
    np.testing.assert_allclose(scene_frequency(omega_df, 2e-3, [0.5, 1.0]), [2 * np.pi / 0.05, np.pi / 0.05])
    with pytest.raises(ValueError):
        scene_frequency(omega_df, 2e-3, 0.0)


@pytest.mark.parametrize("fraction", [0.3, 0.7, 0.93])
def test_speed_below_nyquist_is_recovered(fraction):
    """Eq. 13 sampled at f_s, speed a fraction of the Nyquist limit pi f_s / omega_d: Eq. 14 returns it (sub-bin
    refinement: off-bin frequencies to 1e-6)."""
    rate, omega_d = 200.0, 40.0
    v = fraction * nyquist_speed(rate, omega_d)
    t = np.arange(300) / rate
    got = speed_from_signal(speed_signal(t, v, omega_d, 1.0, 0.4, 0.3), rate, omega_d, max_speed_m_s=v)
    assert got == pytest.approx(v, rel=1e-6)


@pytest.mark.parametrize("fraction", [1.25, 1.6, 2.7])
def test_speed_above_nyquist_is_refused_not_aliased_silently(fraction):
    """Finding: a speed above pi f_s / omega_d came back as a wrong (aliased) speed with no word. The samples
    cannot reveal it; ``max_speed_m_s`` now makes the estimator refuse, and what it would report without it is
    exactly :func:`aliased_speed` (documented)."""
    rate, omega_d = 200.0, 40.0
    v_n = nyquist_speed(rate, omega_d)
    assert v_n == pytest.approx(np.pi * rate / omega_d)
    v = fraction * v_n
    t = np.arange(300) / rate
    signal = speed_signal(t, v, omega_d, 1.0, 0.4, 0.3)
    with pytest.raises(AliasingError, match="Nyquist"):
        speed_from_signal(signal, rate, omega_d, max_speed_m_s=v)
    assert speed_from_signal(signal, rate, omega_d) == pytest.approx(aliased_speed(v, rate, omega_d), rel=1e-5)
    assert aliased_speed(v, rate, omega_d) < v_n
    with pytest.raises(AliasingError):
        check_below_nyquist([0.5 * v_n, v_n], rate, omega_d)  # the limit itself is not measurable


def test_speed_experiment_refuses_unmeasurable_speeds_before_rendering():
    """The speed experiment checks its speeds against the Nyquist limits before rendering anything."""
    from mincam_sim.experiments import Setup
    from mincam_sim.experiments.speed import SpeedParams, check_nyquist

    setup = Setup(quick=True)
    limits = check_nyquist(setup, SpeedParams())
    assert limits["video_nyquist_speed_px_s"] > 30 * 10 and limits["vehicle_nyquist_speed_m_s"] > 16
    fastest_ok = int(np.floor(limits["video_nyquist_speed_px_s"] / 30.0 - 1e-9))
    check_nyquist(setup, SpeedParams(video_shifts_px=(fastest_ok,)))
    with pytest.raises(ConfigError, match="video_shifts_px"):
        check_nyquist(setup, SpeedParams(video_shifts_px=(2, fastest_ok + 1)))
    with pytest.raises(ConfigError, match="vehicle_speeds_m_s"):
        check_nyquist(setup, SpeedParams(vehicle_rate_hz=1000.0))  # 16 m/s needs > 1067 Hz


# ----------------------------------------------------------------------------------------------- metrics
def test_error_rates_count_missed_predictions_honestly():
    """Finding: a frame with a ground truth but a NaN prediction and a frame without a ground truth were both
    lumped into ``n_missing``. Now: ``n_missing`` = truth but no prediction (and ``missing_pct``), rows without a
    truth apart (``n_without_truth``); errors are % of the calibrated range (paper)."""
    pred = np.array([0.10, np.nan, 0.20, 0.05, np.nan])
    true = np.array([0.10, 0.10, 0.25, np.nan, np.nan])
    r = error_rates(pred, true, 0.5)
    assert (r["n"], r["n_missing"], r["n_without_truth"]) == (2, 1, 2)
    assert r["missing_pct"] == pytest.approx(100 / 3)
    assert r["max_error_pct"] == pytest.approx(10.0) and r["avg_error_pct"] == pytest.approx(5.0)
    r2 = error_rates([[0.1, np.nan], [0.0, 0.0]], [[0.1, 0.1], [0.03, 0.04]], 0.5)  # 2D: Euclidean, % of range
    assert (r2["n"], r2["n_missing"], r2["max_error_pct"]) == (1, 1, pytest.approx(10.0))
    with pytest.raises(ValueError, match="all predicted NaN"):
        error_rates([np.nan, np.nan], [0.1, 0.2], 0.5)
    with pytest.raises(ValueError, match="empty"):
        error_rates(np.zeros(0), np.zeros(0), 0.5)
    s = speed_error_rates([np.nan, 1.1], [1.0, 1.0])
    assert s["n_missing"] == 1 and s["max_error_pct"] == pytest.approx(10.0)


def test_experiment_result_without_any_scored_frame():
    """A run in which no frame can be scored reports None rates and n = 0 (it used to stop with a ValueError)."""
    from mincam_sim.experiments import ExperimentResult

    res = ExperimentResult.from_rates("x", {"max_error_pct": None, "avg_error_pct": None, "n": 0, "n_missing": 3},
                                      None, {})
    d = res.as_dict()
    assert d["max_error_pct"] is None and d["n"] == 0 and d["n_missing"] == 3


# ------------------------------------------------------------------------------------------- calibration
def test_non_monotonic_1d_fit_warns():
    """Finding: a cubic that folds over its fitted range (two observations -> one position) was accepted
    silently. Now it warns and ``monotonic`` is False; a monotonic fit stays silent."""
    x = np.linspace(0.0, 1.0, 21)
    with pytest.warns(NonMonotonicCalibrationWarning):
        folded = Calibration1D.fit(x, 0.1 * np.sin(3 * np.pi * x))
    assert not folded.monotonic
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        good = Calibration1D.fit(x, -0.25 + 0.5 * x + 0.05 * (x - 0.5) ** 3)
    assert good.monotonic
    decreasing = Calibration1D.fit(x, 0.25 - 0.5 * x)
    assert decreasing.monotonic


def test_folded_2d_fit_warns_and_jacobian_matches_finite_differences():
    """2D: the calibration's Jacobian determinant (checked against central differences) keeps its sign for a
    smooth one-to-one map, and changes sign when a few calibration points are folded to the far side (as
    squares out of one mixel's view are, see test_experiments)."""
    g = np.linspace(0.05, 0.95, 7)
    obs = np.array([(u, v) for u in g for v in g])
    true = np.column_stack([0.5 * (obs[:, 0] - 0.5) + 0.02 * obs[:, 1] ** 2, 0.5 * (obs[:, 1] - 0.5)])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cal = Calibration2D.fit(obs, true)
    assert cal.monotonic
    h = 1e-6
    pts = obs[(obs[:, 0] > 0.1) & (obs[:, 0] < 0.9) & (obs[:, 1] > 0.1) & (obs[:, 1] < 0.9)]  # inside the hull
    jx = (cal.apply(pts + [h, 0]) - cal.apply(pts - [h, 0])) / (2 * h)
    jy = (cal.apply(pts + [0, h]) - cal.apply(pts - [0, h])) / (2 * h)
    np.testing.assert_allclose(cal.jacobian_determinant(pts), jx[:, 0] * jy[:, 1] - jy[:, 0] * jx[:, 1], rtol=1e-6)
    folded_obs = obs.copy()
    edge = np.flatnonzero(np.isclose(obs[:, 0], 0.05) & (np.abs(obs[:, 1] - 0.5) < 0.2))
    folded_obs[edge, 0] = 0.98  # the left edge read out as the right edge
    with pytest.warns(NonMonotonicCalibrationWarning):
        assert not Calibration2D.fit(folded_obs, true).monotonic


def test_outside_range_is_the_extrapolation_mask_without_warning():
    x = np.linspace(0.2, 0.8, 12)
    cal = Calibration1D.fit(x, x - 0.5)
    probe = np.array([0.1, 0.5, np.nan, 0.81])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mask = cal.outside_range(probe)
    np.testing.assert_array_equal(mask, [True, False, False, True])
    with pytest.warns(ExtrapolationWarning):
        _, flagged = cal.apply(probe, return_extrapolated=True)
    np.testing.assert_array_equal(flagged, mask)


# ------------------------------------------------------------------------------------------------- sensor
@pytest.mark.parametrize("where", ["dark", "full_well", "adc_top"])
def test_aggregate_equals_per_pixel_at_the_clipping_limits(where):
    """Finding: ``method="aggregate"`` (the default) clipped the *sum* of the 48 x 48 pixels, not each pixel.
    In the dark each pixel's read noise (~1 DN) is clipped at 0 DN, so the per-pixel mean is ~0.40 DN; the
    aggregate gave 0.02 DN (20 standard errors off). Values near the clipping limits are now simulated per pixel
    and the two methods agree there as well."""
    if where == "adc_top":
        sensor = SensorModel.paper_prototype(gain_e_per_dn=2.0)  # the ADC tops out (8190 e-) below full well
        electrons = 8190.0
    else:
        sensor = SensorModel.paper_prototype()
        electrons = 0.0 if where == "dark" else sensor.full_well_e
    irradiance = max(0.0, electrons - sensor.dark_current_e_per_s * sensor.exposure_s) / sensor.electrons_per_irradiance
    n = 400
    a = sensor.measure(np.full(n, irradiance), np.random.default_rng(11), method="aggregate")
    b = sensor.measure(np.full(n, irradiance), np.random.default_rng(12), method="per_pixel")
    se = np.sqrt(a.var(ddof=1) / n + b.var(ddof=1) / n)
    assert abs(a.mean() - b.mean()) <= Z * se + 1e-12
    assert a.std(ddof=1) / b.std(ddof=1) == pytest.approx(1.0, rel=Z / np.sqrt(n - 1))
    if where == "dark":
        assert a.mean() > 0.3  # the clipped read noise, far above expected() = 0.02 DN


def test_edge_values_keep_the_other_values_draws_and_same_seed_same_numbers():
    """The per-pixel draws for values near the clipping limits come from a child stream: the other values are
    the numbers they were, and the same seed gives the same numbers."""
    sensor = SensorModel.paper_prototype()
    bright = 800.0 / sensor.electrons_per_irradiance
    first = sensor.measure(np.array([bright, bright]), np.random.default_rng(3))
    mixed = sensor.measure(np.array([bright, 0.0]), np.random.default_rng(3))
    assert mixed[0] == first[0]
    again = sensor.measure(np.array([bright, 0.0]), np.random.default_rng(3))
    np.testing.assert_array_equal(mixed, again)


def test_averaging_2304_pixels_reduces_the_noise_by_48_against_independent_seeds():
    """48 x 48 pixels averaged: the mixel value's spread over independent seeds is the single pixel's / 48 at
    the same per-pixel irradiance, and equals the reported ``expected_std_dn`` (within Z standard errors of a
    standard deviation, 1/sqrt(2(n-1)))."""
    proto = SensorModel.paper_prototype()
    single = SensorModel(detector_area_m2=proto.pixel_area_m2)
    irradiance = 3000.0 / proto.electrons_per_irradiance  # 3000 e- per pixel, far from both limits
    n = 600
    one = np.array([single.measure(irradiance, np.random.default_rng(s)) for s in range(n)])
    avg = np.array([proto.measure(irradiance, np.random.default_rng(10_000 + s)) for s in range(n)])
    rel = Z * np.sqrt(2.0) / np.sqrt(2.0 * (n - 1))
    assert one.std(ddof=1) / avg.std(ddof=1) == pytest.approx(48.0, rel=rel)
    assert avg.std(ddof=1) == pytest.approx(float(proto.expected_std_dn(irradiance)), rel=Z / np.sqrt(2 * (n - 1)))
    assert single.expected_std_dn(irradiance, False) / proto.expected_std_dn(irradiance, False) == pytest.approx(48.0)
    assert np.all(one == np.rint(one)) and one.max() <= 4095  # 12 bits, integers for one pixel
    assert np.shape(proto.measure(irradiance, np.random.default_rng(0))) == ()  # a scalar in, a scalar out


def test_readout_mc_sigma_uses_the_sensor_slope_not_a_clipped_difference():
    """Finding: ``Readout.change_sigma_dn`` converted the Monte Carlo standard error to DN with
    ``expected(1 W/m^2) - expected(0)``, which saturates when the exposure is set for irradiances below
    ~1 W/m^2 (e.g. a dim screen): the Monte Carlo term shrank by the saturation factor. It now uses the slope
    ``dn_per_irradiance``."""
    sensor = SensorModel.paper_prototype().auto_exposed(0.01, 0.7)  # 0.01 W/m^2 fills 70 %
    x1, x2 = 0.002, 0.006
    slope = (sensor.expected(x2) - sensor.expected(x1)) / (x2 - x1)
    assert sensor.dn_per_irradiance == pytest.approx(slope, rel=1e-12)
    assert sensor.expected(1.0) == sensor.max_dn  # the old conversion's saturation
    ro = Readout(np.zeros((1, 1)), np.zeros(1), 0.0, sensor)
    frame, bg, mc = np.array([[0.005]]), np.array([0.004]), np.array([[1e-4]])
    with_mc = ro.change_sigma_dn(frame, bg, mc)
    without = ro.change_sigma_dn(frame, bg)
    assert np.sqrt(with_mc**2 - without**2)[0, 0] == pytest.approx(slope * 1e-4, rel=1e-9)


# ---------------------------------------------------------------------------------------------- experiments
def test_calibration_squares_out_of_a_mixels_view_are_left_out():
    """Finding: the tracking calibration swept squares to the rim of the 50 cm disc; the mixels 3.3 cm off
    centre have a +-26.25 cm field at 0.5 m, so the square at x = -25 cm is out of the right-hand (1 - x) mixel's
    view and Eq. 7 read x_obs = 1.0 for it (and 0.0 at +25 cm): a folded cubic (rms residual 3.0 cm in x).
    Squares in a mixel's penumbra fold the same way (depth 0.6 m, spacing 5 cm: x rms 1.5 cm). Squares are now
    kept only if every detector point of every mixel sees them whole through the mask:
    |centre - mixel| + side/2 <= d (mask - detector) / (2 d_f)."""
    from mincam_sim.experiments import Setup
    from mincam_sim.experiments.layouts import intrusion_mincam, tracking_mincam
    from mincam_sim.experiments.screen_calibration import screen_sweep_1d, screen_sweep_2d, seen_by_every_mixel

    setup = Setup(quick=True)
    sweep = screen_sweep_2d(setup, 15, 0.03)
    for spacing in (0.0, 0.033, 0.06):
        s = setup.with_(spacing_m=spacing)
        keep = seen_by_every_mixel(tracking_mincam(s), s, sweep)
        limit = s.depth_m * (s.mask_size_m - s.detector_size_m) / (2 * s.d_f_m) - spacing - 0.015
        np.testing.assert_array_equal(keep, np.all(np.abs(sweep.positions_m) <= limit + 1e-12, axis=1))
    dropped = screen_sweep_2d(setup, 9, 0.03).positions_m[~seen_by_every_mixel(tracking_mincam(setup), setup,
                                                                                screen_sweep_2d(setup, 9, 0.03))]
    assert len(dropped) == 4 and np.allclose(np.abs(dropped).max(axis=1), 0.25)  # the quick grid's rim
    pair = intrusion_mincam(setup, -0.1378, 0.03)
    line = screen_sweep_1d(setup, -0.1378, 51, 0.03)
    kept = line.positions_m[seen_by_every_mixel(pair, setup, line), 1]
    half_span = setup.depth_m * 0.475 - setup.spacing_m / 2 - 0.015  # 20.6 cm: the 1 cm steps keep +-20 cm
    assert kept.min() >= -half_span - 1e-12 and kept.max() <= half_span + 1e-12 and len(kept) == 41


def test_experiment_streams_are_independent():
    """Finding: calibration noise, the table's printed texture and the read-out noise came from one stream, so
    the number of calibration squares changed the *scene*. Each purpose now has its own stream."""
    from mincam_sim.experiments import REGISTRY, Setup

    exp = REGISTRY["tracking"]
    a = exp.streams(Setup(seed=4), ("calibration", "scene", "readout"))
    b = exp.streams(Setup(seed=4), ("calibration", "scene", "readout"))
    a["calibration"].normal(size=1000)  # more calibration draws ...
    assert a["scene"].random() == b["scene"].random()  # ... same scene
    assert exp.streams(Setup(seed=5), ("scene",))["scene"].random() != b["scene"].random()


@settings(deadline=None, max_examples=30)
@given(
    a=hnp.arrays(np.float64, (6, 9), elements=st.floats(0.0, 1.0)),
    b=hnp.arrays(np.float64, (6, 9), elements=st.floats(0.0, 1.0)),
)
def test_two_objects_entering_at_once_give_the_weighted_mean_of_their_centroids(a, b):
    """Paper Sec. 4.1: two intruders at once are located between them, at the mean of their centroids weighted
    by their total changes (Eq. 4 on Eq. 1 measurements of the sum)."""
    if a.sum() < 1e-6 or b.sum() < 1e-6:
        return
    x, _ = _ramp_images(a.shape)
    both = a + b
    dp = [float(ideal_measurement(m, both)) for m in (x, 1 - x)]
    expected = (centroid(a, x) * a.sum() + centroid(b, x) * b.sum()) / both.sum()
    assert intrusion_position(dp[0], dp[1]) == pytest.approx(expected, abs=1e-12)


def test_read_out_edge_inputs():
    """An empty frame set reads out (background and threshold only); all-dark input and NaN irradiances are
    refused with a message that says so (they failed with numpy's 'zero-size array' or an exposure error)."""
    from mincam_sim.model.readout import read_out

    sensor = SensorModel.paper_prototype()
    empty = read_out(np.zeros((0, 2)), np.ones(2), sensor, np.random.default_rng(0))
    assert empty.frames_dn.shape == (0, 2) and empty.change_dn.shape == (0, 2) and empty.threshold_dn > 0
    with pytest.raises(ValueError, match="every irradiance is 0"):
        read_out(np.zeros((3, 2)), np.zeros(2), sensor, np.random.default_rng(0))
    with pytest.raises(ValueError, match="NaN"):
        read_out(np.array([[np.nan, 1.0]]), np.ones(2), sensor, np.random.default_rng(0))


def test_design_training_converts_irradiance_to_dn_with_the_sensor_slope():
    """Finding: the mask optimiser's linear read-out model used ``expected(1 W/m^2) - expected(0)`` as its DN per
    W/m^2; its training readings peak near 0.013 W/m^2, so 1 W/m^2 saturates and the training signals were 55x
    too small against the (correctly computed) sensor noise. It now uses the sensor's slope, which maps the
    training peak onto the exposure fill."""
    import dataclasses

    from mincam_sim.design import optimise as op
    from mincam_sim.design import tracking as tr

    task = dataclasses.replace(tr.TrackingTask.quick(), frames_per_depth=8, strata=2)
    problem = op.build_problem(task)
    film = task.film()
    peak = max(float((a * film.t_max).sum(axis=1).max()) for a in problem.matrices)
    s = tr.sensor().auto_exposed(peak, tr.EXPOSURE_FILL)
    assert problem.dn_per_w_m2 * peak == pytest.approx(float(s.expected(peak) - s.expected(0.0)), rel=1e-9)
    assert problem.dn_per_w_m2 * peak == pytest.approx(tr.EXPOSURE_FILL * s.max_dn, rel=1e-3)
