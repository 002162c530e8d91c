"""The idealised dot-product model (``ms.DotProduct``): its normalisation against the closed form, the physics it
becomes effect by effect (against the quadrature oracle), its refusals, and the maps it and the response-map
solver export (NPY + JSON, from Python and from ``mincam-sim export-maps``)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

import mincam_sim as ms
from mincam_sim import masks
from mincam_sim.cli import app
from mincam_sim.errors import InputError
from mincam_sim.model.geometry import look_at
from mincam_sim.oracles.closed_forms import open_aperture_irradiance, point_to_parallel_rect
from mincam_sim.oracles.quadrature import mixel_irradiance_polygon
from mincam_sim.render import backend
from mincam_sim.render.solvers.dot_product import aperture_view_factor_pi
from mincam_sim.scene.display import coverage

SCREEN = ms.Screen(1.0, 1.0, (50, 50))  # 0.5 m away: fills the 53 degree field
RADIANCE = 2.0


def test_the_bare_model_of_an_open_mask_is_the_closed_form_at_the_centre_and_all_effects_the_physics():
    cam = ms.single(masks.constant(1.0))
    frame = np.full(SCREEN.shape, RADIANCE)
    sim = ms.Simulation(cam, screen=SCREEN)
    bare = sim.measure([frame], ms.DotProduct())
    centre = np.pi * RADIANCE * point_to_parallel_rect(-1e-3, 1e-3, -1e-3, 1e-3, 2e-3)
    np.testing.assert_allclose(bare.irradiance_w_m2[0, 0], centre, rtol=1e-12)
    # an open mask: the texels' rule is exact, and the error estimate is the sums' rounding alone
    assert 0 < bare.stderr_w_m2[0, 0] <= 2e-12 * centre and bare.meta["deterministic"]
    assert bare.meta["solver"] == "dot_product" and "cos^4 vignetting" in bare.meta["ignored"]
    assert bare.meta["reached_rel_stderr"] <= 2e-12
    full = sim.measure([frame], ms.DotProduct(parallax=True, vignetting=True, detector_blur=True))
    physics = open_aperture_irradiance(RADIANCE, 1e-4, 2e-3, 2e-3, 2e-3, (-0.5, 0.5, -0.5, 0.5), 0.5)
    np.testing.assert_allclose(full.irradiance_w_m2[0, 0], physics, rtol=1e-9)
    assert abs(full.irradiance_w_m2[0, 0] - physics) <= full.stderr_w_m2[0, 0] <= 1e-3 * physics
    assert abs(physics / centre - 1) > 1e-4  # the detector's size is seen: the two checks are different numbers


def _tilted(detector_size_m: float):
    screen = ms.Screen(0.6, 0.4, (60, 40), ms.Pose((0.02, 0.0, -0.5), (0.3, 0.0, 1.0)))
    mixel = ms.Mixel(masks.ramp("x"), detector_size_m=detector_size_m,
                     pose=look_at((0.03, 0.01, 0.0), tuple(screen.to_world(0.05, 0.02))), name="ramp")
    return mixel, screen


def test_parallax_and_vignetting_approach_the_quadrature_oracle_as_the_detector_shrinks():
    region = (-0.1, 0.15, -0.05, 0.1)  # texel edges: 1 cm texels
    deviations = []
    for size in (2e-4, 2e-5):
        mixel, screen = _tilted(size)
        frame = RADIANCE * coverage(screen, *region)
        expected = mixel_irradiance_polygon(mixel, screen, region, RADIANCE, n_detector=6, n_triangle=12)
        sim = ms.Simulation(ms.Mincam((mixel,)), screen=screen)
        model = sim.measure([frame], ms.DotProduct(parallax=True, vignetting=True)).irradiance_w_m2[0, 0]
        bare = sim.measure([frame], ms.DotProduct()).irradiance_w_m2[0, 0]
        deviations.append(abs(model / expected - 1))
        assert abs(bare / expected - 1) > 100 * deviations[-1]  # vignetting is what the bare model misses here
    assert deviations[1] < 1e-4 and deviations[1] < deviations[0] / 10  # ~ (detector / field)^2


@pytest.mark.slow
def test_a_large_detector_is_the_quadrature_oracle_within_the_error_estimate():
    """A 0.5 mm detector at d_f = 1 mm sweeps the field's edge over texels lit differently: the pinhole's
    measurement has a kink at each. Against the independent quadrature oracle (the detector in 16 x 16 panels of
    2 x 2 points) the error is within the estimate with one detector cell and with four, where it is smaller."""
    screen = ms.Screen(2.0, 2.0, (40, 40))  # 5 cm texels; the field's edge at x = 0.5 m
    mixel = ms.Mixel(masks.ramp("x"), d_f_m=1e-3, detector_size_m=5e-4, name="big")
    regions = {(0.3, 0.5, -0.2, 0.0): 1.0, (0.5, 0.7, -0.2, 0.0): 3.0, (0.3, 0.5, 0.0, 0.2): 2.0,
               (0.5, 0.7, 0.0, 0.2): 4.0}
    frame = sum(radiance * coverage(screen, *region) for region, radiance in regions.items())
    oracle = sum(mixel_irradiance_polygon(mixel, screen, region, radiance, n_detector=2, n_triangle=6,
                                          detector_panels=16) for region, radiance in regions.items())
    sim = ms.Simulation(ms.Mincam((mixel,)), screen=screen)
    errors, estimates = [], []
    for cells in (1, 4):
        m = sim.measure([frame], ms.DotProduct(parallax=True, vignetting=True, detector_blur=True,
                                               detector_cells=cells))
        errors.append(abs(m.irradiance_w_m2[0, 0] - oracle))
        estimates.append(m.stderr_w_m2[0, 0])
        assert errors[-1] <= estimates[-1], (cells, errors[-1] / oracle, estimates[-1] / oracle)
    assert errors[0] > 1e-4 * oracle  # one cell's error is real, and now said
    assert errors[1] < errors[0] / 4 and estimates[1] < estimates[0] / 4


@pytest.mark.parametrize("seed", range(4))
def test_the_detector_error_estimate_covers_the_error_on_random_set_ups(seed):
    """A ramp mask blurred by a random detector (0.1-0.5 mm at d_f 1-2 mm) on random frames, against the same
    model with finer rules (the detector in 6 x 6 cells of 3 x 3 points, texels split twice as finely). Over 37
    blurred values of a probe (16 x 9 to 64 x 36 texels; ramp and raster masks) the estimate was below the error
    once, for a raster mask; the raster masks' texel estimate is not covered here: it was below the error in 18 of
    100 random set-ups (docs/ideal_model.md)."""
    from mincam_sim.render.solvers.dot_product import _pinhole_weights, detector_rule

    rng = np.random.default_rng(seed)
    screen = ms.Screen(1.107, 0.623, (16, 9))
    mixel = ms.Mixel(masks.ramp("x"), d_f_m=float(rng.choice([1e-3, 2e-3])),
                     detector_size_m=float(rng.choice([1e-4, 3e-4, 5e-4])), name="m")
    frame = rng.uniform(0, 2, screen.shape)
    m = ms.Simulation(ms.Mincam((mixel,)), screen=screen).measure(
        [frame], ms.DotProduct(parallax=True, vignetting=True, detector_blur=True))
    rot, origin = mixel.pose.matrix()[:3, :3], np.asarray(mixel.pose.position_m, dtype=np.float64)
    finer = sum(w * _pinhole_weights(mixel, screen, origin + rot @ np.array([a, b, 0.0]), rot, (a, b), None, 4, 2)
                for a, b, w in detector_rule(mixel.detector_size_m, 6, 3))
    error = abs(m.irradiance_w_m2[0, 0] - float((finer * frame).sum()))
    assert 0 < error <= m.stderr_w_m2[0, 0], (error, m.stderr_w_m2[0, 0])


def test_parallax_moves_each_mixels_field_by_its_offset():
    """Two mixels 4 cm apart: from the centre both see the same field; with parallax each sees it shifted."""
    cam = ms.pair_layout(spacing_m=0.04)
    sim = ms.Simulation(cam, screen=SCREEN)
    maps = {p: ms.DotProduct(parallax=p).maps(cam, SCREEN).weights_sr for p in (False, True)}
    np.testing.assert_allclose(maps[False][0], maps[False][1][:, ::-1], rtol=1e-12)  # one field, mirrored masks
    centroid = {p: (maps[p] * SCREEN.texel_centers_m()[0]).sum(axis=(1, 2)) / maps[p].sum(axis=(1, 2))
                for p in maps}
    shift = centroid[True] - centroid[False]
    offsets = np.array([m.pose.position_m[0] for m in cam]) - cam.centre_m[0]
    np.testing.assert_allclose(shift, offsets, atol=2e-3)  # 2 cm each way, within a tenth of a texel
    ones = sim.measure([np.ones(SCREEN.shape)], ms.DotProduct(parallax=True))  # a ramp: only the sums round
    assert np.all(ones.stderr_w_m2 <= 2e-12 * ones.irradiance_w_m2)


def test_bad_options_and_wave_optics_are_refused():
    with pytest.raises(InputError, match="nodes must be an integer"):
        ms.DotProduct(nodes=0)
    with pytest.raises(InputError, match="detector_blur needs nodes >= 2"):
        ms.DotProduct(detector_blur=True, nodes=1)
    for cells in (0, 33, 2.0, True):
        with pytest.raises(InputError, match="detector_cells must be an integer from 1 to 32"):
            ms.DotProduct(detector_blur=True, detector_cells=cells)
    with pytest.raises(InputError, match="parallax must be True or False"):
        ms.DotProduct(parallax="yes")
    wave = ms.Mincam((ms.Mixel(masks.constant(1.0), optics="wave"),))
    with pytest.raises(InputError, match="optics = 'wave'"):
        ms.Simulation(wave, screen=SCREEN).measure([np.ones(SCREEN.shape)], ms.DotProduct())


# ------------------------------------------------------------------------------------------------ maps out
def _frames(screen: ms.Screen) -> np.ndarray:
    rng = np.random.default_rng(3)
    return np.stack([rng.random(screen.shape), RADIANCE * coverage(screen, -0.1, 0.05, -0.2, 0.1)])


def _from_export(out, frames: np.ndarray) -> np.ndarray:
    sidecar = json.loads((out / "maps.json").read_text())
    maps = [np.load(out / sidecar["files"][name]["map"]) for name in sidecar["mixel_names"]]
    return np.array([[np.sum(w * f) for w in maps] for f in frames])


def test_exported_ideal_maps_measure_what_the_solver_measures(tmp_path):
    cam = ms.pair_layout(spacing_m=0.033)
    sim = ms.Simulation(cam, screen=SCREEN)
    frames = _frames(SCREEN)
    sidecar = sim.export_maps(tmp_path, solver=ms.DotProduct(parallax=True), psf_grid=(5, 4))
    m = sim.measure(frames, ms.DotProduct(parallax=True))
    np.testing.assert_allclose(_from_export(tmp_path, frames), m.irradiance_w_m2, rtol=1e-12)
    meta = json.loads(sidecar.read_text())
    assert meta["screen"]["resolution"] == [50, 50] and meta["screen"]["position_m"] == [0.0, 0.0, -0.5]
    assert meta["units"]["map"].startswith("sr") and meta["source"]["form"] == "dot_product"
    assert [x["name"] for x in meta["geometry"]["mixels"]] == cam.names
    a = np.load(tmp_path / "forward_matrix.npy")
    np.testing.assert_allclose(a @ frames[0].ravel(), m.irradiance_w_m2[0], rtol=1e-12)
    psfs = np.load(tmp_path / "psfs.npy")
    assert psfs.shape == (4, 5, 2) and meta["psfs"]["shape"] == [4, 5, 2]
    # a point source of intensity I at a grid point: the texel holding it at radiance I / texel area
    x, y = meta["psfs"]["points_x_m"][1], meta["psfs"]["points_y_m"][2]
    j, i = int((x / SCREEN.width_m + 0.5) * 50), int((0.5 - y / SCREEN.height_m) * 50)
    point = np.zeros(SCREEN.shape)
    point[i, j] = 1.0 / SCREEN.texel_area_m2
    np.testing.assert_allclose(psfs[2, 1], sim.measure([point], ms.DotProduct(parallax=True)).irradiance_w_m2[0])


@pytest.mark.skipif(not backend.is_jit(), reason="needs a JIT variant (LLVM or CUDA)")
def test_exported_response_maps_measure_what_the_solver_measures_and_the_cli_writes_them(tmp_path):
    screen = ms.Screen(1.0, 1.0, (24, 24))
    cam = ms.pair_layout(spacing_m=0.033)
    sim = ms.Simulation(cam, screen=screen)
    budget = ms.Budget(samples_per_texel=16, replicates=4, seed=2)
    frames = _frames(screen)
    sim.export_maps(tmp_path / "py", budget)
    m = sim.measure(frames, ms.ResponseMap(), budget)
    np.testing.assert_allclose(_from_export(tmp_path / "py", frames), m.irradiance_w_m2, rtol=1e-12)
    stderr = np.load(tmp_path / "py" / "maps" / f"{cam.names[0]}_stderr.npy")
    assert stderr.shape == screen.shape and stderr.max() > 0

    config = tmp_path / "c.toml"
    config.write_text('[run]\nsolver = "response_map"\nsamples_per_texel = 16\n'
                      '[screen]\nresolution = [32, 18]\n')
    r = CliRunner().invoke(app, ["export-maps", str(config), "--out", str(tmp_path / "cli"), "--psf-grid", "3",
                                 "3", "--ideal"])
    assert r.exit_code == 0, r.output
    meta = json.loads((tmp_path / "cli" / "maps.json").read_text())
    assert meta["source"]["form"] == "dot_product" and np.load(tmp_path / "cli" / "psfs.npy").shape[:2] == (3, 3)
    bad = CliRunner().invoke(app, ["export-maps", str(config), "--out", str(tmp_path / "bad"), "--psf-grid", "0",
                                   "3"])
    assert bad.exit_code == 2 and "error: --psf-grid" in bad.output


def test_export_refuses_bad_input(tmp_path):
    sim = ms.Simulation(ms.single(masks.constant(1.0)), screen=SCREEN)
    with pytest.raises(InputError, match="psf_grid must be two positive integers"):
        sim.export_maps(tmp_path, solver=ms.DotProduct(), psf_grid=(0, 3))
    cols, rows = SCREEN.resolution  # a finer grid only repeats texels (20000 x 20000 was killed at 24 GB)
    with pytest.raises(InputError, match=rf"{cols + 1} x {rows} is finer than the screen's {cols} x {rows} texels"):
        sim.export_maps(tmp_path, solver=ms.DotProduct(), psf_grid=(cols + 1, rows))
    assert not any(tmp_path.iterdir())  # refused before anything is written
    with pytest.raises(InputError, match="ResponseMap or DotProduct"):
        sim.export_maps(tmp_path, solver=ms.Aperture())


# ------------------------------------------------------------------------------------------- from TOML
def test_a_display_file_names_the_model_and_its_options_and_measures_what_python_measures(tmp_path):
    from mincam_sim.configuration.config import load_config

    cfg = load_config('[run]\nsolver = "dot_product"\n[run.dot_product]\nparallax = true\nvignetting = true\n'
                      "[screen]\nresolution = [32, 18]\n[frames]\nn = 4\n")
    assert cfg.run.solver == ms.DotProduct(parallax=True, vignetting=True)
    assert load_config('[run]\nsolver = "dot_product"\n').run.solver == ms.DotProduct()  # the bare model
    config = tmp_path / "ideal.toml"
    config.write_text('[run]\nsolver = "dot_product"\nout_dir = "out"\n[run.dot_product]\nparallax = true\n'
                      "[screen]\nresolution = [32, 18]\n[frames]\nn = 4\n")
    r = CliRunner().invoke(app, ["render", str(config)])
    assert r.exit_code == 0, r.output
    written = np.load(tmp_path / "out" / "measurements.npz")["irradiance_w_m2"]
    python = ms.Simulation(cfg.mincam, screen=cfg.screen).measure(cfg.frames, ms.DotProduct(parallax=True))
    np.testing.assert_allclose(written, python.irradiance_w_m2, rtol=1e-12)
    np.testing.assert_allclose(np.load(tmp_path / "out" / "measurements.npz")["stderr_w_m2"], python.stderr_w_m2,
                               rtol=1e-12)


def test_a_display_file_refuses_bad_model_options_and_says_which_keys_it_ignores():
    from mincam_sim.configuration.config import load_config
    from mincam_sim.configuration.schema import IgnoredSettingWarning
    from mincam_sim.configuration.world_config import load_world_config
    from mincam_sim.errors import ConfigError

    for table, message in (("nodes = 99", r"\[run.dot_product\] nodes must be an integer from 1 to 16"),
                           ("paralax = true", r"unknown key paralax \(did you mean parallax\?\)"),
                           ("vignetting = 1", r"\[run.dot_product\] vignetting must be")):
        with pytest.raises(ConfigError, match=message):
            load_config(f'[run]\nsolver = "dot_product"\n[run.dot_product]\n{table}\n')
    with pytest.warns(IgnoredSettingWarning, match=r"\[run.dot_product\] parallax is ignored: .*\"aperture\""):
        load_config('[run]\nsolver = "aperture"\n[run.dot_product]\nparallax = true\n')
    with pytest.warns(IgnoredSettingWarning,
                      match=r"\[run\] spp is ignored: solver = \"dot_product\" is deterministic"):
        load_config('[run]\nsolver = "dot_product"\nspp = 1000\n')
    with pytest.raises(ConfigError, match="does not solve world scenes"):
        load_world_config('[run]\nsolver = "dot_product"\n[world]\nscene = "x.xml"\n')


# ------------------------------------------------------------------------------ the finding, reproduced
def _calibrated_on_model_tested_on_physics(layout: str, spacing_m: float, models: dict) -> dict:
    """``layout`` at 0.5 m calibrated on each of ``models`` and on the physics, tested on the physics (the code
    of docs/ideal_model.md's table, at its sizes); error rates in % of the 50 cm field by label."""
    from mincam_sim.experiments.ideal_model import calibrated_on_models

    return calibrated_on_models(layout, spacing_m, 0.5, models).errors


@pytest.mark.slow
@pytest.mark.skipif(not backend.is_jit(), reason="needs a JIT variant (LLVM or CUDA)")
def test_calibrating_on_the_ideal_model_misses_the_physics_by_the_field_of_view_offset():
    """The issue's finding (docs/ideal_model.md): ~2 % of the field for the bare model with the pair 3.3 cm apart,
    <= 0.1 % with co-located mixels, <= 0.3 % once parallax and vignetting are in the model."""
    closer = ms.DotProduct(parallax=True, vignetting=True)
    spaced = _calibrated_on_model_tested_on_physics("pair", 0.033, {"bare": ms.DotProduct(), "closer": closer})
    assert 1.8 < spaced["bare"]["avg_error_pct"] < 2.6 and spaced["bare"]["max_error_pct"] < 4.0
    assert spaced["closer"]["avg_error_pct"] <= 0.3 and spaced["closer"]["max_error_pct"] <= 0.3
    co_located = _calibrated_on_model_tested_on_physics("pair", 0.0, {"bare": ms.DotProduct()})["bare"]
    assert co_located["avg_error_pct"] <= 0.1 and co_located["max_error_pct"] <= 0.2


@pytest.mark.slow
@pytest.mark.skipif(not backend.is_jit(), reason="needs a JIT variant (LLVM or CUDA)")
def test_the_tracking_cross_calibrated_on_the_ideal_model_misses_the_physics_until_parallax_and_vignetting():
    """The cross (each mixel 3.3 cm from the centre, so each ratio's mixels are 6.6 cm apart) at 0.5 m: the bare
    model's calibration misses the physics by far more than the physics' own floor (calibrated on itself), and
    co-located mixels do not; with parallax and vignetting the model is within 3 times that floor."""
    models = {"bare": ms.DotProduct(), "parallax": ms.DotProduct(parallax=True),
              "closer": ms.DotProduct(parallax=True, vignetting=True)}
    spaced = _calibrated_on_model_tested_on_physics("cross", 0.033, models)
    floor = spaced["physics"]["avg_error_pct"]
    assert 0 < floor < 0.1 and spaced["physics"]["max_error_pct"] < 0.2
    assert 5.0 < spaced["bare"]["avg_error_pct"] < 8.0 and spaced["bare"]["avg_error_pct"] > 100 * floor
    assert spaced["closer"]["avg_error_pct"] <= 3 * floor and spaced["closer"]["max_error_pct"] <= 0.2
    assert spaced["closer"]["avg_error_pct"] < spaced["parallax"]["avg_error_pct"] < spaced["bare"]["avg_error_pct"]
    co_located = _calibrated_on_model_tested_on_physics("cross", 0.0, {"bare": ms.DotProduct()})["bare"]
    assert co_located["avg_error_pct"] <= 0.1 and co_located["max_error_pct"] <= 0.2


@pytest.mark.parametrize("where", ["behind the screen", "passes through mixel 'm0''s body"])
def test_the_idealised_model_refuses_what_the_ray_solvers_refuse(where):
    """A mixel behind the screen, or a screen through its body: one InputError from every display solver (the
    dot product, which builds no scene, measured 0 and 0.34 W/m^2 there)."""
    turned = np.radians(89.9)
    forward, up = (np.sin(turned), 0.0, np.cos(turned)), (0.0, 1.0, 0.0)
    screen = ms.Screen(resolution=(16, 9), pose=(ms.Pose((0.0, 0.0, -0.5), (0.0, 0.0, -1.0)) if "behind" in where
                                                 else ms.Pose((0.0, 0.0, -0.5), forward, up)))
    sim = ms.Simulation(ms.single(), screen=screen)
    for solver in (ms.DotProduct(parallax=True, vignetting=True, detector_blur=True), ms.ResponseMap()):
        with pytest.raises(InputError, match=where):
            sim.measure([np.ones(screen.shape)], solver=solver)


def test_export_maps_ideal_uses_the_files_model_options(tmp_path):
    """``export-maps --ideal`` exports the model the file's ``[run.dot_product]`` names (it was the bare model
    whatever the file said)."""
    config = tmp_path / "c.toml"
    config.write_text('[run]\nsolver = "dot_product"\n[run.dot_product]\nparallax = true\nvignetting = true\n'
                      "[screen]\nresolution = [16, 9]\n")
    r = CliRunner().invoke(app, ["export-maps", str(config), "--out", str(tmp_path / "out"), "--ideal"])
    assert r.exit_code == 0, r.output
    meta = json.loads((tmp_path / "out" / "maps.json").read_text())
    assert meta["source"]["effects"] == ["parallax", "vignetting"]


# ------------------------------------------------------------------------------------------ raster masks, exactly
def _hat_integrals(edges_lo: np.ndarray, edges_hi: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """(n, len(knots)): the integral over [lo, hi] of each clamped hat function of the knots (1 at its knot, 0 at
    the others, linear between, flat beyond the ends), exactly, by the trapezoid rule on every breakpoint."""
    out = np.zeros((len(edges_lo), len(knots)))
    for t, (lo, hi) in enumerate(zip(edges_lo, edges_hi, strict=True)):
        if hi <= lo:
            continue
        x = np.unique(np.concatenate([[lo, hi], knots[(knots > lo) & (knots < hi)]]))
        for j in range(len(knots)):
            y = np.interp(x, knots, np.eye(len(knots))[j])
            out[t, j] = np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(x))
    return out


def _box_integrals(edges_lo: np.ndarray, edges_hi: np.ndarray, cell_edges: np.ndarray) -> np.ndarray:
    """(n, cells): the length of [lo, hi] inside each cell [cell_edges[j], cell_edges[j + 1]]."""
    lo = np.maximum(edges_lo[:, None], cell_edges[None, :-1])
    hi = np.minimum(edges_hi[:, None], cell_edges[None, 1:])
    return np.clip(hi - lo, 0, None)


@pytest.mark.parametrize("interpolation", ["nearest", "bilinear"])
def test_a_raster_mask_is_integrated_exactly_over_every_texels_image(interpolation):
    """The bare model of a random 23 x 17-texel raster mask (nearest or bilinear) before a parallel 40 x 30-texel
    screen, 0.37 m away and off axis, a random frame: every screen texel's image on the mask plane is a rectangle,
    and the transmission's integral over it is closed form (nearest: the overlaps with each mask texel; bilinear:
    products of clamped hat functions' integrals), with no code shared with the model. The model agrees to 1e-12
    (it cuts each image along the mask's kinks or jumps; splitting images into equal parts, as it did, was 1e-4
    off), and its error estimate is the sums' rounding."""
    rng = np.random.default_rng(11)
    t = rng.uniform(0.05, 1.0, (17, 23))
    mask = masks.from_array(t, width_m=2e-3, height_m=1.6e-3, interpolation=interpolation)
    screen = ms.Screen(0.48, 0.36, (40, 30), ms.Pose((0.05, -0.03, -0.37), (0.0, 0.0, 1.0)))
    cam = ms.single(mask)
    frame = rng.uniform(0.0, 3.0, screen.shape)
    got = ms.Simulation(cam, screen=screen).measure([frame], ms.DotProduct())
    mixel = cam[0]
    d_f, w, h = mixel.d_f_m, mask.width_m, mask.height_m
    # the image of screen point (x, y, -z) seen from the mincam's centre on the mask plane, d_f in front of it
    # (between the detector and the screen: not inverted); the mixel looks down -z with +y up, so "x right as
    # seen from the detector" is the world's +x
    z = 0.37
    xe = 0.05 + (np.arange(41) / 40 - 0.5) * 0.48  # the screen's texel edges, columns left to right
    ye = -0.03 + (0.5 - np.arange(31) / 30) * 0.36  # rows from the top
    img_x, img_y = xe * d_f / z, ye * d_f / z
    x_lo, x_hi = (np.clip(v, -w / 2, w / 2) for v in (img_x[:-1], img_x[1:]))
    y_lo, y_hi = (np.clip(v, -h / 2, h / 2) for v in (img_y[1:], img_y[:-1]))
    rows, cols = t.shape
    up_to_rows = slice(None, None, -1)  # ascending y is the mask's rows from the bottom
    if interpolation == "nearest":
        fx = _box_integrals(x_lo, x_hi, -w / 2 + np.arange(cols + 1) * w / cols)
        fy = _box_integrals(y_lo, y_hi, -h / 2 + np.arange(rows + 1) * h / rows)[:, up_to_rows]
    else:
        fx = _hat_integrals(x_lo, x_hi, -w / 2 + (np.arange(cols) + 0.5) * w / cols)
        fy = _hat_integrals(y_lo, y_hi, -h / 2 + (np.arange(rows) + 0.5) * h / rows)[:, up_to_rows]
    integral = fy @ t @ fx.T  # (screen rows, screen cols): int T dA over each screen texel's image [m^2]
    expected = aperture_view_factor_pi(mixel) / mask.area_m2 * np.sum(integral * frame)
    assert got.irradiance_w_m2[0, 0] == pytest.approx(expected, rel=1e-12)
    assert got.stderr_w_m2[0, 0] <= 1e-11 * expected
