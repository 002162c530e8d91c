"""Every form unbiased on geometries that couple detector and screen, against independent float64 oracles
(:mod:`mincam_sim.oracles.quadrature`): tilted mixels, rotated screens, off-axis sinusoids, mixels that shadow each
other, a close occluder, exact masks. Tolerances: Z = 4.5 estimated standard errors (conftest)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import Z, assert_close_mc

import mincam_sim as ms
from mincam_sim import Mincam, Mixel, Pose, Screen, masks
from mincam_sim.masks import Mask
from mincam_sim.model.geometry import look_at
from mincam_sim.oracles.quadrature import mixel_irradiance_gl, open_aperture_view_factor_irradiance
from mincam_sim.render.kernels.map_tracing import response_maps  # the map kernel
from mincam_sim.scene.display import coverage

TILT_SCREEN = Screen(width_m=0.4, height_m=0.3, resolution=(80, 60),
                     pose=Pose((0.0, 0.0, -0.6), (np.sin(np.radians(25)), 0.0, np.cos(np.radians(25))), (0, 1, 0)))
SQUARE_M = (0.04, 0.07, 0.02, 0.05)  # screen coordinates (x0, x1, y0, y1), on texel edges (5 mm texels)


def _tilted_mixel(mask: Mask) -> Mixel:
    """A mixel off the axis, tilted to look at the square on the rotated screen."""
    target = TILT_SCREEN.to_world(0.055, 0.035)
    return Mixel(mask, pose=look_at((0.05, -0.02, 0.0), tuple(target), (0, 1, 0)), name="tilted")


SOLVERS = {"fast": ms.Aperture(), "reference": ms.Reference()}


def _render(cam: Mincam, screen: Screen, form: str, frames, spp: int, seed: int, replicates: int):
    """The aperture ("fast") or reference solver's measurements of ``frames`` (one frame or a list)."""
    frames = np.asarray(frames)
    budget = ms.Budget(spp=spp, replicates=replicates, seed=seed)
    return ms.Simulation(cam, screen=screen).measure(frames if frames.ndim == 3 else frames[None], SOLVERS[form],
                                                     budget)


def _square_frame(screen: Screen, region=SQUARE_M, radiance: float = 1.0) -> np.ndarray:
    return radiance * coverage(screen, *region)


SINUSOID_30 = masks.sinusoid(2 * np.pi / 0.4e-3, 0.5, 0.5, phase_rad=0.7, direction_deg=30.0)


@pytest.mark.parametrize("mask", [SINUSOID_30, masks.ramp("1-x")], ids=["sinusoid30", "ramp"])
def test_response_map_unbiased_on_coupled_geometry(mask):
    """Tilted mixel, rotated screen, off-centre square: the old fixed strata pairing was biased here
    (+0.5 % / 18 sigma for the sinusoid, -0.05 % / 9 sigma for the ramp)."""
    mixel = _tilted_mixel(mask)
    cam = Mincam((mixel,))
    expected = mixel_irradiance_gl(mixel, TILT_SCREEN, SQUARE_M, 1.0, n_detector=8, n_screen=24)
    maps = response_maps(cam, TILT_SCREEN, samples_per_texel=1024, seed=4, replicates=16)
    m = maps.measure(_square_frame(TILT_SCREEN))
    value, sigma = m.irradiance_w_m2[0, 0], m.stderr_w_m2[0, 0]
    assert sigma / expected < 5e-4, f"test too noisy to see a 0.05 % bias (sigma {sigma / expected:.2e})"
    assert_close_mc(value, expected, sigma, what="response map vs quadrature")


def test_fast_and_reference_unbiased_on_coupled_geometry():
    mixel = _tilted_mixel(SINUSOID_30)
    cam = Mincam((mixel,))
    expected = mixel_irradiance_gl(mixel, TILT_SCREEN, SQUARE_M, 2.0, n_detector=8, n_screen=24)
    frame = _square_frame(TILT_SCREEN, radiance=2.0)
    for form, spp in (("fast", 1 << 22), ("reference", 1 << 22)):
        m = _render(cam, TILT_SCREEN, form, frame, spp, 6, 16)
        assert m.stderr_w_m2[0, 0] / expected < 0.02
        assert_close_mc(m.irradiance_w_m2[0, 0], expected, m.stderr_w_m2[0, 0], what=f"{form} vs quadrature")


def test_response_map_sigma_matches_spread_over_seeds():
    """The reported standard error equals the spread of independent seeds (pooled chi-square over frames)."""
    cam = Mincam((_tilted_mixel(SINUSOID_30),))
    rng = np.random.default_rng(0)
    frames = np.stack([_square_frame(TILT_SCREEN), rng.uniform(0, 1, TILT_SCREEN.shape),
                       _square_frame(TILT_SCREEN, (0.0, 0.1, -0.05, 0.1)),
                       _square_frame(TILT_SCREEN, (0.05, 0.055, -0.15, 0.15))])  # a one-texel line
    values, sigmas = [], []
    for seed in range(10):
        m = response_maps(cam, TILT_SCREEN, samples_per_texel=16, seed=100 + seed).measure(frames)
        values.append(m.irradiance_w_m2[:, 0])
        sigmas.append(m.stderr_w_m2[:, 0])
    values, sigmas = np.array(values), np.array(sigmas)
    n = len(values)
    chi2 = np.sum((n - 1) * values.var(axis=0, ddof=1) / np.mean(sigmas**2, axis=0))
    dof = frames.shape[0] * (n - 1)
    assert abs(chi2 - dof) < Z * np.sqrt(2 * dof), f"chi2 {chi2:.1f} for {dof} dof: sigma does not match the spread"


# ------------------------------------------------------------------------------------------ mixels shadow
FRONT_SCREEN = Screen()  # 50", 0.5 m in front, facing the mincam


def _shadowing_pair() -> Mincam:
    """Mixel "back" at the origin; a larger mixel "front" (6 mm mask at 3 mm) whose body starts 10 mm in front
    of it, 4 mm to the side: it hides 27 % of the back mixel's view."""
    back = Mixel(masks.constant(1.0), pose=Pose((0.0, 0.0, 0.0), (0, 0, -1)), name="back")
    front = Mixel(masks.constant(1.0, width_m=6e-3), d_f_m=3e-3, pose=Pose((0.004, 0.0, -0.010), (0, 0, -1)),
                  name="front")
    return Mincam((back, front))


def _shadow_oracle(cam: Mincam, radiance: float) -> tuple[float, float]:
    back, front = cam
    shadowed = open_aperture_view_factor_irradiance(back, FRONT_SCREEN, radiance, [front.body_corners_m()])
    alone = open_aperture_view_factor_irradiance(back, FRONT_SCREEN, radiance)
    return shadowed, alone


@pytest.mark.parametrize("form", ["fast", "response_map", "reference"])
def test_mixels_shadow_each_other(form):
    """A mixel 10 mm in front of another hides part of its view in every form (the fast forms used to
    return the unshadowed value); the reference form also checks ray offsets with the occluder ~1 cm away."""
    cam = _shadowing_pair()
    radiance = 2.0
    expected, alone = _shadow_oracle(cam, radiance)
    assert expected < 0.8 * alone  # the shadow is large: an unshadowed form cannot pass
    frame = np.full(FRONT_SCREEN.shape, radiance)
    if form == "response_map":
        m = response_maps(cam, FRONT_SCREEN, samples_per_texel=16, seed=3).measure(frame)
    else:
        spp = 1 << 20 if form == "fast" else 1 << 23
        m = _render(cam, FRONT_SCREEN, form, frame, spp, 3, 16)
    value, sigma = m.irradiance_w_m2[0, 0], m.stderr_w_m2[0, 0]
    assert sigma / expected < 1e-3, f"{form}: sigma {sigma / expected:.1e} too large"
    assert_close_mc(value, expected, sigma, what=f"{form}: shadowed mixel vs view-factor oracle")
    front_alone = open_aperture_view_factor_irradiance(cam[1], FRONT_SCREEN, radiance)
    assert_close_mc(m.irradiance_w_m2[0, 1], front_alone, m.stderr_w_m2[0, 1], what=f"{form}: front mixel")


@pytest.mark.slow
def test_reference_form_has_no_ray_offset_bias_near_an_occluder():
    """Scene units of metres put geometry ~90 um closer after the mask: with the occluder 1 cm away that read
    -0.25 % (5.9 sigma at this sample count); the millimetre scene around each mixel must not."""
    cam = _shadowing_pair()
    expected, _ = _shadow_oracle(cam, 2.0)
    m = _render(cam, FRONT_SCREEN, "reference", np.full(FRONT_SCREEN.shape, 2.0), 1 << 25, 11, 16)
    value, sigma = m.irradiance_w_m2[0, 0], m.stderr_w_m2[0, 0]
    assert sigma / expected < 4e-4
    assert_close_mc(value, expected, sigma, what="reference near an occluder")


def test_intersecting_bodies_are_refused_unless_idealised():
    a = Mixel(masks.constant(1.0), name="a")
    b = Mixel(masks.constant(1.0), pose=Pose((0.001, 0.0, -0.001), (0, 0, -1)), name="b")
    with pytest.raises(ValueError, match="bodies of mixels 'a' and 'b' intersect.*allow_overlap"):
        Mincam((a, b))
    assert not Mincam((a, b), allow_overlap=True).occluding_bodies
    touching = Mixel(masks.constant(1.0), pose=Pose((0.002, 0.0, 0.0), (0, 0, -1)), name="c")
    assert Mincam((a, touching)).occluding_bodies  # side by side, walls touching: allowed


# ------------------------------------------------------------------------------------------ exact masks
def test_analytic_masks_are_exact_where_textures_lose_contrast():
    """The 0.2 mm-period speed sinusoid: evaluated exactly it matches the quadrature; read from its 256-texel
    array (bilinear), as before, it loses ~0.5 % of its contrast, which the same test detects (at a trough of
    the projected sinusoid, where the contrast matters most)."""
    screen = Screen(width_m=0.24, height_m=0.12, resolution=(96, 48))
    period = 0.2e-3
    exact = masks.sinusoid(2 * np.pi / period, 0.5, 0.5)
    raster = Mask(exact.transmission, exact.width_m, exact.height_m, "raster copy")
    region = (0.0125, 0.0375, -0.025, 0.025)  # half a projected period (50 mm at 0.5 m) around a trough
    frame = coverage(screen, *region)
    expected = mixel_irradiance_gl(Mixel(exact), screen, region, 1.0, n_detector=12, n_screen=24)
    results = {}
    for label, mask in (("exact", exact), ("raster", raster)):
        maps = response_maps(Mincam((Mixel(mask),)), screen, samples_per_texel=1024, seed=2, replicates=16)
        m = maps.measure(frame)
        results[label] = (m.irradiance_w_m2[0, 0], m.stderr_w_m2[0, 0], maps.meta["masks"])
    value, sigma, meta = results["exact"]
    assert sigma / expected < 5e-4
    assert_close_mc(value, expected, sigma, what="exact sinusoid vs quadrature")
    assert meta["mixel"]["discretisation_error"] == 0.0
    raster_value, raster_sigma, raster_meta = results["raster"]
    assert raster_meta["mixel"]["discretisation_error"] is None
    assert abs(raster_value - expected) > Z * raster_sigma, "the raster reading should be visibly biased here"


@pytest.mark.parametrize("form", ["fast", "reference"])
def test_fast_and_reference_sigma_match_spread_over_seeds(form):
    """The replicate standard error of the ray-traced forms equals the spread over independent seeds."""
    cam = Mincam((_tilted_mixel(SINUSOID_30),))
    frames = [_square_frame(TILT_SCREEN, radiance=2.0), _square_frame(TILT_SCREEN, (0.0, 0.1, -0.05, 0.1))]
    values, sigmas = [], []
    for seed in range(10):
        m = _render(cam, TILT_SCREEN, form, frames, 1 << 14, 200 + seed, 8)
        values.append(m.irradiance_w_m2[:, 0])
        sigmas.append(m.stderr_w_m2[:, 0])
    values, sigmas = np.array(values), np.array(sigmas)
    n = len(values)
    chi2 = np.sum((n - 1) * values.var(axis=0, ddof=1) / np.mean(sigmas**2, axis=0))
    dof = len(frames) * (n - 1)
    assert abs(chi2 - dof) < Z * np.sqrt(2 * dof), f"{form}: chi2 {chi2:.1f} for {dof} dof"
