"""``wave.validity`` takes the ``qe`` its own error advises, and refuses tolerances, direction counts and QE curves
that gave silent nonsense."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import mincam_sim as ms
from mincam_sim import wave
from mincam_sim.errors import InputError


def _ramp_mixel() -> ms.Mixel:
    return ms.Mixel(ms.masks.ramp("x", 64))


def test_validity_follows_its_own_advice_qe_none():
    """Outside the silicon QE model (300 nm) the error says "pass qe=None"; validity had no ``qe``."""
    mixel = _ramp_mixel()
    with pytest.raises(InputError, match="qe=None"):
        wave.validity(mixel, wavelengths_m=(300e-9,), warn=False)
    out = wave.validity(mixel, wavelengths_m=(300e-9,), warn=False, qe=None)
    assert out["wavelength_m"] == 300e-9 and out["ok"]


def test_validity_qe_is_the_one_angular_response_uses():
    """Two bands weighted by a flat QE against one that ignores the second band: validity's central difference
    is the one of angular_response with the same ``qe``."""
    mixel = _ramp_mixel()
    lams = (500e-9, 650e-9)
    only_first = wave.validity(mixel, lams, warn=False, qe=lambda lam: (np.asarray(lam) < 6e-7).astype(float))
    first_alone = wave.validity(mixel, lams[:1], warn=False)
    assert only_first["max_rel_diff_central"] == pytest.approx(first_alone["max_rel_diff_central"], rel=1e-9)


@pytest.mark.parametrize("kw, words", [
    ({"tolerance": -1}, "tolerance must be"),
    ({"tolerance": float("nan")}, "tolerance must be"),
    ({"tolerance": 1.5}, "tolerance must be"),
    ({"n_tan": 2.5}, "n_tan must be an integer"),
    ({"n_tan": 1}, "n_tan must be an integer"),
    ({"qe": "silicon"}, "qe must be"),
])
def test_validity_refuses_nonsense_arguments(kw, words):
    """``tolerance=-1`` returned ok=False with rim_onset_deg 0, NaN a rim of 27.7 deg; ``n_tan=2.5`` was a
    TypeError; ``qe="silicon"`` a TypeError ('str' object is not callable)."""
    with pytest.raises(InputError, match=words):
        wave.validity(_ramp_mixel(), warn=False, **kw)


def test_rim_onset_refuses_nonsense_tolerance():
    with pytest.raises(InputError, match="tolerance must be"):
        wave.rim_onset_deg(_ramp_mixel(), tolerance=float("nan"))


@pytest.mark.parametrize("qe, words", [
    (lambda lam: np.array([1.0, -0.5]), r"\[1.0, -0.5\]"),
    (lambda lam: np.array([1.0, 1.0, 1.0]), "another shape"),
    (lambda lam: np.array([np.nan, 1.0]), "nan"),
])
def test_spectral_weights_refuse_a_bad_qe_curve(qe, words):
    """A QE curve with a negative value gave weights [2, -1] (summing to 1); one of the wrong length a numpy
    broadcasting ValueError."""
    with pytest.raises(InputError, match=words):
        wave.spectral_weights([500e-9, 600e-9], qe=qe)


def test_spectral_weights_closed_form():
    """Trapezoid band widths times QE, normalised: 500/600/700 nm with QE 1, 0.5, 2 (a scalar curve too)."""
    w = wave.spectral_weights([600e-9, 500e-9, 700e-9], qe=lambda lam: np.interp(lam, [5e-7, 6e-7, 7e-7], [1, .5, 2]))
    expected = np.array([100 * 0.5, 50 * 1, 50 * 2])
    np.testing.assert_allclose(w, expected / expected.sum(), rtol=1e-12)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        np.testing.assert_allclose(wave.spectral_weights([5e-7, 6e-7], qe=lambda lam: 60.0), [0.5, 0.5])
