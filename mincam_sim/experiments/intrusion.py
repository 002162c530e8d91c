"""Paper Sec. 4.1: 1D intrusion detection at a finish line with two mixels, calibrated on a 50" screen."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import objects
from ..calibration import error_rates
from ..estimators import detect_change, intrusion_position
from ..progress import progress
from .common import (
    PAPER,
    Setup,
    change_centroid,
    fit_calibration_1d,
    intrusion_mincam,
    make_tabletop,
    signed_change_centroid,
    mincam_on_screen,
    propagate_sigma,
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
    rate = 5.0 if setup.quick else 15.0
    car_a, car_b = objects.race_pair(finish_line_x_m=BOUNDARY_X_M, lanes_y_m=(-0.12, 0.07), speeds_m_s=(0.12, 0.09),
                                     start_distance_m=0.12, overrun_m=0.1, frame_rate_hz=rate)
    frames = [toy_updates(table, {"car_a": (car_a.positions_m[i], car_a.headings_rad[i]),
                                  "car_b": (car_b.positions_m[i], car_b.headings_rad[i])})
              for i in range(len(car_a.times_s))]
    background = toy_updates(table, {})
    camera = sd.pinhole_camera(setup.center.matrix(), _fov(setup), setup.camera_px, setup.camera_px, spp=32)
    world = WorldRenderer(cam, world_elements(table), replicates=8, camera=camera)
    spp = setup.spp // 2 if setup.quick else setup.spp
    dp, _ = world.measure_changes(frames, background, spp=spp, seed=setup.seed, show_progress=show_progress)
    bg_irr = np.asarray(dp.meta["background_w_m2"])
    readout = read_out(bg_irr + dp.irradiance_w_m2, bg_irr, setup, rng)
    detected = detect_change(readout.frames_dn, readout.background_dn, readout.threshold_dn)
    change = readout.change_dn
    calibration = cal["calibration"]

    def predict(c):
        return calibration.apply(intrusion_position(c[:, 0], c[:, 1]))

    predicted = predict(change)
    frame_irr = bg_irr + dp.irradiance_w_m2
    predicted_ideal = predict(readout.ideal_change_dn(frame_irr, bg_irr))
    sigma = propagate_sigma(predict, change, readout.change_sigma_dn(frame_irr, bg_irr, dp.stderr_w_m2))
    sigma_sensor = propagate_sigma(predict, change, readout.change_sigma_dn(frame_irr, bg_irr))

    # ground truth: centroid of the change along the boundary in the centre camera
    world.update(background)
    bg_image = world.camera_image(spp=32, seed=setup.seed)
    region = _band_region(setup, bg_image.shape)
    truth = np.full(len(frames), np.nan)
    signed = np.full(len(frames), np.nan)
    images = []
    for i in progress(range(len(frames)), desc="ground truth", disable=not show_progress):
        world.update(frames[i])
        image = world.camera_image(spp=32, seed=setup.seed)
        centroid, mask = change_centroid(image, bg_image, setup, threshold=0.02 * float(bg_image.max()),
                                         region=region)
        truth[i] = centroid[1] if mask.sum() >= 3 else np.nan
        signed[i] = signed_change_centroid(image, bg_image, setup, region)[1]
        images.append(image)
    world.update(background)
    evaluated = detected & np.isfinite(truth) & np.isfinite(predicted)
    errors = error_rates(predicted[evaluated], truth[evaluated], setup.field_m)
    result = {
        **errors,
        "paper": PAPER["intrusion"],
        "frames": len(frames),
        "detected_frames": int(detected.sum()),
        "ground_truth_frames": int(np.isfinite(truth).sum()),
        "missed_frames": int((np.isfinite(truth) & ~detected).sum()),
        "false_alarm_frames": int((~np.isfinite(truth) & detected).sum()),
        "calibration_rms_residual_m": cal["calibration"].rms_residual_m,
        "calibration_mc_worst_rel_stderr": cal["mc_rel_stderr"],
        "dP_worst_rel_stderr": float(np.nanmax(np.abs(dp.stderr_w_m2 / dp.irradiance_w_m2)[evaluated]))
        if evaluated.any() else float("nan"),
        "spp_per_mixel_per_frame": spp,
        "exposure_s": readout.sensor.exposure_s,
        "noiseless": error_rates(predicted_ideal[evaluated], truth[evaluated], setup.field_m),
        "signed_centroid_vs_ground_truth": error_rates(signed[evaluated], truth[evaluated], setup.field_m),
        "vs_signed_centroid": error_rates(predicted[evaluated], signed[evaluated], setup.field_m),
        "noise_sigma_median_pct": float(100 * np.median(sigma[evaluated]) / setup.field_m) if evaluated.any()
        else float("nan"),
    }
    _plots(setup, cal, images, bg_image, predicted, truth, detected, out_dir)
    np.savez(out_dir / "intrusion_data.npz", predicted_m=predicted, truth_m=truth, detected=detected,
             predicted_noiseless_m=predicted_ideal, predicted_sigma_m=sigma, sensor_sigma_m=sigma_sensor,
             evaluated=evaluated,
             change_dn=change, dP_w_m2=dp.irradiance_w_m2, dP_stderr_w_m2=dp.stderr_w_m2)
    return result


def _fov(setup: Setup) -> float:
    from .common import camera_fov_deg

    return camera_fov_deg(setup)


def _band_region(setup: Setup, shape) -> np.ndarray:
    from .common import camera_pixel_to_table

    rows, cols = np.indices(shape)
    xy = camera_pixel_to_table(setup, rows, cols, shape)
    return np.abs(xy[..., 0] - BOUNDARY_X_M) <= BAND_M / 2


def _plots(setup, cal, images, bg_image, predicted, truth, detected, out_dir: Path) -> None:
    from ..plots import plot_calibration_1d, plot_overlays

    plot_calibration_1d(cal["true_m"], cal["change_dn"], cal["observed"], cal["calibration"],
                        out_dir / "intrusion_calibration.png", names=("y", "1-y"))
    chosen = [i for i in np.flatnonzero(detected & np.isfinite(truth))][:: max(1, int(detected.sum()) // 3)][:3]
    points = [(np.array([BOUNDARY_X_M, predicted[i]]), np.array([BOUNDARY_X_M, truth[i]])) for i in chosen]
    plot_overlays([images[i] for i in chosen], points, setup, out_dir / "intrusion_frames.png",
                  boundary_x_m=BOUNDARY_X_M, title="intrusion at the finish line")
