"""Audit of the display geometry: the exact visibility check (:func:`mincam_sim.scene.display.check_visible`), the
exact-shadow quadrature oracle (:func:`mincam_sim.oracles.quadrature.mixel_irradiance_polygon`) against closed forms,
and every render form against that oracle on geometries the other tests never used (tilted and rolled mixels,
off-axis screens cut by the view, a screen a few mask widths away, d_f from 0.05 mm to 60 mm, 2 x 3 mm masks,
a ramp and an off-axis sinusoid). Monte Carlo tolerances: Z = 4.5 estimated standard errors (conftest)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_close_mc

from mincam_sim import Aperture, Budget, Mincam, Mixel, Pose, Reference, ResponseMap, Screen, Simulation, masks, single
from mincam_sim.model.geometry import look_at
from mincam_sim.model.optics import cross_layout, pair_layout
from mincam_sim.oracles.closed_forms import open_aperture_irradiance
from mincam_sim.oracles.quadrature import (
    mixel_irradiance_gl,
    mixel_irradiance_polygon,
    open_aperture_view_factor_irradiance,
    visible_polygon_screen_m,
)
from mincam_sim.scene.display import check_visible


def _old_grid_sees(screen: Screen, mixel: Mixel) -> bool:
    """The check this replaces: a 65 x 65 grid of screen points against the widest rays from the origin."""
    xs, ys = np.meshgrid(np.linspace(-0.5, 0.5, 65) * screen.width_m, np.linspace(-0.5, 0.5, 65) * screen.height_m)
    local = mixel.pose.to_local(screen.to_world(xs, ys).reshape(-1, 3))
    tx, ty = mixel.half_fov_tan()
    z = local[:, 2]
    return bool(np.any((z > mixel.d_f_m) & (np.abs(local[:, 0]) <= tx * z) & (np.abs(local[:, 1]) <= ty * z)))


# ------------------------------------------------------------------------------------------ check_visible
def _corner_sliver_screen(depth_m: float) -> tuple[Screen, Mixel]:
    """A 1 m screen at 0.5 m, rolled 45 deg, whose straight edge cuts the corner of the mixel's square view by
    ``depth_m`` (along the diagonal, x + y), shifted half a grid step along that edge so that the sliver lies
    between the old check's grid points."""
    mixel = Mixel(masks.constant(1.0), name="m0")
    tx, _ = mixel.half_fov_tan()
    z = 0.5
    a = tx * z - mixel.detector_size_m / 2  # exact half-width of the view at the screen (world x = -local x)
    side = 1.0
    u = np.array([1.0, 1.0, 0.0]) / np.sqrt(2)  # the screen's x axis: cross(up, forward)
    v = np.array([-1.0, 1.0, 0.0]) / np.sqrt(2)  # the screen's y axis
    edge_mid = np.array([a - depth_m / 2, a - depth_m / 2, -z])  # on the line x + y = 2a - depth
    centre = edge_mid + side / 2 * u + side / 128 * v
    screen = Screen(side, side, (32, 32), Pose(tuple(centre), (0.0, 0.0, 1.0), tuple(v)))
    return screen, mixel


def test_visible_sliver_between_grid_points_is_accepted():
    """The old grid refused this valid set-up; the exact check accepts it, and the oracle sees light there."""
    screen, mixel = _corner_sliver_screen(2e-3)
    assert not _old_grid_sees(screen, mixel), "construction: the sliver should fall between the old grid points"
    check_visible(screen, [mixel])
    assert mixel_irradiance_polygon(mixel, screen, None, 1.0, n_detector=8, n_triangle=6) > 0


def test_view_boundary_is_exact():
    """A point is seen iff |x| <= tx z - s/2 (union of the detector points' pyramids): a screen 1 um inside that
    boundary is accepted (and seen through the aperture from the far detector edge), 1 um outside it refused (and
    seen from no detector point), though the widest-ray pyramid from the origin (50 um wider) contains both."""
    mixel = Mixel(masks.constant(1.0), name="m0")
    tx, _ = mixel.half_fov_tan()
    z = 0.5
    edge = tx * z - mixel.detector_size_m / 2
    for margin_m, visible in ((1e-6, True), (-1e-6, False)):
        x0 = edge - margin_m  # left edge (world x) of a 0.2 m screen on the right of the view
        screen = Screen(0.2, 0.2, (8, 8), Pose((x0 + 0.1, 0.0, -z), (0.0, 0.0, 1.0)))
        # the detector edge opposite the screen (local x = +s/2; world x is -local x) is the only one that could
        corner = mixel.pose.to_world(np.array([mixel.detector_size_m / 2, 0.0, 0.0]))
        seen = visible_polygon_screen_m(mixel, screen, corner, (-0.1, 0.1, -0.1, 0.1))
        assert _old_grid_sees(screen, mixel)
        if visible:
            check_visible(screen, [mixel])
            assert len(seen) >= 3
        else:
            with pytest.raises(ValueError, match="outside mixel 'm0'.*field of view.*point the mixel"):
                check_visible(screen, [mixel])
            assert len(seen) == 0


@pytest.mark.parametrize(
    "pose",
    [Pose((0.0, 0.0, -0.001), (0.0, 0.0, 1.0)),  # parallel, inside the housing (z = 1 mm of 2 mm)
     Pose((0.0, 0.0, -0.0015), (0.6, 0.0, 1.0)),  # oblique, cutting the housing and the mask plane
     Pose((0.0008, 0.0, -0.001), (-1.0, 0.0, 0.0))],  # edge-on: a plane through the body along its axis
    ids=["parallel", "oblique", "edge-on"],
)
def test_screen_through_body_is_refused(pose):
    mixel = Mixel(masks.constant(1.0), name="m0")
    screen = Screen(0.01, 0.01, (8, 8), pose)
    with pytest.raises(ValueError, match="passes through mixel 'm0'.*body.*move the screen"):
        check_visible(screen, [mixel])


def test_screen_on_the_mask_plane_or_just_beyond_is_not_a_body_intersection():
    mixel = Mixel(masks.constant(1.0), name="m0")
    beyond = Screen(0.01, 0.01, (8, 8), Pose((0.0, 0.0, -0.0021), (0.0, 0.0, 1.0)))
    check_visible(beyond, [mixel])  # 0.1 mm beyond the mask: a close but valid screen
    on_mask = Screen(0.01, 0.01, (8, 8), Pose((0.0, 0.0, -0.002), (0.0, 0.0, 1.0)))
    with pytest.raises(ValueError, match="outside mixel 'm0'"):  # touching, not through; sees nothing beyond
        check_visible(on_mask, [mixel])


def test_behind_the_screen_is_still_refused():
    with pytest.raises(ValueError, match="behind the screen"):
        check_visible(Screen(pose=Pose((0, 0, -0.5), (0, 0, -1))), single())


def test_usual_setups_stay_accepted():
    screen = Screen()
    rolled = Pose((0.02, -0.01, 0.0), (0.3, 0.2, -1.0), (0.5, 1.0, 0.0))
    tilted = Screen(0.4, 0.3, (80, 60), Pose((0.0, 0.0, -0.6), (np.sin(np.radians(25)), 0.0, np.cos(np.radians(25)))))
    for cam in (single(), pair_layout(), cross_layout(), single(masks.ramp("x"), pose=rolled),
                cross_layout(center=look_at((0.1, 0.05, 0.0), (-0.05, 0.0, -0.5), (0.3, 1.0, 0.0)))):
        check_visible(screen, cam)
    check_visible(tilted, [Mixel(masks.ramp("1-x"), pose=look_at((0.05, -0.02, 0.0),
                                                                   tuple(tilted.to_world(0.055, 0.035))))])


# ------------------------------------------------------------------------------------------ the oracle
@pytest.mark.parametrize(
    "offset_m, distance_m, d_f_m, size_m",
    [((0.0, 0.0), 0.5, 2e-3, (2e-3, 2e-3)), ((0.3, 0.12), 0.5, 2e-3, (2e-3, 2e-3)),
     ((0.01, -0.004), 0.008, 2e-3, (2e-3, 3e-3)), ((0.0, 0.0), 0.3, 5e-5, (2e-4, 3e-4)),
     ((0.25, 0.0), 0.5, 0.06, (4e-3, 6e-3))],
    ids=["on-axis", "screen-edge", "close-2x3", "short-df", "long-df"],
)
def test_polygon_oracle_matches_closed_form_view_factor(offset_m, distance_m, d_f_m, size_m):
    """Open aperture, parallel uniform screen: E = pi L F (closed form, same detector nodes) to 1e-9."""
    mixel = Mixel(masks.constant(1.0, width_m=size_m[0], height_m=size_m[1]), d_f_m=d_f_m,
                  pose=Pose((*offset_m, 0.0), (0.0, 0.0, -1.0)))
    screen = Screen(pose=Pose((0.0, 0.0, -distance_m), (0.0, 0.0, 1.0)))
    sx, sy = -offset_m[0], offset_m[1]  # viewer-right -> mixel-left flips x
    rect = (sx - screen.width_m / 2, sx + screen.width_m / 2, -sy - screen.height_m / 2, -sy + screen.height_m / 2)
    expected = open_aperture_irradiance(2.0, mixel.detector_size_m, *size_m, d_f_m, rect, distance_m, order=12)
    value = mixel_irradiance_polygon(mixel, screen, None, 2.0, n_detector=12, n_triangle=16, subdivisions=2)
    assert expected > 0
    assert abs(value / expected - 1) < 1e-9, f"oracle {value} vs closed form {expected}"


def test_polygon_oracle_matches_view_factor_oracle_tilted_close_non_square():
    """Tilted, rolled mixel with a 2 x 3 mm open aperture; rotated screen 12 mm away whose edge cuts the view."""
    mixel = Mixel(masks.constant(1.0, width_m=2e-3, height_m=3e-3),
                  pose=Pose((0.0, 0.0, 0.0), (0.5, 0.1, -0.866), (0.5, 1.0, 0.0)))
    screen = Screen(0.03, 0.02, (32, 18), Pose((0.004, 0.002, -0.012), (0.3, -0.2, 1.0), (0.2, 1.0, 0.0)))
    expected = open_aperture_view_factor_irradiance(mixel, screen, 1.0, n_detector=12)
    value = mixel_irradiance_polygon(mixel, screen, None, 1.0, n_detector=12, n_triangle=12)
    assert abs(value / expected - 1) < 1e-9


def test_polygon_oracle_agrees_with_gl_where_gl_is_smooth_and_converges():
    """Where the region lies wholly inside the aperture's view (no moving edge), both quadratures agree; the
    polygon oracle's own refinements (more nodes, subdivided triangles) agree to 1e-9 on a masked, tilted case."""
    screen = Screen(0.4, 0.3, (80, 60), Pose((0.0, 0.0, -0.6), (np.sin(np.radians(25)), 0.0, np.cos(np.radians(25)))))
    mask = masks.sinusoid(2 * np.pi / 0.4e-3, 0.5, 0.5, phase_rad=0.7, direction_deg=30.0)
    mixel = Mixel(mask, pose=look_at((0.05, -0.02, 0.0), tuple(screen.to_world(0.055, 0.035))))
    region = (0.04, 0.07, 0.02, 0.05)
    gl = mixel_irradiance_gl(mixel, screen, region, 1.0, n_detector=8, n_screen=24)
    poly = mixel_irradiance_polygon(mixel, screen, region, 1.0, n_detector=8, n_triangle=16)
    assert abs(poly / gl - 1) < 1e-9
    whole = mixel_irradiance_polygon(mixel, screen, None, 1.0, n_detector=8, n_triangle=16)
    finer = mixel_irradiance_polygon(mixel, screen, None, 1.0, n_detector=8, n_triangle=24, subdivisions=1)
    assert abs(finer / whole - 1) < 1e-9


# ------------------------------------------------------------------------------------------ forms vs oracle
def _geometry(name: str) -> tuple[Mixel, Screen]:
    """Geometries never used elsewhere; in each the screen's edge cuts the mixel's view (checked below)."""
    if name == "tilt30-rolled-sinusoid":
        screen = Screen(0.36, 0.2, (32, 18), Pose((0.12, -0.05, -0.45), (-0.3, 0.1, 1.0), (0.1, 1.0, 0.0)))
        mask = masks.sinusoid(2 * np.pi / 0.5e-3, 0.5, 0.4, phase_rad=1.1, direction_deg=30.0)
        return Mixel(mask, pose=look_at((-0.1, 0.04, 0.02), tuple(screen.to_world(0.03, 0.02)), (0.4, 1.0, 0.0)),
                     name="tilt30"), screen
    if name == "close-2x3-ramp-tilt20":
        screen = Screen(0.032, 0.018, (32, 18), Pose((0.006, 0.004, -0.009), (0.15, 0.0, 1.0), (-0.2, 1.0, 0.0)))
        mask = masks.ramp("x", 64, width_m=2e-3, height_m=3e-3)
        return Mixel(mask, pose=Pose((0.0, 0.0, 0.0), (np.sin(np.radians(20)), 0.0, -np.cos(np.radians(20))),
                                     (0.3, 1.0, 0.0)), name="close"), screen
    if name == "short-df-0.05mm-sinusoid":
        screen = Screen(0.32, 0.18, (32, 18), Pose((0.05, 0.02, -0.1), (0.0, 0.0, 1.0)))
        mask = masks.sinusoid(2 * np.pi / 0.1e-3, 0.5, 0.5, phase_rad=0.3, direction_deg=60.0, width_m=2e-4,
                              height_m=3e-4)
        return Mixel(mask, d_f_m=5e-5, pose=Pose((0.0, 0.0, 0.0), (0.35, 0.2, -1.0), (0.2, 1.0, 0.0)),
                     name="short"), screen
    if name == "long-df-60mm-ramp":
        screen = Screen(0.32, 0.18, (32, 18), Pose((0.16, 0.0, -0.5), (-0.2, 0.0, 1.0)))
        mask = masks.ramp("y", 64, width_m=4e-3, height_m=6e-3)
        return Mixel(mask, d_f_m=0.06, pose=Pose((0.0, 0.0, 0.0), (0.0, 0.1, -1.0), (0.3, 1.0, 0.0)),
                     name="long"), screen
    raise KeyError(name)


GEOMETRIES = ["tilt30-rolled-sinusoid", "close-2x3-ramp-tilt20", "short-df-0.05mm-sinusoid", "long-df-60mm-ramp"]
FORMS = [("response_map", {"samples_per_texel": 1024}), ("fast", {"spp": 1 << 22}), ("reference", {"spp": 1 << 22})]
# brute-force reference rays rarely pass a 4 x 6 mm aperture 60 mm away: 2^25 rays (~20 s) for sigma < 1 %
CASES = [pytest.param(name, form, {"spp": 1 << 25}, marks=pytest.mark.slow, id=f"{name}-{form}")
         if (name, form) == ("long-df-60mm-ramp", "reference") else pytest.param(name, form, kw, id=f"{name}-{form}")
         for name in GEOMETRIES for form, kw in FORMS]


def _oracle(mixel: Mixel, screen: Screen) -> float:
    return mixel_irradiance_polygon(mixel, screen, None, 1.0, n_detector=12, n_triangle=16, detector_panels=2)


@pytest.mark.parametrize("name", GEOMETRIES)
def test_geometry_is_valid_and_cut_by_the_screen_edge(name):
    """Each geometry passes check_visible, and the screen's edge cuts the view (a screen 10x larger gives more
    light), so the region's edges and the aperture's moving shadow both matter; the oracle has converged."""
    mixel, screen = _geometry(name)
    check_visible(screen, [mixel])
    value = _oracle(mixel, screen)
    big = Screen(10 * screen.width_m, 10 * screen.height_m, screen.resolution, screen.pose)
    assert _oracle(mixel, big) > 1.05 * value > 0
    coarse = mixel_irradiance_polygon(mixel, screen, None, 1.0, n_detector=8, n_triangle=12)
    assert abs(coarse / value - 1) < 1e-4, f"oracle not converged: {coarse} vs {value}"


@pytest.mark.parametrize("name, form, kw", CASES)
def test_forms_match_exact_shadow_oracle(name, form, kw):
    """Uniform white screen whose edge cuts the view: each form within 4.5 sigma of the exact-shadow oracle,
    with sigma < 1 % (response maps: ~0.05-0.15 %, fast ~0.05-0.3 %, reference ~0.05-0.5 %)."""
    mixel, screen = _geometry(name)
    expected = _oracle(mixel, screen)
    frame = np.ones((1, *screen.shape))  # uniform white (radiance 1): the oracle's region is the whole screen
    solver = {"response_map": ResponseMap(), "fast": Aperture(), "reference": Reference()}[form]
    m = Simulation(Mincam((mixel,)), screen=screen).measure(frame, solver, Budget(seed=11, replicates=16, **kw))
    value, sigma = m.irradiance_w_m2[0, 0], m.stderr_w_m2[0, 0]
    assert sigma / expected < 0.01, f"{form} too noisy to mean anything (sigma {sigma / expected:.2e})"
    assert_close_mc(value, expected, sigma, what=f"{form} on {name} vs exact-shadow quadrature")


def test_response_map_noise_falls_with_samples_per_texel():
    """64x the samples per texel cut the (honest) standard error by more than 2x (the terms that couple
    different axes average over k random pairs: ~64^-1/4 = 0.35x; measured 0.25x). With one random shift per
    block in place of the permutations, a block converged to one line of strata pairs, and sigma stayed at
    5.8e-4 -> 5.1e-4 (relative) from 256 to 65,536 samples per texel."""
    mixel, screen = _geometry("close-2x3-ramp-tilt20")
    sigma = {}
    for spt in (256, 16384):
        budget = Budget(samples_per_texel=spt, seed=5, replicates=4)
        maps = Simulation(Mincam((mixel,)), screen=screen).response_maps(budget)
        sigma[spt] = float(np.sqrt(maps.variance_sr2[0].sum()))
    assert sigma[16384] < 0.5 * sigma[256], f"sigma {sigma[256]:.3g} -> {sigma[16384]:.3g} with 64x the samples"
