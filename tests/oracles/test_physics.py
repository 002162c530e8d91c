"""Physics of rendered mixels against closed forms and invariants.

Every Monte Carlo tolerance is Z = 4.5 standard errors of the estimator (see conftest), seeds fixed.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import Z, assert_close_mc
from scipy.optimize import curve_fit

from mincam_sim import Aperture, Budget, Mincam, Mixel, Pose, Reference, Screen, Simulation, masks, single
from mincam_sim.oracles.closed_forms import open_aperture_irradiance
from mincam_sim.scene.display import vertical_line, white_square

SPP = 1 << 18
REPLICATES = 16
SOLVERS = {"fast": Aperture(), "reference": Reference()}


def render(cam, screen, form, frames, spp, seed, replicates=REPLICATES):
    """The frames measured by the aperture ("fast") or the reference solver."""
    budget = Budget(spp=spp, replicates=replicates, seed=seed)
    return Simulation(cam, screen=screen).measure(frames, SOLVERS[form], budget)


def response_maps(cam, screen, samples_per_texel, seed):
    return Simulation(cam, screen=screen).response_maps(Budget(samples_per_texel=samples_per_texel, seed=seed))


def closed_form(screen: Screen, mixel: Mixel, radiance: float = 1.0) -> float:
    """Open-aperture irradiance for a mixel facing a parallel screen (mixel frame: x left, screen x right)."""
    sx, sy = -mixel.pose.position_m[0], mixel.pose.position_m[1]  # viewer-right -> mixel-left flips x
    distance = mixel.pose.position_m[2] - screen.pose.position_m[2]
    rect = (sx - screen.width_m / 2, sx + screen.width_m / 2, -sy - screen.height_m / 2, -sy + screen.height_m / 2)
    return open_aperture_irradiance(
        radiance, mixel.detector_size_m, mixel.mask.width_m, mixel.mask.height_m, mixel.d_f_m, rect, distance
    )


@pytest.mark.parametrize("offset_m", [(0.0, 0.0), (0.3, 0.12)], ids=["on-axis", "clipped-by-screen-edge"])
@pytest.mark.parametrize("form", ["fast", "reference", "response_map"])
def test_open_aperture_matches_view_factor(form, offset_m):
    """E = pi L F, F the closed-form view factor of the screen part seen through the aperture."""
    cam = single(masks.constant(1.0), pose=Pose((*offset_m, 0.0), (0, 0, -1)))
    screen = Screen()
    radiance = 2.0
    frame = np.full(screen.shape, radiance)
    expected = closed_form(screen, cam[0], radiance)
    if form == "response_map":
        m = response_maps(cam, screen, samples_per_texel=16, seed=1).measure(frame)
    else:
        m = render(cam, screen, form, frame, SPP, seed=1)
    value, sigma = m.irradiance_w_m2[0, 0], m.stderr_w_m2[0, 0]
    assert sigma / expected < 0.01, "test too noisy to mean anything"
    assert_close_mc(value, expected, sigma, what=f"{form} open aperture")


def _two_squares(screen):
    a = white_square(screen, (-0.1, 0.05), 0.08, 3.0)
    b = white_square(screen, (0.12, -0.08), 0.12, 1.5)
    return a, b


@pytest.mark.parametrize("form", ["fast", "reference"])
def test_linearity_in_scene_radiance(form):
    """P(A + B) = P(A) + P(B), frames rendered with independent seeds."""
    screen = Screen()
    cam = single(masks.ramp("x"))
    a, b = _two_squares(screen)
    spp = SPP if form == "fast" else 8 * SPP  # the literal scene wastes most rays on the housing and mask
    pa = render(cam, screen, form, a, spp, seed=11)
    pb = render(cam, screen, form, b, spp, seed=12)
    pab = render(cam, screen, form, a + b, spp, seed=13)
    lhs = pab.irradiance_w_m2[0, 0]
    rhs = pa.irradiance_w_m2[0, 0] + pb.irradiance_w_m2[0, 0]
    sigma = np.sqrt(pab.stderr_w_m2[0, 0] ** 2 + pa.stderr_w_m2[0, 0] ** 2 + pb.stderr_w_m2[0, 0] ** 2)
    assert sigma / lhs < 0.02
    assert_close_mc(lhs, rhs, sigma, what=f"{form} superposition")


@pytest.mark.parametrize("form", ["fast", "reference"])
def test_complementary_and_scaled_masks(form):
    """P(x) + P(1 - x) = P(1) and P(k x) = k P(x) on a non-uniform frame."""
    screen = Screen()
    gx, gy = screen.texel_centers_m()
    frame = 1.0 + 0.8 * np.sin(6 * gx) * np.cos(4 * gy)
    ramp = masks.ramp("x", 64)
    results = {}
    for label, mask in {"x": ramp, "1-x": ramp.complement(), "1": masks.constant(1.0), "kx": ramp.scaled(0.3)}.items():
        m = render(single(mask), screen, form, frame, SPP, seed=hash(label) % 1000)
        results[label] = (m.irradiance_w_m2[0, 0], m.stderr_w_m2[0, 0])
    (px, sx), (pc, sc), (p1, s1), (pk, sk) = (results[k] for k in ("x", "1-x", "1", "kx"))
    assert_close_mc(px + pc, p1, np.sqrt(sx**2 + sc**2 + s1**2), what="complementary masks")
    assert_close_mc(pk, 0.3 * px, np.sqrt(sk**2 + (0.3 * sx) ** 2), what="scaled mask")


def test_mask_orientation_projects_without_inversion():
    """A mask open only in its top-right quadrant sees only the screen's top-right quadrant (as the viewer
    in front of the mixel sees it): lensless masks do not invert the scene."""
    quadrant = masks.from_function(lambda x, y: ((x > 0.5) & (y > 0.5)).astype(float), "top-right", 64)
    screen = Screen()
    cam = single(quadrant)
    frames = [white_square(screen, (sx * 0.12, sy * 0.12), 0.1) for sx, sy in ((1, 1), (-1, 1), (1, -1), (-1, -1))]
    m = render(cam, screen, "reference", frames, SPP, seed=3)
    top_right, others = m.irradiance_w_m2[0, 0], m.irradiance_w_m2[1:, 0]
    assert top_right > 20 * m.stderr_w_m2[0, 0]  # clearly lit (the reference form has ~2 % noise here)
    assert np.all(others == 0.0)
    maps = response_maps(cam, screen, samples_per_texel=4, seed=3).weights_sr[0]
    gx, gy = screen.texel_centers_m()
    # The quadrant's edge is blurred on the screen by the detector (0.1 mm -> 12 mm at 0.5 m) and by the
    # bilinear mask texture (1 texel of 31 um -> 8 mm): beyond 3 cm from the edges the map is exactly 0.
    assert maps[(gx > 0.03) & (gx < 0.2) & (gy > 0.03) & (gy < 0.2)].min() > 0  # inside the 0.25 m half-FOV
    assert np.all(maps[(gx < -0.03) | (gy < -0.03)] == 0.0)


def _sinusoid_frequency(positions_m, response, guess):
    def model(x, a0, a1, omega, phi):
        return a0 + a1 * np.cos(omega * x + phi)

    a1 = 0.5 * (response.max() - response.min())
    best = None
    for phi in np.linspace(0, 2 * np.pi, 8, endpoint=False):
        try:
            p, cov = curve_fit(model, positions_m, response, p0=[response.mean(), a1, guess, phi])
        except RuntimeError:
            continue
        res = np.sum((model(positions_m, *p) - response) ** 2)
        if best is None or res < best[0]:
            best = (res, p, cov)
    assert best is not None
    return best[1][2], np.sqrt(best[2][2, 2])


@pytest.mark.parametrize("depth_m", [0.5, 1.0])
def test_sinusoid_mask_frequency_scales_with_depth(depth_m):
    """A thin bright line swept across a screen at depth d modulates a sinusoid-mask mixel with the
    scene-side frequency omega_df d_f / d (paper Eq. 10), emerging from the ray geometry (within 1 %)."""
    period_mask_m = 0.4e-3
    omega_df = 2 * np.pi / period_mask_m
    d_f = 2e-3
    sin_mask = masks.sinusoid(omega_df, 0.5, 0.5, resolution=512)
    screen = Screen(width_m=1.2, height_m=1.2, resolution=(480, 8), pose=Pose((0, 0, -depth_m), (0, 0, 1)))
    cam = Mincam((Mixel(sin_mask, d_f, name="sin"), Mixel(masks.constant(1.0), d_f, name="open")),
                 allow_overlap=True)  # co-located: each rendered as if alone
    maps = response_maps(cam, screen, samples_per_texel=16, seed=5)
    gx, _ = screen.texel_centers_m()
    x = gx[0]
    lines = np.stack([vertical_line(screen, xc, screen.texel_size_m[0]) for xc in x])
    p = maps.measure(lines).irradiance_w_m2
    half_fov = (sin_mask.width_m / 2) * depth_m / d_f
    keep = (np.abs(x) < 0.8 * half_fov) & (p[:, 1] > 0)
    ratio = p[keep, 0] / p[keep, 1]  # divide out the cos^4-like envelope of the open aperture
    expected = omega_df * d_f / depth_m
    omega, omega_sigma = _sinusoid_frequency(x[keep], ratio, expected)
    assert abs(omega / expected - 1) < 0.01, f"omega {omega:.3f} vs {expected:.3f} rad/m (fit sigma {omega_sigma:.3g})"


def test_field_of_view_offset_equals_baseline():
    """Two identical mixels a baseline b apart see response curves shifted by b on the screen (chi-square
    test of c2(X) against c1(X - b) over all line positions)."""
    screen = Screen(width_m=1.2, height_m=0.6, resolution=(240, 6))
    texel = screen.texel_size_m[0]
    baseline = 10 * texel  # 5 cm: an integer number of texels so the comparison needs no interpolation
    ramp = masks.ramp("x", 64)
    cam = Mincam((
        Mixel(ramp, pose=Pose((-baseline / 2, 0, 0), (0, 0, -1)), name="left"),
        Mixel(ramp, pose=Pose((baseline / 2, 0, 0), (0, 0, -1)), name="right"),
    ))
    maps = response_maps(cam, screen, samples_per_texel=32, seed=7)
    curves = maps.weights_sr.sum(axis=1)  # response to a full-height line at each column
    sig = np.sqrt(maps.variance_sr2.sum(axis=1))
    c1, c2 = curves[0, :-10], curves[1, 10:]
    s = np.hypot(sig[0, :-10], sig[1, 10:])
    live = s > 0
    chi2 = np.sum(((c2 - c1)[live] / s[live]) ** 2)
    n = int(live.sum())
    assert n > 50
    assert chi2 < n + Z * np.sqrt(2 * n), f"chi2 {chi2:.1f} for {n} points"
    x = screen.texel_centers_m()[0][0]
    centroid = (curves * x).sum(axis=1) / curves.sum(axis=1)
    assert abs((centroid[1] - centroid[0]) - baseline) < 0.02 * baseline


def test_fast_and_reference_agree_on_ramp_and_square():
    """The fast form (rays start on the aperture) equals the literal scene within Monte Carlo error."""
    screen = Screen()
    cam = single(masks.ramp("1-y", 64))
    frames = [white_square(screen, (0.05, 0.1), 0.1), white_square(screen, (-0.15, -0.05), 0.06, 2.0)]
    fast = render(cam, screen, "fast", frames, SPP, seed=2)
    ref = render(cam, screen, "reference", frames, 4 * SPP, seed=2)
    sigma = np.hypot(fast.stderr_w_m2, ref.stderr_w_m2)
    assert np.all(sigma / ref.irradiance_w_m2 < 0.05)
    assert_close_mc(fast.irradiance_w_m2, ref.irradiance_w_m2, sigma, what="fast vs reference")


@pytest.mark.slow
@pytest.mark.parametrize("form", ["fast", "reference"])
def test_open_aperture_high_precision(form):
    """The closed form to ~1e-4 relative (2^24 samples): no bias at the level of float32 films."""
    cam = single(masks.constant(1.0))
    screen = Screen()
    frame = np.ones(screen.shape)
    expected = closed_form(screen, cam[0])
    m = render(cam, screen, form, frame, 1 << 24, seed=21)
    assert_close_mc(m.irradiance_w_m2[0, 0], expected, m.stderr_w_m2[0, 0], what=f"{form} high precision")


def test_response_maps_match_reference_on_unseen_frames():
    """Maps built once predict the literal scene's measurement of new frames (texture + squares) within the
    combined standard error."""
    screen = Screen()
    cam = single(masks.ramp("x", 64))
    maps = response_maps(cam, screen, samples_per_texel=64, seed=8)
    rng = np.random.default_rng(4)
    frames = [rng.uniform(0, 1, screen.shape), white_square(screen, (0.08, -0.1), 0.12, 2.0)]
    ref = render(cam, screen, "reference", frames, 4 * SPP, seed=9)
    pred = maps.measure(np.stack(frames))
    sigma = np.hypot(ref.stderr_w_m2, pred.stderr_w_m2)
    assert np.all(sigma / ref.irradiance_w_m2 < 0.02)
    assert_close_mc(pred.irradiance_w_m2, ref.irradiance_w_m2, sigma, what="response map vs reference")


def test_scalar_fallback_reference_form_matches_closed_form():
    """The scalar_rgb fallback (no LLVM, no GPU) renders the literal scene correctly; the fast form, a Python
    plugin, refuses it with a clear message (run in a subprocess: the variant is per process)."""
    import json
    import os
    import subprocess
    import sys

    code = (
        "import json, numpy as np\n"
        "import mincam_sim as ms\n"
        "from mincam_sim import Screen, masks, single\n"
        "sim = ms.Simulation(single(masks.constant(1.0)), screen=Screen())\n"
        "m = sim.measure(np.ones(Screen().shape), ms.Reference(), ms.Budget(spp=1 << 17, replicates=8, seed=0))\n"
        "try:\n"
        "    sim.measure(np.ones(Screen().shape), ms.Aperture())\n"
        "    err = ''\n"
        "except RuntimeError as e:\n"
        "    err = str(e)\n"
        "print(json.dumps([float(m.irradiance_w_m2[0, 0]), float(m.stderr_w_m2[0, 0]), m.meta['variant'], err]))\n"
    )
    env = {**os.environ, "MINCAM_VARIANT": "scalar_rgb"}
    out = subprocess.run([sys.executable, "-c", code], env=env, check=True, capture_output=True, text=True)
    value, sigma, variant, err = json.loads(out.stdout.strip().splitlines()[-1])
    assert variant == "scalar_rgb"
    assert_close_mc(value, closed_form(Screen(), single()[0]), sigma, what="scalar_rgb reference")
    assert "vectorised Mitsuba variant" in err
