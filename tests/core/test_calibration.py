"""Tests of the position calibrations and error rates (mincam_sim.estimation.calibration)."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from mincam_sim.estimation.calibration import (
    Calibration1D,
    Calibration2D,
    ExtrapolationWarning,
    bivariate_exponents,
)
from mincam_sim.estimation.metrics import error_rates, speed_error_rates

coefficient = st.floats(min_value=-1.0, max_value=1.0, allow_nan=False)


def cubic_2d(coefficients: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """sum_k c[k, :] x^i y^j over the exponents of total degree <= 3, in the raw (unscaled) inputs."""
    return sum(
        np.outer(xy[:, 0] ** i * xy[:, 1] ** j, coefficients[k]) for k, (i, j) in enumerate(bivariate_exponents(3))
    )


@settings(deadline=None, max_examples=50)
@given(coefficients=hnp.arrays(np.float64, 4, elements=coefficient))
def test_1d_recovers_a_cubic(coefficients):
    observed = np.linspace(0.05, 0.95, 25)
    true_m = np.polynomial.polynomial.polyval(observed, coefficients)
    calibration = Calibration1D.fit(observed, true_m)
    probe = np.linspace(0.05, 0.95, 101)
    np.testing.assert_allclose(
        calibration.apply(probe), np.polynomial.polynomial.polyval(probe, coefficients), rtol=0, atol=1e-12
    )
    assert calibration.rms_residual_m <= 1e-13
    assert calibration.fit_range == (0.05, 0.95)


@settings(deadline=None, max_examples=50)
@given(coefficients=hnp.arrays(np.float64, (10, 2), elements=coefficient))
def test_2d_recovers_a_bivariate_cubic(coefficients):
    grid = np.linspace(0.1, 0.9, 6)
    obs = np.stack(np.meshgrid(grid, grid), axis=-1).reshape(-1, 2)
    calibration = Calibration2D.fit(obs, cubic_2d(coefficients, obs))
    probe = np.random.default_rng(0).uniform(0.1, 0.9, size=(200, 2))
    np.testing.assert_allclose(calibration.apply(probe), cubic_2d(coefficients, probe), rtol=0, atol=1e-12)
    assert np.all(calibration.rms_residual_m <= 1e-13)


def test_2d_conditioning_far_from_origin():
    """Centring/scaling: data at x ~ 1000 +- 0.01 is fitted as well as data in [0, 1]."""
    rng = np.random.default_rng(1)
    obs = 1000.0 + 0.01 * rng.random((60, 2))
    u = (obs - 1000.0) / 0.01
    true = np.stack([0.1 + 0.2 * u[:, 0] ** 3 - 0.05 * u[:, 0] * u[:, 1], 0.3 * u[:, 1] ** 2], axis=1)
    calibration = Calibration2D.fit(obs, true)
    np.testing.assert_allclose(calibration.apply(obs), true, atol=1e-9)


def test_json_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(2)
    observed = np.sort(rng.random(30))
    calibration = Calibration1D.fit(
        observed, 0.5 * observed**3 - 0.25 + 1e-3 * rng.normal(size=30), metadata={"boundary": "finish line"}
    )
    calibration.to_json(tmp_path / "c1.json")
    loaded = Calibration1D.from_json(tmp_path / "c1.json")
    probe = np.linspace(observed.min(), observed.max(), 77)
    np.testing.assert_array_equal(loaded.apply(probe), calibration.apply(probe))
    assert loaded.metadata == {"boundary": "finish line"}
    assert loaded.rms_residual_m == calibration.rms_residual_m
    payload = json.loads((tmp_path / "c1.json").read_text())
    assert payload["degree"] == 3 and len(payload["coefficients"]) == 4

    obs = rng.random((40, 2))
    calibration2 = Calibration2D.fit(obs, np.sin(obs) + 1e-3 * rng.normal(size=(40, 2)), metadata={"units": "m"})
    calibration2.to_json(tmp_path / "c2.json")
    loaded2 = Calibration2D.from_json(tmp_path / "c2.json")
    probe2 = np.concatenate([obs, 0.5 * (obs[:-1] + obs[1:])])  # inside the convex hull
    np.testing.assert_array_equal(loaded2.apply(probe2), calibration2.apply(probe2))
    np.testing.assert_array_equal(loaded2.fit_hull, calibration2.fit_hull)
    with pytest.raises(ValueError, match="kind='Calibration2D'"):
        Calibration2D.from_json(tmp_path / "c1.json")


def test_1d_bad_inputs():
    x = np.linspace(0, 1, 10)
    with pytest.raises(ValueError, match="cannot determine the 4 coefficients"):
        Calibration1D.fit(x[:3], x[:3])
    with pytest.warns(UserWarning, match="interpolates them exactly"):
        Calibration1D.fit(x[:4], x[:4])
    with pytest.raises(ValueError, match="NaN/inf.*drop_nonfinite=True"):
        Calibration1D.fit(np.r_[x, np.nan], np.r_[x, 0.0])
    with pytest.warns(UserWarning, match="dropped 1 of 11"):
        calibration = Calibration1D.fit(np.r_[x, np.nan], np.r_[x, 0.0], drop_nonfinite=True)
    assert calibration.n_points == 10
    with pytest.raises(ValueError, match="equal length"):
        Calibration1D.fit(x, x[:5])
    with pytest.raises(ValueError, match="all observed values are equal"):
        Calibration1D.fit(np.ones(10), x)
    with pytest.raises(ValueError, match="do not determine"):
        Calibration1D.fit(np.r_[np.zeros(5), np.ones(5)], x)  # 2 distinct points for 4 coefficients
    with pytest.raises(ValueError, match="degree"):
        Calibration1D.fit(x, x, degree=-1)


def test_2d_bad_inputs():
    rng = np.random.default_rng(3)
    obs = rng.random((20, 2))
    with pytest.raises(ValueError, match="cannot determine the 10 coefficients"):
        Calibration2D.fit(obs[:9], obs[:9])
    with pytest.raises(ValueError, match=r"shape \(n, 2\)"):
        Calibration2D.fit(obs[:, :1], obs[:, :1])
    line = np.stack([np.linspace(0, 1, 20), np.linspace(0, 2, 20)], axis=1)
    with pytest.raises(ValueError, match="not all on one line"):
        Calibration2D.fit(line, line)
    bad = obs.copy()
    bad[4, 1] = np.nan
    with pytest.raises(ValueError, match="NaN/inf"):
        Calibration2D.fit(bad, obs)


def test_extrapolation_is_flagged_and_warned_once():
    x = np.linspace(0.2, 0.8, 12)
    calibration = Calibration1D.fit(x, 2 * x)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        predicted, outside = calibration.apply(np.array([0.2, 0.5, 0.8]), return_extrapolated=True)
    assert not outside.any()
    with pytest.warns(ExtrapolationWarning, match="2 of 4"):
        predicted, outside = calibration.apply(np.array([0.1, 0.5, 0.9, np.nan]), return_extrapolated=True)
    np.testing.assert_array_equal(outside, [True, False, True, False])
    np.testing.assert_allclose(predicted[:3], [0.2, 1.0, 1.8], atol=1e-12)
    assert np.isnan(predicted[3])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # warned once already
        calibration.apply(0.0)

    # 2D: a disk of calibration points (like the paper's 50 cm field of view): a corner of its bounding box is
    # outside the convex hull even though it is inside the box.
    angles = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    disk = np.concatenate([np.stack([np.cos(angles), np.sin(angles)], 1) * r for r in (0.2, 0.4)])
    calibration2 = Calibration2D.fit(0.5 + disk, disk)
    with pytest.warns(ExtrapolationWarning):
        _, outside2 = calibration2.apply(np.array([[0.5, 0.5], [0.15, 0.15], [0.5, 0.9]]), return_extrapolated=True)
    np.testing.assert_array_equal(outside2, [False, True, False])
    single = calibration2.apply(np.array([0.6, 0.55]))
    np.testing.assert_allclose(single, [0.1, 0.05], atol=1e-12)


def test_error_rates():
    rates = error_rates([0.0, 0.1, 0.25, np.nan], [0.0, 0.11, 0.2, 0.3], calibrated_range=0.5)
    assert rates["max_error_pct"] == pytest.approx(10.0)
    assert rates["avg_error_pct"] == pytest.approx((0 + 2 + 10) / 3)
    assert rates["n"] == 3 and rates["n_missing"] == 1
    rates2 = error_rates([[0.03, 0.04], [0.0, 0.0]], [[0.0, 0.0], [0.0, 0.0]], calibrated_range=0.5)
    assert rates2["max_error_pct"] == pytest.approx(10.0)  # Euclidean: 5 cm of 50 cm
    speed = speed_error_rates([9.0, 10.5], [10.0, 10.0])
    assert speed["max_error_pct"] == pytest.approx(10.0) and speed["avg_error_pct"] == pytest.approx(7.5)
    with pytest.raises(ValueError, match="zero speeds"):
        speed_error_rates([1.0], [0.0])
    with pytest.raises(ValueError, match="calibrated_range"):
        error_rates([0.0], [0.0], 0.0)
    with pytest.raises(ValueError, match="no finite"):
        error_rates([np.nan], [0.0], 1.0)
