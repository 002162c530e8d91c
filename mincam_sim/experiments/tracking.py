"""Paper Sec. 4.2: naive tracking of wind-up toys with four mixels (x, 1 - x, y, 1 - y), calibrated on a grid
of white squares on the 50" screen (3rd-degree 2D polynomial)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import objects
from ..estimators import track_4
from .common import (
    PAPER,
    STRATIFIED_SHARE,
    Setup,
    camera_fov_deg,
    fit_calibration_2d,
    locate_in_world,
    make_tabletop,
    mincam_on_screen,
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
    n_per_toy = 8 if setup.quick else 100  # full mode: a 300-frame video
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
    spp = (setup.spp // 2 if setup.quick else setup.spp) // STRATIFIED_SHARE  # rays per pass of the stratified dP
    calibration = cal["calibration"]

    def predict(c):
        return calibration.apply(track_4(c))

    summary, arrays, images, _ = locate_in_world(world, frames, background, setup, rng, predict, spp,
                                                 show_progress=show_progress)
    result = {
        **summary,
        "paper": PAPER["tracking"],
        "toys": list(kinds),
        "calibration_points": len(cal["true_m"]),
        "calibration_rms_residual_m": np.asarray(calibration.rms_residual_m).tolist(),  # (x, y)
        "calibration_mc_worst_rel_stderr": cal["mc_rel_stderr"],
    }
    predicted, truth, evaluated = arrays["predicted_m"], arrays["truth_m"], arrays["evaluated"]
    plot_calibration_2d(cal["true_m"], cal["observed"], calibration, out_dir / "tracking_calibration.png")
    plot_tracks(predicted, truth, sequence, out_dir / "tracking_paths.png")
    chosen = np.flatnonzero(evaluated)[:: max(1, int(evaluated.sum()) // 3)][:3]
    plot_overlays([images[i] for i in chosen], [(predicted[i], truth[i]) for i in chosen], setup,
                  out_dir / "tracking_frames.png", title="tracking wind-up toys")
    np.savez(out_dir / "tracking_data.npz", **arrays)
    return result
