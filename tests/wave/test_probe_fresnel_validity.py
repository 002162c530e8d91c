"""The wave solver against Fresnel's closed form for an open square aperture, and its refusal where its
ray-sized band and domain miss the aperture's own diffraction (small Fresnel numbers)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import fresnel

import mincam_sim as ms
from mincam_sim import wave
from mincam_sim.errors import InputError

LAMBDA_M = 550e-9


def _fresnel_open_square(half_m: float, d_f_m: float, detector_m: float) -> float:
    """Paraxial Fresnel diffraction of a unit plane wave through a square of half side ``half_m``, intensity
    averaged over a centred ``detector_m`` square at ``d_f_m`` (separable: the square of the slit's average)."""
    x = np.linspace(-detector_m / 2, detector_m / 2, 801)
    scale = np.sqrt(2 / (LAMBDA_M * d_f_m))
    s2, c2 = fresnel((half_m - x) * scale)
    s1, c1 = fresnel((-half_m - x) * scale)
    slit = 0.5 * ((c2 - c1) ** 2 + (s2 - s1) ** 2)
    return float((np.trapezoid(slit, x) / detector_m) ** 2)


def test_fresnel_number_closed_form():
    mixel = ms.Mixel(ms.masks.constant(1.0), d_f_m=2e-3)
    assert wave.fresnel_number(mixel, LAMBDA_M) == pytest.approx(1e-6 / (LAMBDA_M * 2e-3))


def test_open_aperture_matches_fresnel_where_accepted():
    """A 2 mm aperture 5 cm from a 0.1 mm detector (Fresnel number 36): within 1e-3 of the closed form, whose
    fringes put it 0.7 % below the geometric 1."""
    mixel = ms.Mixel(ms.masks.constant(1.0), d_f_m=0.05)
    closed = _fresnel_open_square(1e-3, 0.05, 1e-4)
    assert closed == pytest.approx(0.99338, abs=1e-4)
    got = wave.angular_response(mixel, np.array([[0.0, 0.0]]), qe=None)[0]
    assert got == pytest.approx(closed, abs=1e-3)


def test_small_fresnel_number_is_refused_not_answered_wrong():
    """d_f = 1 m (Fresnel number 1.8): the solver answered 0.514 where Fresnel's closed form gives 0.375."""
    mixel = ms.Mixel(ms.masks.constant(1.0), d_f_m=1.0)
    assert _fresnel_open_square(1e-3, 1.0, 1e-4) == pytest.approx(0.3751, abs=1e-3)
    with pytest.raises(InputError, match=r"Fresnel number .* is 1\.82.*give d_f_m <= 0\.182 m"):
        wave.angular_response(mixel, np.array([[0.0, 0.0]]), qe=None)
    with pytest.raises(InputError, match="Fresnel number"):
        wave.response_table(mixel, n_tan=3)
    with pytest.raises(InputError, match="Fresnel number"):
        wave.validity(mixel, warn=False)


def test_quick_check_flags_an_aperture_that_diffracts():
    """A geometric mixel 1 m behind its 2 mm mask, or behind a 0.3 mm mask at 2 mm, was never flagged."""
    for mixel in (ms.Mixel(ms.masks.ramp("x", 16), d_f_m=1.0),
                  ms.Mixel(ms.masks.ramp("x", 16, width_m=3e-4), d_f_m=2e-3, detector_size_m=1e-4)):
        reasons = wave.quick_check(mixel, warn=False)
        assert len(reasons) == 1 and "Fresnel number" in reasons[0]
    assert wave.quick_check(ms.Mixel(ms.masks.ramp("x", 16)), warn=False) == []  # the default: 909


@pytest.mark.parametrize("call, words", [
    (lambda: wave.talbot_parameter(0.0, 2e-3), "period_m"),
    (lambda: wave.talbot_parameter(-1e-3, 2e-3), "period_m"),
    (lambda: wave.talbot_parameter("1e-3", 2e-3), "period_m"),
    (lambda: wave.quick_check(ms.Mixel(ms.masks.ramp("x", 16)), wavelength_m=float("nan"), warn=False),
     "wavelength_m must be"),
    (lambda: wave.rim_onset_deg(ms.Mixel(ms.masks.ramp("x", 16)), wavelength_m=-1.0), "wavelength_m must be"),
])
def test_wave_helpers_refuse_nonsense(call, words):
    """A zero period divided by zero, a negative one gave a positive u, a NaN wavelength passed every check."""
    with pytest.raises(InputError, match=words):
        call()


def test_talbot_parameter_closed_form():
    assert wave.talbot_parameter(0.2e-3, 2e-3, LAMBDA_M) == pytest.approx(0.0275)
