"""The front door: Simulation + solvers + Budget + typed results, and Run outside the numerics."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import trimesh

import mincam_sim as ms
from mincam_sim.errors import InputError, StaleResultError
from mincam_sim.render.kernels.map_tracing import response_maps
from mincam_sim.render.kernels.monte_carlo import replicate_mean_stderr
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.mincam_scene import MincamScene
from mincam_sim.render.scene.updates import vertex_update


def _frames(screen, n=3):
    return ms.line_sweep((-0.15, 0.0), (0.15, 0.0), n=n, size_m=0.04).frame_stack(screen)


def test_display_measure_is_the_kernels_bit_for_bit():
    """The ResponseMap solver is the map kernel's product with the frames (its maps kept as ``m.maps``); the
    Aperture solver the fast kernel's replicates frame by frame."""
    cam, screen = ms.pair_layout(), ms.Screen()
    sim = ms.Simulation(cam, screen=screen)
    m = sim.measure(_frames(screen), solver=ms.ResponseMap(), budget=ms.Budget(samples_per_texel=16, seed=3))
    ref = response_maps(cam, screen, 16, 3, replicates=4).measure(_frames(screen))
    np.testing.assert_array_equal(m.irradiance_w_m2, ref.irradiance_w_m2)
    np.testing.assert_array_equal(m.stderr_w_m2, ref.stderr_w_m2)
    np.testing.assert_array_equal(m.maps.measure(_frames(screen)).irradiance_w_m2, ref.irradiance_w_m2)
    assert m.meta["solver"] == "response_map"
    m = sim.measure(_frames(screen), solver=ms.Aperture(), budget=ms.Budget(spp=1 << 14, seed=3))
    scene = MincamScene.display(cam, screen)
    for frame, values, errors in zip(_frames(screen), m.irradiance_w_m2, m.stderr_w_m2, strict=True):
        scene.set_frame(frame)
        mean, err = replicate_mean_stderr(scene.fast_estimates(1 << 14, 8, 3))
        np.testing.assert_array_equal(values, mean)
        np.testing.assert_array_equal(errors, err)
    assert m.meta["solver"] == "aperture" and m.maps is None


def _world_parts():
    box = trimesh.creation.box((0.04, 0.04, 0.04))
    v = box.vertices + [5.0, 5.0, 0.02]
    elements = {"floor": {"type": "rectangle", "bsdf": {"type": "diffuse"}},
                "lamp": sd.area_light(0.3, 0.3, ms.Pose((0, 0, 1.0), (0, 0, -1)).matrix(), 10.0),
                "toy": sd.mesh_object("toy", v, box.faces, 0.9)}
    frames = [vertex_update("toy", v - [5.0, 5.0, 0.0] + [x, 0.02, 0.0]) for x in (-0.08, 0.05)]
    cam = ms.cross_layout(center=ms.Pose((0.0, 0.0, 0.4), (0, 0, -1), (0, 1, 0)))
    return cam, elements, frames


@pytest.mark.parametrize("solver", [ms.StratifiedChange(), ms.PlainChange()], ids=["stratified", "plain"])
def test_world_changes_are_typed(solver):
    cam, elements, frames = _world_parts()
    ch = ms.Simulation(cam, world=elements).measure_changes(frames, solver=solver, budget=ms.Budget(spp=1 << 12))
    assert isinstance(ch.info, ms.RunInfo) and ch.dp.meta["solver"] == solver.name
    assert ch.info.solver == solver.name and ch.info.rays_per_mixel_per_frame > 0
    assert ch.info.reached_rel_stderr is not None and ch.info.replicates == 8
    assert np.all(np.abs(ch.dp.irradiance_w_m2) > 3 * ch.dp.stderr_w_m2)


def test_world_measure_gives_absolute_p_per_update():
    cam, elements, frames = _world_parts()
    sim = ms.Simulation(cam, world=elements)
    m = sim.measure(frames, budget=ms.Budget(spp=1 << 14))
    ch = sim.measure_changes(frames, solver=ms.PlainChange(), budget=ms.Budget(spp=1 << 14))
    sigma = np.hypot(m.stderr_w_m2, ch.p.stderr_w_m2)
    assert np.all(np.abs(m.irradiance_w_m2 - ch.p.irradiance_w_m2) < 4.5 * sigma)


def test_run_keeps_resumes_and_refuses(tmp_path):
    cam, elements, frames = _world_parts()
    sim = ms.Simulation(cam, world=elements)
    with ms.Run(tmp_path / "out") as run:
        first = run.measure_changes(sim, frames, budget=ms.Budget(spp=1 << 12))
    with ms.Run(tmp_path / "out") as run:  # a rerun of the same run: reused, same numbers
        again = run.measure_changes(sim, frames, budget=ms.Budget(spp=1 << 12))
    np.testing.assert_array_equal(first.dp.irradiance_w_m2, again.dp.irradiance_w_m2)
    loaded = ms.Changes.load_npz(tmp_path / "out" / "measurements.npz")
    assert loaded.info == first.info
    np.testing.assert_array_equal(loaded.dp.stderr_w_m2, first.dp.stderr_w_m2)
    header = (tmp_path / "out" / "measurements.csv").read_text().splitlines()[1]
    assert header.startswith("frame,") and "_dP_w_m2" in header and "_P_stderr_w_m2" in header
    with ms.Run(tmp_path / "out") as run, pytest.raises(StaleResultError):
        run.measure_changes(sim, frames, budget=ms.Budget(spp=1 << 12, seed=1))
    with pytest.raises(InputError, match="with-block"):
        ms.Run(tmp_path / "x").measure(sim, frames)


@pytest.mark.parametrize("make, message", [
    (lambda: ms.Budget(spp=0), "Budget.spp must be an integer > 0"),
    (lambda: ms.Budget(spp=4, replicates=8), "fewer than its 8 replicates"),
    (lambda: ms.Budget(target_rel_stderr=-1e-3), "target_rel_stderr"),
    (lambda: ms.Budget(replicates=1), "replicates must be an integer >= 2"),
    (lambda: ms.Budget(seed=1.5), "seed"),
    (lambda: ms.Simulation(ms.pair_layout()), "exactly one"),
    (lambda: ms.Simulation(ms.pair_layout(), screen=ms.Screen()).measure_changes([]), "does not solve display"),
    (lambda: ms.Simulation(ms.pair_layout(), screen=ms.Screen()).measure([], ms.PlainChange()), "does not solve"),
    (lambda: ms.Simulation(ms.pair_layout(), screen=ms.Screen()).measure([], solver="fast"), "solver must be"),
    (lambda: ms.Simulation(ms.pair_layout(), world="no/such/room.xml"), "does not exist"),
])
def test_front_door_errors_name_the_fix(make, message):
    with pytest.raises(InputError, match=message):
        make()


def test_import_stays_pure_numpy_until_the_renderer_is_used():
    code = ("import sys, mincam_sim as ms\nb = ms.Budget(spp=64)\n"
            "assert 'mitsuba' not in sys.modules and 'drjit' not in sys.modules\n"
            "ms.Simulation\nassert 'mincam_sim.render.simulation' in sys.modules\n")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_max_spp_caps_the_target_search_and_the_run_says_so():
    """``Budget.max_spp`` is the cap of the ray solvers' target search: an unreachable target stops there, and the
    result and a warning say that the target was missed."""
    cam = ms.pair_layout(spacing_m=0.033)
    screen = ms.Screen(resolution=(16, 9))
    sim = ms.Simulation(cam, screen=screen)
    frame = np.ones(screen.shape)
    with pytest.warns(UserWarning, match="target"):
        m = sim.measure([frame], ms.Aperture(), ms.Budget(target_rel_stderr=1e-7, max_spp=1 << 15, seed=1))
    assert m.meta["spp"] <= 1 << 15


@pytest.mark.parametrize("frames, said", [
    ([], "got no frame"), ([np.zeros((18, 32)), np.zeros((9, 32))], "each of one (rows, cols) shape"),
    (None, "got NoneType"), (np.array([["a"]]), "real numbers"), (np.zeros((1, 1, 18, 32)), "shape (1, 1, 18, 32)"),
])
def test_display_frames_of_no_image_form_are_one_input_error(frames, said):
    """Each was numpy's ValueError ("need at least one array to stack", ...) or a TypeError from deep in the frame
    source, with every solver."""
    sim = ms.Simulation(ms.pair_layout(), screen=ms.Screen(resolution=(32, 18)))
    for solver in (ms.ResponseMap(), ms.DotProduct(), ms.Aperture()):
        with pytest.raises(InputError, match=f"frames must be radiance images.*{re_escape(said)}"):
            sim.measure(frames, solver=solver, budget=ms.Budget(spp=64) if isinstance(solver, ms.Aperture) else None)


def test_display_radiance_beyond_a_float32_is_refused_by_every_solver():
    """1e308 is finite, but Mitsuba's textures hold 32-bit floats: the aperture solver's sigma became NaN and an
    internal check on the result fired; the map solvers called it NaN. Now one InputError that says why."""
    sim = ms.Simulation(ms.pair_layout(), screen=ms.Screen(resolution=(32, 18)))
    for solver in (ms.ResponseMap(), ms.DotProduct(), ms.Aperture()):
        with pytest.raises(InputError, match=r"too large|beyond a 32-bit float"):
            sim.measure(np.full((1, 18, 32), 1e308), solver=solver,
                        budget=ms.Budget(spp=64) if isinstance(solver, ms.Aperture) else None)


def test_mask_screen_and_sweep_inputs_are_input_errors():
    from mincam_sim import masks

    for make, said in ((lambda: masks.Mask(np.ones((4, 4)), width_m="2mm"), "width_m must be a positive size"),
                       (lambda: masks.ramp("z"), "unknown ramp"), (lambda: ms.Screen(width_m="1"), "screen width_m"),
                       (lambda: ms.line_sweep((0, 0), (0.1, 0), 2.5, 0.03), "integer n"),
                       (lambda: ms.grid_sweep((0, 0.1), (0, 0.1), 2.5, 2, 0.03), "integers nx, ny"),
                       (lambda: ms.line_sweep((np.nan, 0), (0.1, 0), 3, 0.03), "NaN"),
                       (lambda: ms.line_sweep((0, 0), (0.1, 0), 3, 0.03, radiance=-1.0), "radiance >= 0")):
        with pytest.raises(InputError, match=said):
            make()


def re_escape(text: str) -> str:
    import re

    return re.escape(text)
