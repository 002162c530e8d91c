"""Tests of the estimators (mincam_sim.estimation.estimators) on ideal synthetic data with known answers."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from mincam_sim.estimation.estimators import (
    centroid,
    change_statistic,
    detect_change,
    dominant_frequency,
    frequency_error_std,
    intrusion_position,
    noise_threshold,
    scene_frequency,
    spectrum,
    speed_from_signal,
    speed_track,
    track_3,
    track_4,
    trajectory_from_speeds,
    window_weights,
)
from mincam_sim.model.forward_model import ideal_measurement, speed_signal

non_negative = st.floats(min_value=0.0, max_value=1e3, allow_nan=False, allow_infinity=False)


# ------------------------------------------------------------------------------------------- intrusion / tracking
@settings(deadline=None, max_examples=60)
@given(
    disturbance=hnp.arrays(
        np.float64, hnp.array_shapes(min_dims=2, max_dims=2, min_side=2, max_side=40), elements=non_negative
    )
)
def test_intrusion_position_equals_centroid(disturbance):
    """Ideal masks x and 1 - x on a grid: Eq. 4 is the centroid of the change, frame by frame."""
    assume(np.all(disturbance.sum(axis=1) > 1e-6))
    x = np.linspace(0.0, 1.0, disturbance.shape[1])[None, :]
    dP_x = ideal_measurement(x, disturbance[:, None, :])
    dP_1mx = ideal_measurement(1.0 - x, disturbance[:, None, :])
    np.testing.assert_allclose(intrusion_position(dP_x, dP_1mx), centroid(disturbance, x[0]), rtol=0, atol=1e-9)
    observed = intrusion_position(dP_x, dP_1mx)
    assert np.all((observed >= -1e-12) & (observed <= 1 + 1e-12))


@settings(deadline=None, max_examples=60)
@given(
    disturbance=hnp.arrays(
        np.float64, hnp.array_shapes(min_dims=3, max_dims=3, min_side=2, max_side=16), elements=non_negative
    )
)
def test_track_4_and_track_3_equal_centroid(disturbance):
    """Masks x, 1-x, y, 1-y (Eq. 5-7) and x, y, 1 (Eq. 8) recover the 2D centroid of each frame exactly."""
    assume(np.all(disturbance.sum(axis=(1, 2)) > 1e-6))
    _, ny, nx = disturbance.shape
    xs, ys = np.meshgrid(np.linspace(0, 1, nx), np.linspace(0, 1, ny))

    def project(mask):
        return ideal_measurement(mask, disturbance)

    truth = centroid(disturbance, (xs, ys))
    dP4 = np.stack([project(xs), project(1 - xs), project(ys), project(1 - ys)], axis=1)
    dP3 = np.stack([project(xs), project(ys), project(np.ones_like(xs))], axis=1)
    np.testing.assert_allclose(track_4(dP4), truth, rtol=0, atol=1e-9)
    np.testing.assert_allclose(track_3(dP3), truth, rtol=0, atol=1e-9)


def test_ratios_are_nan_without_change():
    assert np.isnan(intrusion_position(0.0, 0.0))
    np.testing.assert_array_equal(
        np.isnan(intrusion_position([1.0, 0.5, 1e-3], [1.0, 0.5, 0.0], 0.01)), [False, False, True]
    )
    assert np.all(np.isnan(track_4(np.zeros((3, 4)))))
    assert np.all(np.isnan(track_3(np.zeros((2, 3)))))
    assert np.isnan(centroid(np.zeros(5), np.arange(5.0)))
    with pytest.raises(ValueError, match=r"\(n_frames, 4\)"):
        track_4(np.zeros((3, 3)))


def test_centroid_with_weights_and_batches():
    x = np.array([0.0, 1.0, 3.0])
    d = np.array([[1.0, 1.0, 1.0], [0.0, 0.0, 2.0]])
    np.testing.assert_allclose(centroid(d, x), [4 / 3, 3.0])
    np.testing.assert_allclose(centroid(d, x, cell_weights=[2.0, 1.0, 1.0]), [1.0, 3.0])


def test_detect_change_and_norms():
    background = np.array([10.0, 10.0])
    frames = np.array([[10.0, 10.0], [12.0, 11.0], [12.0, 8.0], [9.0, 10.5]])
    np.testing.assert_allclose(change_statistic(frames, background, "sum"), [0, 3, 0, 0.5])
    np.testing.assert_allclose(change_statistic(frames, background, "l1"), [0, 3, 4, 1.5])
    np.testing.assert_allclose(change_statistic(frames, background, "l2"), [0, np.sqrt(5), np.sqrt(8), np.sqrt(1.25)])
    np.testing.assert_allclose(change_statistic(frames, background, "max"), [0, 2, 2, 1])
    np.testing.assert_array_equal(detect_change(frames, background, 1.0), [False, True, False, False])
    np.testing.assert_array_equal(detect_change(frames, background, 1.0, norm="l1"), [False, True, True, True])
    with pytest.raises(ValueError, match="threshold"):
        detect_change(frames, background, -1.0)


def test_noise_threshold_separates_noise_from_intruder():
    rng = np.random.default_rng(0)
    quiet = 100.0 + rng.normal(0, 1.0, size=(500, 2))
    background, threshold = noise_threshold(quiet, n_sigma=6.0)
    np.testing.assert_allclose(background, 100.0, atol=0.2)
    live = 100.0 + rng.normal(0, 1.0, size=(200, 2))
    live[100:] += 30.0
    detected = detect_change(live, background, threshold)
    assert not detected[:100].any() and detected[100:].all()


# ------------------------------------------------------------------------------------------- frequency / speed
def _leakage_bias_bound(omega0: float, n_samples: int, window: str) -> float:
    """First-order bound [rad/sample] on the noiseless error of the windowed-periodogram peak.

    For x_n = A cos(w0 n + phi) the (centred) windowed transform is Y(w) = A/2 [e^{i phi} W(w - w0) +
    e^{-i phi} W(w + w0)] - c W(w), the last term from the removal of the weighted mean c, |c| <= A |W(w0)| / S0.
    Linearising d|Y|^2/dw = 0 around w0 (W'(0) = 0 for a centred symmetric window) gives
    |dw| <= (|W'(2 w0)| + 2 |W(w0)| |W'(w0)| / S0) / S2 with S0 = sum w_n, S2 = sum n^2 w_n.
    """
    w = window_weights(window, n_samples)
    n = np.arange(n_samples) - (n_samples - 1) / 2

    def transform(omega, power):
        return abs(np.sum((-1j * n) ** power * w * np.exp(-1j * omega * n)))

    s0, s2 = w.sum(), np.sum(n**2 * w)
    return (transform(2 * omega0, 1) + 2 * transform(omega0, 0) * transform(omega0, 1) / s0) / s2


@settings(deadline=None, max_examples=40)
@given(
    n_samples=st.integers(min_value=64, max_value=1024),
    cycles_fraction=st.floats(min_value=0.0, max_value=1.0),
    phase=st.floats(min_value=0.0, max_value=2 * np.pi),
    offset=st.floats(min_value=-100.0, max_value=100.0),
    window=st.sampled_from(["hann", "rect", "blackman"]),
)
def test_noiseless_frequency_within_leakage_bound(n_samples, cycles_fraction, phase, offset, window):
    """Noiseless sinusoid 4 bins or more from DC and Nyquist: error <= 2 x the first-order leakage bound
    (factor 2 for the neglected second-order terms) + 1e-9 rad/sample of root-finding tolerance."""
    fs = 50.0
    f0 = (4 + cycles_fraction * (n_samples / 2 - 8)) * fs / n_samples
    t = np.arange(n_samples) / fs
    signal = offset + 2.0 * np.cos(2 * np.pi * f0 * t + phase)
    omega = dominant_frequency(signal, fs, window=window)
    bound = 2 * _leakage_bias_bound(2 * np.pi * f0 / fs, n_samples, window) + 1e-9
    assert abs(omega / fs - 2 * np.pi * f0 / fs) <= bound


@settings(deadline=None, max_examples=40)
@given(
    n_samples=st.integers(min_value=128, max_value=1024),
    cycles_fraction=st.floats(min_value=0.0, max_value=1.0),
    phase=st.floats(min_value=0.0, max_value=2 * np.pi),
    noise_to_amplitude=st.floats(min_value=0.0, max_value=0.5),
    seed=st.integers(min_value=0, max_value=2**32 - 1),
)
def test_noisy_frequency_within_stated_bound(n_samples, cycles_fraction, phase, noise_to_amplitude, seed):
    """White Gaussian noise sigma <= A/2 (per-sample SNR A^2/(2 sigma^2) >= 2, N SNR >= 256: far above the
    threshold SNR of periodogram estimators, so the small-error theory applies). Bound: 2 x leakage bound +
    5.5 x the theoretical standard deviation of :func:`frequency_error_std` (two-sided normal tail 4e-8 per
    example) + 1e-9 rad/sample."""
    fs = 200.0
    f0 = (4 + cycles_fraction * (n_samples / 2 - 8)) * fs / n_samples
    rng = np.random.default_rng(seed)
    t = np.arange(n_samples) / fs
    amplitude = 1.0
    signal = 5.0 + amplitude * np.cos(2 * np.pi * f0 * t + phase)
    signal += rng.normal(0.0, noise_to_amplitude * amplitude, n_samples)
    omega = dominant_frequency(signal, fs)
    sigma = frequency_error_std(amplitude, noise_to_amplitude * amplitude, n_samples, fs)
    bound = fs * (2 * _leakage_bias_bound(2 * np.pi * f0 / fs, n_samples, "hann") + 1e-9) + 5.5 * sigma
    assert abs(omega - 2 * np.pi * f0) <= bound


@pytest.mark.parametrize("window", ["hann", "rect"])
def test_frequency_spread_matches_theory(window):
    """Empirical std over 400 noisy records = frequency_error_std (rect: the Cramer-Rao bound) within the
    sampling error of a standard deviation, 5 / sqrt(2 x 399) = 18 % (bias is < 1 % of sigma here)."""
    n_samples, fs, f0, noise = 256, 100.0, 17.3, 0.3
    rng = np.random.default_rng(11)
    t = np.arange(n_samples) / fs
    estimates = np.array(
        [
            dominant_frequency(
                np.cos(2 * np.pi * f0 * t + rng.uniform(0, 2 * np.pi)) + rng.normal(0, noise, n_samples),
                fs,
                window=window,
            )
            for _ in range(400)
        ]
    )
    theory = frequency_error_std(1.0, noise, n_samples, fs, window)
    assert estimates.std(ddof=1) == pytest.approx(theory, rel=5 / np.sqrt(2 * 399))
    assert abs(estimates.mean() - 2 * np.pi * f0) <= 5 * theory / np.sqrt(400)
    if window == "rect":
        crlb = np.sqrt(12 / ((1 / (2 * noise**2)) * n_samples * (n_samples**2 - 1))) * fs
        assert theory == pytest.approx(crlb, rel=1e-12)


def test_spectrum_shape_and_errors():
    fs, f0 = 100.0, 12.5
    t = np.arange(200) / fs
    result = spectrum(3 + 0.5 * np.sin(2 * np.pi * f0 * t), fs, zero_pad_factor=4)
    assert result.freqs_hz.shape == result.magnitude.shape == (401,)
    leakage_hz = 2 * _leakage_bias_bound(2 * np.pi * f0 / fs, 200, "hann") * fs / (2 * np.pi)
    assert abs(result.peak_hz - f0) <= leakage_hz
    assert result.peak_omega_rad_s == pytest.approx(2 * np.pi * result.peak_hz)
    assert result.peak_magnitude == pytest.approx(0.5, rel=1e-3)
    with pytest.raises(ValueError, match="no spectral peak"):
        spectrum(np.ones(64), fs)
    with pytest.raises(ValueError, match="NaN"):
        spectrum(np.r_[np.ones(63), np.nan], fs)
    with pytest.raises(ValueError, match="window"):
        spectrum(np.sin(np.arange(64)), fs, window="kaiser")  # type: ignore[arg-type]


@pytest.mark.parametrize("seed", range(4))
def test_speed_from_moving_textured_scene(seed):
    """End to end (Eq. 9-14): a mixel with mask A0 + A1 cos(omega_d x) over L = 40 periods slides over a random
    texture at speed v. The signal holds scene frequencies within the mask window's main lobe,
    omega_d +- 2 pi / L, so |v_hat - v| / v <= 1 / 40 (plus the temporal estimator's error, far smaller here)."""
    rng = np.random.default_rng(seed)
    omega_df, d_f, depth = 2 * np.pi / 0.2e-3, 2e-3, 0.5  # mask period 0.2 mm at 2 mm; road at 0.5 m
    omega_d = scene_frequency(omega_df, d_f, depth)
    assert omega_d == pytest.approx(2 * np.pi / 0.05)  # 5 cm period on the road
    dx = 0.5e-3
    texture = np.convolve(rng.random(20_000), np.ones(9) / 9, mode="same")  # 10 m of road
    window = np.arange(int(40 * 0.05 / dx)) * dx
    mask = 0.5 + 0.5 * np.cos(omega_d * window)
    v, fs = 3.0, 400.0
    starts = (np.arange(800) * v / fs / dx).astype(int)
    signal = np.array([texture[s : s + window.size] @ mask for s in starts]) * dx
    # The mask's constant term A0 passes the texture's slow variations: reject speeds below 0.5 m/s.
    f_min = omega_d * 0.5 / (2 * np.pi)
    assert speed_from_signal(signal, fs, omega_d, min_frequency_hz=f_min) == pytest.approx(v, rel=1 / 40)
    # 1 s windows: their own spectral resolution (one bin, 1 Hz of f_p = 60 Hz) adds to the spread of the content
    times, speeds = speed_track(signal, fs, omega_d, 400, 200, min_frequency_hz=f_min)
    assert times.shape == speeds.shape == (3,)
    np.testing.assert_allclose(times, [199.5, 399.5, 599.5] / np.float64(fs))
    bin_relative = (fs / 400) / (omega_d * v / (2 * np.pi))
    np.testing.assert_allclose(speeds, v, rtol=1 / 40 + bin_relative)


# ------------------------------------------------------------------------------------------- trajectory
def test_straight_line_when_speeds_equal():
    path = trajectory_from_speeds(np.full(10, 2.0), np.full(10, 2.0), 1.5, 0.1, initial_pose=(1.0, 2.0, np.pi / 2))
    np.testing.assert_allclose(path.x_m, 1.0, atol=1e-12)
    np.testing.assert_allclose(path.y_m, 2.0 + 0.2 * np.arange(11), atol=1e-12)
    assert np.all(np.isinf(path.turn_radius_m)) and np.all(path.heading_change_rad == 0)


def test_constant_turn_is_a_circle_of_predicted_radius():
    width, vl, vr, dt = 1.6, 1.0, 2.0, 0.05
    radius = width / 2 * (vr + vl) / (vr - vl)  # 2.4 m, centre on the left
    steps = int(round(2 * np.pi / ((vr - vl) / width) / dt))
    path = trajectory_from_speeds(np.full(steps, vl), np.full(steps, vr), width, dt)
    np.testing.assert_allclose(path.turn_radius_m, radius)
    np.testing.assert_allclose(np.hypot(path.x_m, path.y_m - radius), radius, atol=1e-12)
    assert path.y_m[steps // 4] > 0, "right side faster -> turning left (counter-clockwise)"
    assert path.heading_rad[-1] == pytest.approx(steps * (vr - vl) / width * dt)


def test_spin_in_place():
    path = trajectory_from_speeds([-1.0, -1.0], [1.0, 1.0], 0.5, 0.1)
    np.testing.assert_allclose(path.x_m, 0, atol=1e-15)
    np.testing.assert_allclose(path.turn_radius_m, 0)
    np.testing.assert_allclose(path.heading_rad, [0, 0.4, 0.8])


@settings(deadline=None, max_examples=40)
@given(
    speeds=hnp.arrays(
        np.float64, st.tuples(st.integers(1, 30), st.just(2)), elements=st.floats(min_value=-3.0, max_value=3.0)
    )
)
def test_arc_integration_is_exact_under_step_splitting(speeds):
    """Each step is an exact arc: splitting every step into two halves leaves the poses unchanged."""
    coarse = trajectory_from_speeds(speeds[:, 0], speeds[:, 1], 0.8, 0.2)
    fine = trajectory_from_speeds(np.repeat(speeds[:, 0], 2), np.repeat(speeds[:, 1], 2), 0.8, 0.1)
    np.testing.assert_allclose(fine.x_m[::2], coarse.x_m, atol=1e-12)
    np.testing.assert_allclose(fine.y_m[::2], coarse.y_m, atol=1e-12)
    np.testing.assert_allclose(fine.heading_rad[::2], coarse.heading_rad, atol=1e-12)


def test_trajectory_input_errors():
    with pytest.raises(ValueError, match="width_m"):
        trajectory_from_speeds([1.0], [1.0], 0.0, 0.1)
    with pytest.raises(ValueError, match="same|one length"):
        trajectory_from_speeds([1.0, 2.0], [1.0], 1.0, 0.1)
    with pytest.raises(ValueError, match="NaN"):
        trajectory_from_speeds([np.nan], [1.0], 1.0, 0.1)


@pytest.mark.parametrize("speed_m_s", [1.5, 4.0, 9.0])
def test_eq13_signal_gives_back_its_speed(speed_m_s):
    """Eq. 13 -> Eq. 14: the FFT peak of A0' + A1' cos(omega_d v t + phi') over 2 s at 400 Hz returns v to within
    the sub-bin estimator's resolution (a small fraction of one 0.5 Hz bin)."""
    omega_d, fs = 2 * np.pi / 0.05, 400.0
    t = np.arange(800) / fs
    signal = speed_signal(t, speed_m_s, omega_d, a0=3.0, a1=0.4, phase_rad=0.7)
    assert signal[0] == pytest.approx(3.0 + 0.4 * np.cos(0.7), abs=1e-12)
    bin_speed = 2 * np.pi * (fs / t.size) / omega_d  # one frequency bin, in m/s
    assert speed_from_signal(signal, fs, omega_d, min_frequency_hz=2.0) == pytest.approx(speed_m_s,
                                                                                          abs=0.1 * bin_speed)
