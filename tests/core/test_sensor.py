"""Tests of the photodetector / readout model (mincam_sim.model.sensor).

Monte Carlo checks compare sample statistics with Poisson + read-noise theory using Z = 5 standard errors
(two-sided false-failure probability ~6e-7 per comparison for normal sampling errors); seeds are fixed, so every
run is repeatable. Standard errors: mean sigma / sqrt(n); variance s^2 sqrt(2 / (n - 1)) (the values are very
nearly normal: Poisson excess kurtosis 1/lambda is negligible at the electron counts used); a standard
deviation's relative error 1 / sqrt(2 (n - 1)).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mincam_sim.model.sensor import PLANCK_J_S, SPEED_OF_LIGHT_M_S, SensorModel

Z = 5.0


def irradiance_for_electrons(sensor: SensorModel, electrons: float) -> float:
    """Irradiance [W/m^2] giving ``electrons`` mean signal electrons per pixel (dark current excluded)."""
    return electrons / sensor.electrons_per_irradiance


def test_expected_matches_formula():
    sensor = SensorModel(exposure_s=2e-3, quantum_efficiency=0.5, wavelength_m=600e-9, dark_current_e_per_s=100.0)
    irradiance = np.array([0.0, 1e-3, 0.05])
    photons = irradiance * sensor.detector_area_m2 * 2e-3 / (PLANCK_J_S * SPEED_OF_LIGHT_M_S / 600e-9)
    electrons = 0.5 * photons + 100.0 * 2e-3
    gain = 10_000.0 / 4095.0
    np.testing.assert_allclose(sensor.photons(irradiance), photons, rtol=1e-14)
    np.testing.assert_allclose(sensor.electrons(irradiance), electrons, rtol=1e-14)
    np.testing.assert_allclose(sensor.expected(irradiance), np.minimum(electrons, 10_000.0) / gain, rtol=1e-14)
    assert sensor.gain == pytest.approx(gain, rel=1e-15)


def test_expected_saturates_and_keeps_shape():
    sensor = SensorModel()
    values = sensor.expected(np.full((3, 2), 1e3))
    assert values.shape == (3, 2)
    assert np.all(values == sensor.max_dn)


@pytest.mark.parametrize("method", ["aggregate", "per_pixel"])
def test_single_pixel_mean_and_variance_match_theory(method):
    sensor = SensorModel()
    irradiance = irradiance_for_electrons(sensor, 2000.0)
    n = 200_000
    values = sensor.measure(np.full(n, irradiance), np.random.default_rng(1), method=method)
    mean_theory = float(sensor.expected(irradiance))
    var_theory = float(sensor.expected_std_dn(irradiance)) ** 2
    assert abs(values.mean() - mean_theory) <= Z * np.sqrt(var_theory / n)
    assert abs(values.var(ddof=1) - var_theory) <= Z * var_theory * np.sqrt(2.0 / (n - 1))
    assert np.all(values == np.rint(values)), "single-pixel readout must be integer DN"


@pytest.mark.parametrize(("method", "n"), [("aggregate", 100_000), ("per_pixel", 1_000)])
def test_averaged_pixels_mean_and_variance_match_theory(method, n):
    sensor = SensorModel.paper_prototype()
    irradiance = irradiance_for_electrons(sensor, 3000.0)
    values = sensor.measure(np.full(n, irradiance), np.random.default_rng(2), method=method)
    mean_theory = float(sensor.expected(irradiance))
    var_theory = float(sensor.expected_std_dn(irradiance)) ** 2
    assert abs(values.mean() - mean_theory) <= Z * np.sqrt(var_theory / n)
    assert abs(values.var(ddof=1) - var_theory) <= Z * var_theory * np.sqrt(2.0 / (n - 1))
    steps = values * sensor.pixels_averaged
    np.testing.assert_allclose(steps, np.rint(steps), atol=1e-6, err_msg="averages of N integers are k/N")


def test_averaging_48x48_reduces_relative_noise_by_48():
    """N pixels of the same size as the single pixel: same mean, noise / sqrt(N) = / 48 (all noise per pixel)."""
    single = SensorModel()
    averaged = SensorModel(pixels_averaged=48 * 48, detector_area_m2=single.detector_area_m2 * 48 * 48)
    irradiance = irradiance_for_electrons(single, 5000.0)  # shot noise 71 e- >> read noise 2.5 e-
    n = 20_000
    rng = np.random.default_rng(3)
    one = single.measure(np.full(n, irradiance), rng)
    many = averaged.measure(np.full(n, irradiance), rng)
    relative_one = one.std(ddof=1) / one.mean()
    relative_many = many.std(ddof=1) / many.mean()
    ratio_rel_se = np.sqrt(2.0) / np.sqrt(2.0 * (n - 1))  # two independent standard deviations
    assert relative_one / relative_many == pytest.approx(48.0, rel=Z * ratio_rel_se)


def test_per_pixel_and_aggregate_agree_for_prototype():
    sensor = SensorModel.paper_prototype()
    irradiance = irradiance_for_electrons(sensor, 800.0)
    n = 1_500
    a = sensor.measure(np.full(n, irradiance), np.random.default_rng(4), method="aggregate")
    b = sensor.measure(np.full(n, irradiance), np.random.default_rng(5), method="per_pixel")
    std = float(sensor.expected_std_dn(irradiance))
    assert abs(a.mean() - b.mean()) <= Z * std * np.sqrt(2.0 / n)
    assert a.std(ddof=1) / b.std(ddof=1) == pytest.approx(1.0, rel=Z / np.sqrt(n - 1))


def test_saturation_and_clipping():
    rng = np.random.default_rng(6)
    sensor = SensorModel()  # full well maps to 4095 DN; read noise may lower a saturated pixel by a few DN
    values = sensor.measure(np.full(10_000, 10.0), rng)
    assert values.max() == 4095.0
    assert values.min() >= 4095.0 - np.ceil(Z * sensor.read_noise_e / sensor.gain)
    high_gain = SensorModel(gain_e_per_dn=1.0)  # full well (10 000 DN) beyond the ADC: the ADC clips
    assert np.all(high_gain.measure(np.full(1000, 10.0), rng) == 4095.0)
    assert np.all(high_gain.measure(np.full(1000, 10.0), rng, method="per_pixel") == 4095.0)
    dark = SensorModel(dark_current_e_per_s=0.0).measure(np.zeros(10_000), rng)
    assert dark.min() == 0.0 and np.count_nonzero(dark == 0.0) > 0
    eight_bit = SensorModel(bit_depth=8)
    assert eight_bit.max_dn == 255.0
    assert np.all(eight_bit.measure(np.full(100, 10.0), rng) <= 255.0)


def test_same_seed_same_numbers_and_no_global_state():
    sensor = SensorModel.paper_prototype()
    irradiance = np.linspace(0.0, 0.02, 50)
    for method in ("aggregate", "per_pixel"):
        np.random.seed(0)  # noqa: NPY002 -- the global state must not matter
        a = sensor.measure(irradiance, np.random.default_rng(42), method=method)
        np.random.seed(1)  # noqa: NPY002
        b = sensor.measure(irradiance, np.random.default_rng(42), method=method)
        c = sensor.measure(irradiance, np.random.default_rng(43), method=method)
        np.testing.assert_array_equal(a, b)
        assert not np.array_equal(a, c)


def test_exposure_for_fills_requested_fraction():
    sensor = SensorModel()
    auto = sensor.auto_exposed(3.7, fill=0.6)
    assert auto.exposure_s == pytest.approx(sensor.exposure_for(3.7, 0.6), rel=1e-15)
    assert float(auto.electrons(3.7)) == pytest.approx(0.6 * sensor.full_well_e, rel=1e-12)
    assert float(auto.expected(3.7)) == pytest.approx(0.6 * sensor.max_dn, rel=1e-12)


@settings(deadline=None, max_examples=30)
@given(
    electrons=st.floats(min_value=0.0, max_value=2e4),
    bit_depth=st.integers(min_value=1, max_value=16),
    pixels=st.sampled_from([1, 4, 2304]),
)
def test_measure_stays_in_adc_range(electrons, bit_depth, pixels):
    sensor = SensorModel(bit_depth=bit_depth, pixels_averaged=pixels, detector_area_m2=pixels * 4.84e-12)
    values = sensor.measure(np.full(64, irradiance_for_electrons(sensor, electrons)), np.random.default_rng(7))
    assert values.shape == (64,)
    assert np.all((values >= 0.0) & (values <= 2**bit_depth - 1))


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("bit_depth", 0, "bit_depth"),
        ("bit_depth", 12.5, "bit_depth"),
        ("quantum_efficiency", 1.5, "quantum_efficiency"),
        ("exposure_s", -1.0, "exposure_s"),
        ("read_noise_e", float("nan"), "read_noise_e"),
        ("pixels_averaged", 0, "pixels_averaged"),
        ("detector_area_m2", 0.0, "detector_area_m2"),
        ("gain_e_per_dn", 0.0, "gain_e_per_dn"),
        ("full_well_e", float("inf"), "full_well_e"),
    ],
)
def test_invalid_fields_raise_naming_the_field(field, value, match):
    with pytest.raises(ValueError, match=match):
        SensorModel(**{field: value})


def test_invalid_irradiance_and_rng():
    sensor = SensorModel()
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="irradiance_w_m2 must be >= 0"):
        sensor.measure(np.array([0.1, -0.1]), rng)
    with pytest.raises(ValueError, match="non-finite"):
        sensor.expected(np.array([np.nan]))
    with pytest.raises(TypeError, match="default_rng"):
        sensor.measure(np.array([0.1]), None)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="method"):
        sensor.measure(np.array([0.1]), rng, method="exact")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="fill"):
        sensor.exposure_for(1.0, fill=0.0)
    with pytest.raises(ValueError, match="irradiance_peak_w_m2"):
        sensor.exposure_for(0.0)
