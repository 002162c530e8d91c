"""Paper Sec. 4.1: 1D intrusion detection at a finish line with two mixels, calibrated on a 50" screen."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import objects
from ..estimators import intrusion_position
from .common import (
    PAPER,
    STRATIFIED_SHARE,
    Setup,
    camera_fov_deg,
    camera_pixel_to_table,
    fit_calibration_1d,
    intrusion_mincam,
    locate_in_world,
    make_tabletop,
    mincam_on_screen,
    read_out,
    screen_sweep_1d,
    toy_updates,
    world_elements,
)

BOUNDARY_X_M = -0.1378  # the paper's finish line x0 = -13.78 cm
BAND_M = 0.03  # width of the boundary band the masks look at [m]


def calibrate(setup: Setup, cam, rng, out_dir: Path) -> dict:
    """Sweep a white square along the boundary on the screen; fit the cubic f(x_obs) -> true position."""
    from ..render.screen_engine import render_frames

    screen = setup.screen()
    sweep = screen_sweep_1d(setup, BOUNDARY_X_M, 26 if setup.quick else 51, 0.03)
    frames = sweep.frame_stack(screen)
    m, maps = render_frames(mincam_on_screen(cam, setup), screen, frames, "response_map",
                            target_rel_stderr=3e-3 if setup.quick else 1e-3, seed=setup.seed)
    readout = read_out(m.irradiance_w_m2, np.zeros(len(cam)), setup, rng)
    change = readout.change_dn
    observed = intrusion_position(change[:, 0], change[:, 1])
    true = sweep.positions_m[:, 1]
    cal = fit_calibration_1d(observed, true, {"experiment": "intrusion", "boundary_x_m": BOUNDARY_X_M,
                                              "depth_m": setup.depth_m, "spacing_m": setup.spacing_m})
    cal.to_json(out_dir / "intrusion_calibration.json")
    return {"true_m": true, "change_dn": change, "observed": observed, "calibration": cal, "maps": maps,
            "screen": screen, "mc_rel_stderr": m.meta["reached_rel_stderr"]}


def run(setup: Setup, out_dir: Path, show_progress: bool = False) -> dict:
    from ..render import scene_dicts as sd
    from ..render.world import WorldRenderer

    out_dir.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(setup.seed)
    cam = intrusion_mincam(setup, BOUNDARY_X_M, BAND_M)
    cal = calibrate(setup, cam, rng, out_dir)

    cars = {"car_a": objects.toy_car(albedo=0.9), "car_b": objects.toy_car(albedo=0.75)}
    table = make_tabletop(setup, cars, rng)
    rate = 5.0 if setup.quick else 125.0  # full mode: a >= 300-frame video (the slower car's 2.4 s run)
    car_a, car_b = objects.race_pair(finish_line_x_m=BOUNDARY_X_M, lanes_y_m=(-0.12, 0.07), speeds_m_s=(0.12, 0.09),
                                     start_distance_m=0.12, overrun_m=0.1, frame_rate_hz=rate)
    frames = [toy_updates(table, {"car_a": (car_a.positions_m[i], car_a.headings_rad[i]),
                                  "car_b": (car_b.positions_m[i], car_b.headings_rad[i])})
              for i in range(len(car_a.times_s))]
    background = toy_updates(table, {})
    camera = sd.pinhole_camera(setup.center.matrix(), camera_fov_deg(setup), setup.camera_px, setup.camera_px, spp=32)
    world = WorldRenderer(cam, world_elements(table), replicates=8, camera=camera)
    spp = (setup.spp // 2 if setup.quick else setup.spp) // STRATIFIED_SHARE  # rays per pass of the stratified dP
    calibration = cal["calibration"]

    def predict(c):
        return calibration.apply(intrusion_position(c[:, 0], c[:, 1]))

    region = _band_region(setup, (setup.camera_px, setup.camera_px))
    summary, arrays, images, _ = locate_in_world(world, frames, background, setup, rng, predict, spp, region=region,
                                                 axis=1, show_progress=show_progress)
    result = {
        **summary,
        "paper": PAPER["intrusion"],
        "calibration_rms_residual_m": calibration.rms_residual_m,
        "calibration_mc_worst_rel_stderr": cal["mc_rel_stderr"],
    }
    _plots(setup, cal, images, arrays["predicted_m"], arrays["truth_m"], arrays["evaluated"], out_dir)
    np.savez(out_dir / "intrusion_data.npz", **arrays)
    return result


def _band_region(setup: Setup, shape) -> np.ndarray:
    rows, cols = np.indices(shape)
    xy = camera_pixel_to_table(setup, rows, cols, shape)
    return np.abs(xy[..., 0] - BOUNDARY_X_M) <= BAND_M / 2


def _plots(setup, cal, images, predicted, truth, evaluated, out_dir: Path) -> None:
    from ..plots import plot_calibration_1d, plot_overlays

    plot_calibration_1d(cal["true_m"], cal["change_dn"], cal["observed"], cal["calibration"],
                        out_dir / "intrusion_calibration.png", names=("y", "1-y"))
    chosen = np.flatnonzero(evaluated)[:: max(1, int(evaluated.sum()) // 3)][:3]
    points = [(np.array([BOUNDARY_X_M, predicted[i]]), np.array([BOUNDARY_X_M, truth[i]])) for i in chosen]
    plot_overlays([images[i] for i in chosen], points, setup, out_dir / "intrusion_frames.png",
                  boundary_x_m=BOUNDARY_X_M, title="intrusion at the finish line")
