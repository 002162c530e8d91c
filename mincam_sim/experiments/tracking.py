"""Paper Sec. 4.2: naive tracking of wind-up toys with four mixels (x, 1 - x, y, 1 - y), calibrated on a grid
of white squares on the 50" screen (3rd-degree 2D polynomial)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import objects
from ..calibration import error_rates
from ..estimators import detect_change, track_4
from ..progress import progress
from .common import (
    PAPER,
    Setup,
    camera_fov_deg,
    change_centroid,
    fit_calibration_2d,
    make_tabletop,
    signed_change_centroid,
    mincam_on_screen,
    propagate_sigma,
    read_out,
    screen_sweep_2d,
    toy_updates,
    tracking_mincam,
    world_elements,
)

TOYS = ("robot", "chick", "frog")


def calibrate(setup: Setup, cam, rng, out_dir: Path) -> dict:
    from ..render.screen_engine import render_frames

    screen = setup.screen()
    sweep = screen_sweep_2d(setup, 9 if setup.quick else 15, 0.03)
    m, _ = render_frames(mincam_on_screen(cam, setup), screen, sweep.frame_stack(screen), "response_map",
                         target_rel_stderr=3e-3 if setup.quick else 1e-3, seed=setup.seed)
    readout = read_out(m.irradiance_w_m2, np.zeros(len(cam)), setup, rng)
    observed = track_4(readout.change_dn)
    cal = fit_calibration_2d(observed, sweep.positions_m, {"experiment": "tracking", "depth_m": setup.depth_m,
                                                           "spacing_m": setup.spacing_m})
    cal.to_json(out_dir / "tracking_calibration.json")
    return {"true_m": sweep.positions_m, "observed": observed, "calibration": cal,
            "mc_rel_stderr": m.meta["reached_rel_stderr"]}


def run(setup: Setup, out_dir: Path, show_progress: bool = False) -> dict:
    from ..plots import plot_calibration_2d, plot_overlays, plot_tracks
    from ..render import scene_dicts as sd
    from ..render.world import WorldRenderer

    out_dir.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(setup.seed + 1)
    cam = tracking_mincam(setup)
    cal = calibrate(setup, cam, rng, out_dir)

    kinds = TOYS[:2] if setup.quick else TOYS
    n_per_toy = 8 if setup.quick else 24
    toys = {kind: objects.windup_toy(kind, size_m=0.07) for kind in kinds}
    table = make_tabletop(setup, toys, rng)
    frames, sequence = [], []
    reach = 0.4 * setup.field_m
    for k, kind in enumerate(kinds):
        path = objects.random_smooth_path(np.random.default_rng(setup.seed + 10 + k), n_per_toy, dt_s=0.5,
                                          bounds_m=((-reach, reach), (-reach, reach)), speed_m_s=0.04)
        for i in range(n_per_toy):
            frames.append(toy_updates(table, {kind: (path.positions_m[i], path.headings_rad[i])}))
            sequence.append(kind)
    sequence = np.array(sequence)
    background = toy_updates(table, {})
    camera = sd.pinhole_camera(setup.center.matrix(), camera_fov_deg(setup), setup.camera_px, setup.camera_px,
                               spp=32)
    world = WorldRenderer(cam, world_elements(table), replicates=8, camera=camera)
    spp = setup.spp // 2 if setup.quick else setup.spp
    dp, _ = world.measure_changes(frames, background, spp=spp, seed=setup.seed, show_progress=show_progress)
    bg_irr = np.asarray(dp.meta["background_w_m2"])
    readout = read_out(bg_irr + dp.irradiance_w_m2, bg_irr, setup, rng)
    detected = detect_change(readout.frames_dn, readout.background_dn, readout.threshold_dn)
    calibration = cal["calibration"]

    def predict(c):
        return calibration.apply(track_4(c))

    predicted = predict(readout.change_dn)
    frame_irr = bg_irr + dp.irradiance_w_m2
    predicted_ideal = predict(readout.ideal_change_dn(frame_irr, bg_irr))
    sigma = propagate_sigma(predict, readout.change_dn, readout.change_sigma_dn(frame_irr, bg_irr, dp.stderr_w_m2))
    sigma_sensor = propagate_sigma(predict, readout.change_dn, readout.change_sigma_dn(frame_irr, bg_irr))

    world.update(background)
    bg_image = world.camera_image(spp=32, seed=setup.seed)
    truth = np.full((len(frames), 2), np.nan)
    signed = np.full((len(frames), 2), np.nan)
    images = []
    for i in progress(range(len(frames)), desc="ground truth", disable=not show_progress):
        world.update(frames[i])
        image = world.camera_image(spp=32, seed=setup.seed)
        truth[i], _ = change_centroid(image, bg_image, setup, threshold=0.02 * float(bg_image.max()))
        signed[i] = signed_change_centroid(image, bg_image, setup)
        images.append(image)
    world.update(background)
    evaluated = detected & np.all(np.isfinite(truth), axis=1) & np.all(np.isfinite(predicted), axis=1)
    errors = error_rates(predicted[evaluated], truth[evaluated], setup.field_m)
    result = {
        **errors,
        "paper": PAPER["tracking"],
        "frames": len(frames),
        "toys": list(kinds),
        "detected_frames": int(detected.sum()),
        "calibration_points": len(cal["true_m"]),
        "calibration_mc_worst_rel_stderr": cal["mc_rel_stderr"],
        "dP_worst_rel_stderr": float(np.nanmax(np.abs(dp.stderr_w_m2 / dp.irradiance_w_m2)[evaluated]))
        if evaluated.any() else float("nan"),
        "spp_per_mixel_per_frame": spp,
        "exposure_s": readout.sensor.exposure_s,
        "noiseless": error_rates(predicted_ideal[evaluated], truth[evaluated], setup.field_m),
        "signed_centroid_vs_ground_truth": error_rates(signed[evaluated], truth[evaluated], setup.field_m),
        "vs_signed_centroid": error_rates(predicted[evaluated], signed[evaluated], setup.field_m),
        "noise_sigma_median_pct": float(100 * np.median(np.hypot(*sigma[evaluated].T)) / setup.field_m)
        if evaluated.any() else float("nan"),
    }
    plot_calibration_2d(cal["true_m"], cal["observed"], cal["calibration"], out_dir / "tracking_calibration.png")
    plot_tracks(predicted, truth, sequence, out_dir / "tracking_paths.png")
    chosen = np.flatnonzero(evaluated)[:: max(1, int(evaluated.sum()) // 3)][:3]
    plot_overlays([images[i] for i in chosen], [(predicted[i], truth[i]) for i in chosen], setup,
                  out_dir / "tracking_frames.png", title="tracking wind-up toys")
    np.savez(out_dir / "tracking_data.npz", predicted_m=predicted, truth_m=truth, detected=detected,
             predicted_noiseless_m=predicted_ideal, predicted_sigma_m=sigma, sensor_sigma_m=sigma_sensor,
             evaluated=evaluated,
             change_dn=readout.change_dn, dP_w_m2=dp.irradiance_w_m2, dP_stderr_w_m2=dp.stderr_w_m2)
    return result
