"""Wave optics of a mixel (mincam_sim.wave) against closed forms, limits, an independent package and the renderer.

Closed forms here are written independently of the solver: the infinite grating as a Fourier series of the
amplitude with the exact propagation phase of each order, the Fresnel edge from scipy.special.fresnel, the
geometric limit from the ray model's own quadrature.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest
from scipy.integrate import trapezoid
from scipy.special import fresnel

from mincam_sim import masks, wave
from mincam_sim.masks.profiles import NUMPY_OPS, Band, Constant, MaskProfile
from mincam_sim.model.optics import Mixel

LAM = 550e-9  # [m]


# ------------------------------------------------------------------------------------------------ closed forms
def grating_detector_average(amp_coeffs: np.ndarray, period_m: float, d_f_m: float, detector_m: float,
                             tan_x: np.ndarray, lam: float = LAM) -> np.ndarray:
    """Detector-averaged intensity behind an infinite grating of amplitude sum_n c_n exp(i 2 pi n x / p).

    Order n of a plane wave with transverse frequency f0 = -sin(atan t)/lam travels at f0 + n/p and gains
    exp(i 2 pi d_f sqrt(1/lam^2 - (f0 + n/p)^2)); the detector [-a, a] averages exp(i 2 pi (n - m) x / p) to
    sinc((n - m) 2a / p).
    """
    n = np.arange(len(amp_coeffs)) - (len(amp_coeffs) - 1) // 2
    out = []
    for t in np.atleast_1d(tan_x):
        f0 = -math.sin(math.atan(t)) / lam
        kz = np.sqrt(1 / lam**2 - (f0 + n / period_m) ** 2 + 0j)
        a = amp_coeffs * np.exp(2j * np.pi * d_f_m * kz)
        dn = n[:, None] - n[None, :]
        out.append(float(np.real(np.sum(a[:, None] * np.conj(a[None, :]) * np.sinc(dn * detector_m / period_m)))))
    return np.array(out)


def sqrt_cosine_coeffs(a0: float, a1: float, orders: int = 40) -> np.ndarray:
    """Fourier coefficients c_-N..c_N of sqrt(a0 + a1 cos(2 pi x / p)) (by a 4096-point FFT over one period)."""
    x = np.arange(4096) / 4096
    c = np.fft.fft(np.sqrt(a0 + a1 * np.cos(2 * np.pi * x))) / 4096
    return np.concatenate([c[-orders:], c[: orders + 1]])


def fresnel_edge_intensity(x_m: np.ndarray, z_m: float, lam: float = LAM) -> np.ndarray:
    """Intensity behind a half-plane open for x > 0 (paraxial Fresnel diffraction, unit incident intensity)."""
    w = x_m * np.sqrt(2 / (lam * z_m))
    s, c = fresnel(w)
    return 0.5 * ((c + 0.5) ** 2 + (s + 0.5) ** 2)


@dataclass(frozen=True)
class SquaredCosine(MaskProfile):
    """T = (b0 + b1 cos(omega x))^2: a pure sinusoidal *amplitude* grating."""

    omega_rad_per_m: float
    b0: float
    b1: float

    def evaluate(self, x_m, y_m, ops=NUMPY_OPS):
        return (self.b0 + self.b1 * ops.cos(self.omega_rad_per_m * x_m)) ** 2 + 0.0 * y_m


# ------------------------------------------------------------------------------------------------ closed forms
@pytest.mark.parametrize("period_m, a0, a1", [(0.2e-3, 0.5, 0.5), (0.1e-3, 0.5, 0.5), (0.06e-3, 0.45, 0.3)])
def test_infinite_grating_closed_form(period_m, a0, a1):
    """Sinusoidal intensity masks (amplitude sqrt(T)): detector averages match the grating's Fourier series.

    The finite 2 mm aperture's rim is >= 0.6 mm from the detector's view here: its Fresnel ripple averaged
    over 0.1 mm is ~1e-4 of the signal (the open aperture's central response is 1 +- 2e-4 below), which sets
    the tolerance.
    """
    mixel = Mixel(masks.sinusoid(2 * np.pi / period_m, a0, a1))
    t = np.linspace(-0.15, 0.15, 13)
    pts = np.column_stack([t, 0 * t])
    got = wave.angular_response(mixel, pts) / wave.angular_response(Mixel(masks.constant(1.0)), pts)
    expected = grating_detector_average(sqrt_cosine_coeffs(a0, a1), period_m, mixel.d_f_m,
                                        mixel.detector_size_m, t)
    np.testing.assert_allclose(got, expected, atol=3e-4 * (a0 + a1))


@pytest.mark.parametrize("u", [0.05, 0.09, 0.2, 0.5, 1.0])
def test_talbot_loss_of_fundamental_of_an_amplitude_grating(u):
    """A pure amplitude grating b0 + b1 cos keeps its fundamental times cos(pi u') (u' with the exact kz)."""
    d_f = 2e-3
    period = math.sqrt(LAM * d_f / u)
    det = 0.25 * period  # a detector narrower than the period keeps a measurable fundamental
    size = 2e-3
    b0, b1 = 0.6, 0.3
    profile = SquaredCosine(2 * np.pi / period, b0, b1)
    mixel = Mixel(masks.from_profile(profile, "amp_grating", 64, size), d_f, det)
    n = 32  # one period of the walk-off d_f t, sampled evenly: the DFT bin 1 is the fundamental exactly
    t = (np.arange(n) - n / 2) / n * period / d_f
    pts = np.column_stack([t, 0 * t])
    f_wave = np.fft.fft(wave.angular_response(mixel, pts))[1]
    f_geo = np.fft.fft(wave.geometric_response(mixel, pts))[1]
    ratio = float(np.real(f_wave / f_geo))
    # exact phase difference of orders +-1 against order 0 at normal incidence
    dphi = 2 * np.pi * d_f * (1 / LAM - math.sqrt(1 / LAM**2 - 1 / period**2))
    assert abs(ratio - math.cos(dphi)) < 2e-3, (ratio, math.cos(dphi))
    assert abs(dphi / math.pi - u) < 0.01 * u + 1e-3  # u = lambda d_f / p^2 is the paraxial phase / pi


@pytest.mark.parametrize("edge_m", [-100e-6, -40e-6, 0.0, 30e-6, 80e-6, 150e-6])
def test_fresnel_edge(edge_m):
    """An opaque half-plane (x < edge) inside the aperture: the detector average of Fresnel's edge pattern."""
    size = 2e-3
    profile = Band(Constant(1.0), edge_m, size / 2)
    mixel = Mixel(masks.from_profile(profile, "edge", 64, size))
    got = wave.angular_response(mixel, [[0.0, 0.0]])[0]
    a = mixel.detector_size_m / 2
    x = np.linspace(-a, a, 20001)
    expected = trapezoid(fresnel_edge_intensity(x - edge_m, mixel.d_f_m), x) / (2 * a)
    geometric = float(np.clip((a - edge_m) / (2 * a), 0, 1))
    assert abs(got - expected) < 3e-4, (got, expected, geometric)


# ------------------------------------------------------------------------------------------------ limits
def _halftone_print(dpi: float, size_m: float) -> masks.Mask:
    film = masks.PrintedFilm(dpi=dpi, halftone="ordered")
    return film.print(masks.sinusoid(2 * np.pi / 0.2e-3, resolution=256, width_m=size_m))


@pytest.mark.parametrize("kind", ["ramp", "sinusoid", "open"])
def test_short_wavelength_limit_is_geometric_1d(kind):
    mask = {"ramp": masks.ramp("x"), "sinusoid": masks.sinusoid(2 * np.pi / 0.2e-3),
            "open": masks.constant(1.0)}[kind]
    mixel = Mixel(mask)
    t = np.linspace(-0.55, 0.55, 23)
    pts = np.column_stack([t, 0.6 * t[::-1]])
    got = wave.angular_response(mixel, pts, wavelengths_m=(1e-13,), qe=None)
    np.testing.assert_allclose(got, wave.geometric_response(mixel, pts), atol=2e-4)


def test_short_wavelength_limit_is_geometric_2d_print():
    """A 600-dpi halftone print (2D solver): at lambda -> 0 the wave answer is the ray model's dot average."""
    size = 0.6e-3
    mixel = Mixel(_halftone_print(600, size), 1e-3, 0.1e-3)
    pts = np.array([[0.0, 0.0], [0.013, -0.021], [0.1, 0.05], [-0.2, 0.17], [0.3, 0.3]])
    got = wave.angular_response(mixel, pts, wavelengths_m=(1e-13,), qe=None, max_cells=1024)
    np.testing.assert_allclose(got, wave.geometric_response(mixel, pts), atol=2e-3)


def test_two_d_equals_separable_product():
    """A one-axis mask: the 2D solver equals the product of two 1D solutions (both grids hold the full band)."""
    mixel = Mixel(masks.sinusoid(2 * np.pi / 0.1e-3, width_m=0.6e-3), 1e-3, 0.05e-3)
    pts = np.array([[0.0, 0.0], [0.03, 0.0], [0.11, -0.07], [-0.2, 0.15]])
    r2, info2 = wave.angular_response(mixel, pts, method="2d", max_cells=4096, return_info=True)
    r1 = wave.angular_response(mixel, pts, method="separable")
    assert info2.band_covered_min == 1.0
    np.testing.assert_allclose(r2, r1, atol=2e-4)
    assert np.max(np.abs(r1 - wave.geometric_response(mixel, pts))) > 5e-3  # the wave effect is really there


def test_open_aperture_is_one_far_from_the_rim_and_half_at_the_edge():
    mixel = Mixel(masks.constant(1.0))
    edge = (mixel.mask.width_m / 2) / mixel.d_f_m  # detector centre looks at the rim
    r = wave.angular_response(mixel, [[0.0, 0.0], [edge, 0.0]])
    assert abs(r[0] - 1) < 3e-4
    assert abs(r[1] - 0.5) < 0.02  # half the detector sees through (Fresnel edge, ringing averaged out)


def test_spectral_weighting():
    assert wave.spectral_weights([550e-9]).tolist() == [1.0]
    w = wave.spectral_weights([450e-9, 550e-9, 650e-9, 750e-9], qe=None)
    np.testing.assert_allclose(w, [1 / 6, 1 / 3, 1 / 3, 1 / 6])
    qe = wave.silicon_qe(np.array([420e-9, 580e-9, 1000e-9]))
    assert qe[1] > qe[0] and qe[1] > 3 * qe[2]  # peaks in the visible, falls in the near infrared
    mixel = Mixel(masks.sinusoid(2 * np.pi / 0.1e-3))
    lams = (500e-9, 600e-9, 700e-9)
    r = wave.angular_response(mixel, [[0.01, 0.0]], wavelengths_m=lams)
    singles = np.array([wave.angular_response(mixel, [[0.01, 0.0]], wavelengths_m=(v,))[0] for v in lams])
    assert r[0] == pytest.approx(float(wave.spectral_weights(lams) @ singles), rel=1e-12)
    with pytest.raises(ValueError, match="metres"):
        wave.angular_response(mixel, [[0.0, 0.0]], wavelengths_m=(550.0,))


def test_validity_warns_when_geometric_optics_is_off():
    ok = wave.validity(Mixel(masks.sinusoid(2 * np.pi / 0.2e-3)), warn=False)
    assert ok["ok"] and ok["u"] == pytest.approx(0.0275)
    assert 20 < ok["rim_onset_deg"] < 25  # the rim enters the view at atan(0.475) = 25.4 deg
    with pytest.warns(UserWarning, match="optics"):
        bad = wave.validity(Mixel(masks.sinusoid(2 * np.pi / 0.08e-3), detector_size_m=0.05e-3))
    assert not bad["ok"] and bad["u"] > 0.1


def test_quick_check_flags_fine_periods_and_printed_dots():
    assert wave.quick_check(Mixel(masks.sinusoid(2 * np.pi / 0.2e-3))) == []
    assert wave.quick_check(Mixel(masks.ramp("x"))) == []
    with pytest.warns(UserWarning, match="u = "):
        assert len(wave.quick_check(Mixel(masks.sinusoid(2 * np.pi / 0.08e-3)))) == 1
    printed = masks.PrintedFilm(dpi=600, halftone="ordered").print(masks.ramp("x"))
    with pytest.warns(UserWarning, match="printed dots"):
        assert len(wave.quick_check(Mixel(printed))) == 1
    assert wave.quick_check(Mixel(printed, optics="wave")) == []
    coarse = masks.PrintedFilm(dpi=100).print(masks.ramp("x"))  # 254 um dots: u = 0.017
    assert wave.quick_check(Mixel(coarse)) == []


def test_table_matches_direct_response_between_its_nodes():
    """The render table (1D factors on wavelength levels, bilinear between grid points) against direct solves."""
    mixel = Mixel(masks.sinusoid(2 * np.pi / 0.1e-3), detector_size_m=0.05e-3)
    table = wave.response_table(mixel, n_tan=257)
    i, j = np.array([10, 80, 128, 180, 240, 128]), np.array([6, 128, 154, 40, 220, 128])
    pts = np.column_stack([table.tan_x[j], table.tan_y[i]])
    direct = wave.angular_response(mixel, pts)
    # ~1e-3: the far rim's coherent ripple oscillates with wavelength faster than the table's levels follow
    np.testing.assert_allclose(table.wave[i, j], direct, atol=1e-3)
    assert np.max(np.abs(table.wave[i, j] - direct)) < 0.1 * np.max(np.abs(direct - table.geometric[i, j]))
    np.testing.assert_allclose(table.geometric[i, j], wave.geometric_response(mixel, pts), atol=1e-12)


# ------------------------------------------------------------------------------------------------ diffractio
def test_cross_check_against_diffractio():
    """An independent package: diffractio's Rayleigh-Sommerfeld propagation (Hankel kernel) of the same 1D masks.

    A printed row of 47 random dots (600 dpi: T = 0.9 or 0.02) and the open aperture, 2 mm at d_f = 2 mm, tilted
    plane waves; the detector average of |U|^2 over 0.1 mm, as a ratio to the open aperture (our y factor
    cancels). diffractio's own answer moves by ~4e-4 with its domain and sampling (the default sinusoid reads
    0.81775-0.81817 where the infinite-grating closed form gives 0.81808), hence the 1e-3 tolerance; the wave
    effect on the dots is 10-40 times larger.
    """
    pytest.importorskip("diffractio")
    from diffractio.scalar_masks_X import Scalar_mask_X
    from diffractio.scalar_sources_X import Scalar_source_X

    x_um = np.linspace(-2000, 2000, 1 << 14)
    rng = np.random.default_rng(1)
    dots_t = np.where(rng.random(47) < 0.5, 0.9, 0.02)
    idx = np.floor((x_um + 1000) / (2000 / 47)).astype(int)
    amp_dots = np.where((idx >= 0) & (idx < 47), np.sqrt(dots_t[np.clip(idx, 0, 46)]), 0.0)
    amp_open = (np.abs(x_um) <= 1000).astype(float)

    def detector_average(amp: np.ndarray, tan: float) -> float:
        u0 = Scalar_source_X(x_um, LAM * 1e6)
        u0.plane_wave(A=1, theta=-math.atan(tan))  # light travels opposite to the look direction
        m = Scalar_mask_X(x_um, LAM * 1e6)
        m.u = amp.astype(complex)
        u = (u0 * m).RS(z=2000.0, new_field=True, verbose=False).u
        return float(np.mean(np.abs(u[np.abs(x_um) <= 50]) ** 2))

    dots = Mixel(masks.Mask(np.tile(dots_t, (4, 1)), 2e-3, 2e-3, "dots", interpolation="nearest"))
    open_ = Mixel(masks.constant(1.0))
    effect = []
    for tan in (0.0, 0.1, 0.25):
        pts = [[tan, 0.0]]
        ours = wave.angular_response(dots, pts)[0] / wave.angular_response(open_, pts)[0]
        theirs = detector_average(amp_dots, tan) / detector_average(amp_open, tan)
        assert abs(ours - theirs) < 1e-3, (tan, ours, theirs)
        effect.append(abs(ours - wave.geometric_response(dots, pts)[0]))
    assert max(effect) > 0.02


# ------------------------------------------------------------------------------------------------ rendering
def _quadrature(mixel: Mixel, screen, frame: np.ndarray, response: np.ndarray, tan_x: np.ndarray,
                tan_y: np.ndarray, sub: int = 4) -> float:
    """E = sum_texels L int_texel R(t) cos(t_d) cos(t_s) / r^2 dA (directions from the detector centre)."""
    from scipy.interpolate import RegularGridInterpolator

    interp = RegularGridInterpolator((tan_y, tan_x), response, bounds_error=False, fill_value=0.0)
    rows, cols = screen.shape
    right, up, normal = (np.asarray(a) for a in screen.pose.axes())
    centre = np.asarray(screen.pose.position_m)
    u = (np.arange(cols * sub) + 0.5) / (cols * sub)
    v = (np.arange(rows * sub) + 0.5) / (rows * sub)
    xs, ys = np.meshgrid((u - 0.5) * screen.width_m, (0.5 - v) * screen.height_m)
    p = centre + xs[..., None] * right + ys[..., None] * up
    rot = mixel.pose.matrix()[:3, :3]
    d = p - np.asarray(mixel.pose.position_m)
    r2 = np.sum(d * d, axis=-1)
    local = d @ rot  # rows: d in the mixel's local frame
    cos_d = local[..., 2] / np.sqrt(r2)
    cos_s = -(d @ normal) / np.sqrt(r2)
    t = np.stack([local[..., 1] / local[..., 2], -local[..., 0] / local[..., 2]], axis=-1)  # (tan_y, tan_x)
    g = interp(t) * np.clip(cos_d, 0, None) * np.clip(cos_s, 0, None) / r2 * (screen.width_m * screen.height_m
                                                                             / (rows * cols * sub * sub))
    return float(np.sum(np.repeat(np.repeat(frame, sub, axis=0), sub, axis=1) * g))


def test_rendered_wave_measurement_matches_quadrature_of_the_response():
    """Response maps and the fast form with optics='wave' equal sum L R over the screen (R: the mixel's table).

    The renderer's rays cover the ray model's field of view only: light diffracted beyond it (R > 0 where the
    open fraction is 0) is not rendered; the quadrature is restricted to the same cone, and that spill is
    checked to be small (~4e-4 of the signal here).
    """
    from conftest import assert_close_mc

    from mincam_sim import Aperture, Budget, Simulation, single
    from mincam_sim.render.kernels.mask_eval import wave_table  # the ray model's table: the quadrature's integrand
    from mincam_sim.scene.display import Screen

    screen = Screen()
    mask = masks.sinusoid(2 * np.pi / 0.1e-3, phase_rad=0.7)
    cam_wave = single(mask, detector_size_m=0.05e-3, optics="wave")
    cam_geo = single(mask, detector_size_m=0.05e-3)
    rows, cols = screen.shape
    x = ((np.arange(cols) + 0.5) / cols - 0.5) * screen.width_m
    y = (0.5 - (np.arange(rows) + 0.5) / rows) * screen.height_m
    gx, gy = np.meshgrid(x, y)
    frame = 1.0 + 0.8 * np.cos(2 * np.pi * gx / 0.05) * (1 + 0.2 * np.sin(2 * np.pi * gy / 0.3))
    table = wave_table(cam_wave[0])
    in_cone = np.where(table.open > 0, table.wave, 0.0)
    expected_wave = _quadrature(cam_wave[0], screen, frame, in_cone, table.tan_x, table.tan_y)
    spill = _quadrature(cam_wave[0], screen, frame, table.wave, table.tan_x, table.tan_y) - expected_wave
    expected_geo = _quadrature(cam_geo[0], screen, frame, table.geometric, table.tan_x, table.tan_y)
    assert 0 <= spill < 1e-3 * expected_wave
    maps_budget = Budget(samples_per_texel=64, seed=3)
    m_wave = Simulation(cam_wave, screen=screen).response_maps(maps_budget).measure(frame)
    with pytest.warns(UserWarning, match="rendered with geometric optics"):  # u = 0.11: the quick check flags it
        m_geo = Simulation(cam_geo, screen=screen).response_maps(maps_budget).measure(frame)
    sigma = m_wave.stderr_w_m2[0, 0]
    assert abs(expected_wave - expected_geo) > 10 * sigma, "wave and geometric must be distinguishable here"
    assert_close_mc(m_wave.irradiance_w_m2[0, 0], expected_wave, sigma, what="wave response map")
    assert_close_mc(m_geo.irradiance_w_m2[0, 0], expected_geo, m_geo.stderr_w_m2[0, 0], what="geometric map")
    assert m_wave.meta["optics"][cam_wave[0].name]["optics"] == "wave"
    fast = Simulation(cam_wave, screen=screen).measure(frame, Aperture(), Budget(spp=1 << 21, replicates=16, seed=2))
    sigma_fast = fast.stderr_w_m2[0, 0]
    assert abs(expected_wave - expected_geo) > 5 * sigma_fast
    assert_close_mc(fast.irradiance_w_m2[0, 0], expected_wave, sigma_fast, what="wave fast form")


def test_reference_form_refuses_wave_optics():
    from mincam_sim import Reference, Simulation, single
    from mincam_sim.scene.display import Screen

    with pytest.raises(ValueError, match="reference form"):
        Simulation(single(masks.ramp("x"), optics="wave"), screen=Screen()).measure(Screen().blank(), Reference())


def test_config_selects_wave_optics():
    from mincam_sim.configuration.config import load_config
    from mincam_sim.errors import ConfigError

    cfg = load_config('[mincam]\noptics = "wave"\nwavelengths_m = [500e-9, 600e-9]\n')
    assert {m.optics for m in cfg.mincam} == {"wave"}
    assert cfg.mincam[0].wavelengths_m == (500e-9, 600e-9)
    assert {m.optics for m in load_config("").mincam} == {"geometric"}
    with pytest.raises(ConfigError, match=r"\[mincam\] optics"):
        load_config('[mincam]\noptics = "waves"\n')
    with pytest.raises(ConfigError, match="wavelengths_m"):
        load_config('[mincam]\nwavelengths_m = [550]\n')
    with pytest.raises(ConfigError, match="reference"):
        load_config('[run]\nform = "reference"\n[mincam]\noptics = "wave"\n')
    custom = load_config('[mincam]\nlayout = "custom"\n[[mixel]]\nmask = "ramp:x"\noptics = "wave"\n'
                         '[[mixel]]\nmask = "ramp:y"\nposition_m = [0.05, 0.0, 0.0]\n')
    assert [m.optics for m in custom.mincam] == ["wave", "geometric"]


def test_optics_enters_run_identities_only_when_not_default():
    from mincam_sim.storage.identity import canonical, fingerprint

    geo = Mixel(masks.ramp("x"))
    assert "optics" not in canonical(geo) and "wavelengths_m" not in canonical(geo)  # older stores stay valid
    assert fingerprint(geo.with_optics("wave")) != fingerprint(geo)
    assert fingerprint(geo.with_optics("wave", (500e-9,))) != fingerprint(geo.with_optics("wave"))


def test_wave_sizes_a_caller_types_are_one_input_error():
    """``max_cells = 3`` ran on a 14-cell grid and read a ramp 0.677 against 0.700 (3 %) without a word; an empty
    tan_theta and ``workers = 0`` were numpy's and scipy's ValueErrors."""
    from mincam_sim.errors import InputError

    mixel = Mixel(masks.ramp("x"))
    for kwargs, said in (({"max_cells": 3}, "max_cells must be None"), ({"max_cells": 1.5}, "max_cells must be"),
                         ({"workers": 0, "method": "2d"}, "workers must be an integer >= 1")):
        with pytest.raises(InputError, match=said):
            wave.angular_response(mixel, [[0.2, 0.0]], **kwargs)
    with pytest.raises(InputError, match=r"n >= 1, got shape \(0, 2\)"):
        wave.angular_response(mixel, np.zeros((0, 2)))
    r = wave.angular_response(mixel, [[0.2, 0.0]], max_cells=64)
    assert abs(r[0] - 0.7) < 0.005  # the fewest cells allowed still read the ramp within 0.2 %
