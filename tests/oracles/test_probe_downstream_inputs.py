"""Estimators, calibrations, the sensor and the read-out: closed forms where a number is returned, one InputError
naming the argument where a user's mistake used to give NaN, a negative threshold, a numpy error or a crash."""

from __future__ import annotations

import json

import numpy as np
import pytest

import mincam_sim  # noqa: F401  (before drjit/mitsuba)
from mincam_sim.errors import InputError
from mincam_sim.estimation import estimators as E
from mincam_sim.estimation.calibration import Calibration1D, Calibration2D
from mincam_sim.model.readout import read_out
from mincam_sim.model.sensor import PLANCK_J_S, SPEED_OF_LIGHT_M_S, SensorModel

# ------------------------------------------------------------------------------------------------ estimators


@pytest.mark.parametrize("call, words", [
    (lambda: E.noise_threshold(np.random.default_rng(0).random((5, 2)), float("nan")), "n_sigma"),
    (lambda: E.noise_threshold(np.random.default_rng(0).random((5, 2)), -5), "n_sigma"),
    (lambda: E.noise_threshold([[1.0, 2.0], [np.nan, 3.0], [1.0, 1.0]]), "NaN"),
    (lambda: E.intrusion_position(1.0, 1.0, float("nan")), "min_total"),
    (lambda: E.track_3(np.ones((2, 3)), -1.0), "min_total"),
    (lambda: E.change_statistic(np.zeros((3, 2)), [0, 0, 0]), "one value per mixel"),
    (lambda: E.detect_change(np.zeros((3, 2)), [0, 0], "1"), "threshold"),
    (lambda: E.spectrum(np.sin(np.arange(64)), 10, zero_pad_factor=10**9), "zero_pad_factor"),
    (lambda: E.spectrum(np.sin(np.arange(64)), 10, zero_pad_factor=float("nan")), "zero_pad_factor"),
    (lambda: E.spectrum(np.sin(np.arange(64)), "10"), "sample_rate_hz"),
    (lambda: E.spectrum(np.sin(np.arange(64)), 10, min_frequency_hz=float("nan")), "min_frequency_hz"),
    (lambda: E.spectrum(np.sin(np.arange(64)), 10, min_frequency_hz=3, max_frequency_hz=1), "must not exceed"),
    (lambda: E.frequency_error_std(1.0, 0.1, 1, 10.0), "n_samples"),
    (lambda: E.frequency_error_std(0.0, 0.1, 64, 10.0), "amplitude"),
    (lambda: E.scene_frequency(float("nan"), 0.002, 0.5), "omega_df_rad_per_m"),
    (lambda: E.scene_frequency(-1000.0, 0.002, 0.5), "omega_df_rad_per_m"),
    (lambda: E.scene_frequency(1000.0, "0.002", 0.5), "d_f_m"),
    (lambda: E.speed_track(np.sin(np.arange(64)), 10, 1, 16.5), "window_samples"),
    (lambda: E.trajectory_from_speeds([1], [1], 0.5, 1.0, (np.nan, 0, 0)), "initial_pose"),
    (lambda: E.trajectory_from_speeds([1], [1], "0.5", 1.0), "width_m"),
])
def test_estimator_mistakes_are_one_input_error(call, words):
    """Before: a NaN or negative threshold (every frame detected), NaN speeds and paths, a negative scene
    frequency, numpy's TypeError/ValueError, RuntimeWarnings, a 477 GiB MemoryError."""
    with pytest.raises(InputError, match=words):
        call()


def test_centroid_of_a_list_of_numbers_is_one_coordinate():
    """``centroid([0, 1, 1, 0], [0, 1, 2, 3])`` took the list as four coordinates and raised; it is 1.5."""
    assert E.centroid([0, 1, 1, 0], [0.0, 1, 2, 3]) == pytest.approx(1.5)
    xy = E.centroid(np.ones((2, 3)), list(np.meshgrid(np.arange(3.0), np.arange(2.0))))
    np.testing.assert_allclose(xy, [1.0, 0.5])


def test_closed_forms_of_the_speed_chain():
    """Eq. 10: omega_d = omega_df d_f / d; Eq. 14: v = omega_p / omega_d; the rect-window error is the CRB;
    a half circle of a differential drive ends 2 R = 2 v / omega away."""
    assert E.scene_frequency(1000.0, 0.002, 0.5) == pytest.approx(4.0)
    assert E.speed_from_frequency(4.0, 2.0) == pytest.approx(2.0)
    n, sigma, a = 64, 0.1, 1.0
    crb = np.sqrt(12 / ((a**2 / (2 * sigma**2)) * n * (n**2 - 1)))
    assert E.frequency_error_std(a, sigma, n, 1.0, "rect") == pytest.approx(crb, rel=1e-12)
    k = np.arange(256)
    assert E.spectrum(np.cos(2 * np.pi * 7.3 * k / 100 + 0.3), 100.0, "rect").peak_hz == pytest.approx(7.3, abs=1e-3)
    path = E.trajectory_from_speeds([1.0] * 100, [2.0] * 100, 0.5, np.pi * 0.5 / 100)
    assert (path.x_m[-1], path.y_m[-1]) == pytest.approx((0.0, 1.5), abs=1e-12)


# ------------------------------------------------------------------------------------------------ calibration


def _cal1d() -> Calibration1D:
    x = np.linspace(0.1, 0.9, 30)
    return Calibration1D.fit(x, np.polynomial.polynomial.polyval(x, [0.01, 0.2, 0.3, 0.05]))


def test_cubic_calibration_recovers_a_cubic_and_round_trips(tmp_path):
    cal = _cal1d()
    u = np.linspace(0.1, 0.9, 7)
    np.testing.assert_allclose(cal.apply(u), np.polynomial.polynomial.polyval(u, [0.01, 0.2, 0.3, 0.05]),
                               atol=1e-14)
    cal.to_json(tmp_path / "c.json")
    np.testing.assert_array_equal(Calibration1D.from_json(tmp_path / "c.json").apply(u), cal.apply(u))
    g = np.stack(np.meshgrid(np.linspace(0.1, 0.9, 5), np.linspace(0.1, 0.9, 5)), -1).reshape(-1, 2)
    true = np.stack([0.1 * g[:, 0] + 0.02 * g[:, 0] ** 3 - 0.01 * g[:, 0] * g[:, 1],
                     -0.05 + 0.2 * g[:, 1] + 0.01 * g[:, 0] ** 2 * g[:, 1]], 1)
    cal2 = Calibration2D.fit(g, true)
    np.testing.assert_allclose(cal2.apply(g), true, atol=1e-14)
    cal2.to_json(tmp_path / "c2.json")
    np.testing.assert_array_equal(Calibration2D.from_json(tmp_path / "c2.json").apply(g), cal2.apply(g))


@pytest.mark.parametrize("content, words", [
    ("{not json", "cannot read a Calibration1D JSON file"),
    ("[1, 2]", "expected a JSON file with kind='Calibration1D'"),
    ('{"kind": "Calibration1D"}', "lacks degree, coefficients"),
    ('{"kind": "Calibration1D", "degree": 3, "coefficients": [1, 2], "fit_range": [0, 1], "rms_residual_m": 0, '
     '"n_points": 2}', "has 4 coefficients, got 2"),
    ('{"kind": "Calibration1D", "degree": 1, "coefficients": [1, 2], "fit_range": [0, 0], "rms_residual_m": 0, '
     '"n_points": 2}', "min < max"),
])
def test_a_broken_calibration_file_is_one_input_error(tmp_path, content, words):
    """Before: JSONDecodeError, AttributeError ('list' has no 'get'), KeyError 'degree', and a file with two
    coefficients for a cubic or an empty range loaded and applied to a RuntimeWarning (division by zero)."""
    path = tmp_path / "c.json"
    path.write_text(content)
    with pytest.raises(InputError, match=words):
        Calibration1D.from_json(path)


def test_a_broken_2d_calibration_is_one_input_error(tmp_path):
    g = np.stack(np.meshgrid(np.linspace(0.1, 0.9, 5), np.linspace(0.1, 0.9, 5)), -1).reshape(-1, 2)
    payload = Calibration2D.fit(g, g * 0.1).to_dict()
    payload["coefficients_y"] = payload["coefficients_y"][:-1]
    path = tmp_path / "c.json"
    path.write_text(json.dumps(payload))
    with pytest.raises(InputError, match="coefficients"):
        Calibration2D.from_json(path)
    with pytest.raises(InputError, match="cannot read"):
        Calibration2D.from_json(tmp_path / "missing.json")


# ------------------------------------------------------------------------------------------------ sensor


def test_sensor_closed_forms():
    """Photons = E A t lambda / (h c); 12 bits: 4095 DN, gain = full well / 4095; saturation at 4095."""
    s = SensorModel()
    photons = 1.0 * s.pixel_area_m2 * s.exposure_s / (PLANCK_J_S * SPEED_OF_LIGHT_M_S / 550e-9)
    assert s.photons(1.0) == pytest.approx(photons, rel=1e-14)
    assert s.max_dn == 4095 and s.gain == pytest.approx(10_000 / 4095)
    assert s.expected(1e6) == 4095 and s.expected(0.0) == pytest.approx(5 * 0.01 / s.gain)


def test_sensor_numpy_integer_bit_depth_keeps_its_range():
    """``bit_depth=np.int8(12)`` gave max_dn = -1 (2**12 overflowed int8) and every reading clipped to nonsense."""
    s = SensorModel(bit_depth=np.int8(12))
    assert s.max_dn == 4095 and s.expected(1e6) == 4095


def test_sensor_absurd_irradiance_saturates_instead_of_crashing():
    """1e300 W/m^2 made numpy's Poisson sampler raise "lam value too large"; it saturates at the ADC's top."""
    rng = np.random.default_rng(0)
    assert SensorModel().measure(1e300, rng) == 4095
    # 48 x 48 pixels at full well, each read with its read noise and clipped at 4095: just below the top
    assert np.all(SensorModel.paper_prototype().measure(np.array([1e300, 1e30]), rng) > 4094)


@pytest.mark.parametrize("fields, words", [
    ({"exposure_s": "0.01"}, "exposure_s"),
    ({"exposure_s": True}, "exposure_s"),
    ({"quantum_efficiency": "0.6"}, "quantum_efficiency"),
    ({"pixels_averaged": 10**12}, "pixels_averaged"),
])
def test_sensor_mistakes_are_one_input_error(fields, words):
    """Before: numpy TypeError for strings, True taken as a 1 s exposure, a 931 GiB MemoryError at measure."""
    with pytest.raises(InputError, match=words):
        SensorModel(**fields)


def test_read_out_refuses_a_background_of_other_mixels_and_too_few_frames():
    """A 3-value background for 2-mixel frames gave a Readout whose change could not be formed; 1 background
    frame was an error about ``background_frames``, 2.5 a TypeError."""
    frames, rng = np.array([[1.0, 0.5], [0.8, 0.2]]), np.random.default_rng(0)
    s = SensorModel.paper_prototype()
    with pytest.raises(InputError, match="one value per mixel"):
        read_out(frames, np.array([0.3, 0.1, 0.2]), s, rng)
    for n in (1, 2.5):
        with pytest.raises(InputError, match="n_background_frames"):
            read_out(frames, np.array([0.3, 0.1]), s, rng, n_background_frames=n)
    r = read_out(frames, np.array([0.3, 0.1]), s, rng)
    assert r.sensor.expected(1.0) == pytest.approx(0.7 * 4095)  # the brightest value fills 70 % of 12 bits
