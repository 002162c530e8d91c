"""Paper Sec. 4.3: speed from one mixel with a sinusoid mask.

* road video (the paper's experiment): a road texture crop slides across the 50" screen by k display pixels
  per frame at 30 frames/s; speed in px/s; the stationary mixel's signal P(t) -> FFT peak -> v = omega_p/omega_d.
* vehicle (its physical version): the mixel looks down from height d at a textured road plane that moves at
  v m/s under an overcast sky (the plane moves by a parameter update per frame).
omega_d = omega_df d_f / d is the estimator's model (Eq. 10); the signal itself comes from rays.

The mask's constant term A0 lets the road's coarse structure (patches, lane dashes) through at temporal
frequencies below omega_d v, and on textured roads the plain periodogram peak often lands there. The
estimator therefore takes the FFT peak of the frame-to-frame difference P(t) - P(t - dt) (a high-pass with
|H| ~ omega at low frequencies); ``plain_fft`` reports the paper's plain windowed FFT of P(t) as well.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import masks as masks_mod
from .. import objects
from ..estimators import scene_frequency, spectrum, speed_from_signal
from ..geometry import Pose
from ..metrics import speed_error_rates
from ..optics import Mincam, Mixel
from ..progress import progress
from .common import PAPER, Setup

MASK_PERIOD_M = 0.2e-3  # sinusoid period on the mask [m]: 10 periods across the 2 mm mask, 5 cm at 0.5 m
FRAME_RATE_HZ = 30.0
ROAD_VIDEO_SHIFTS_PX = (2, 3, 4, 5, 6, 7, 8, 9, 10)
ROAD_VIDEO_RESOLUTION = (512, 288)  # display pixels: ~23 px per mask period at 0.5 m
DIFFERENCE_ORDER = 1  # the estimator works on P(t) - P(t - dt)
VEHICLE_HEIGHT_M = 0.3
VEHICLE_SPEEDS_M_S = (4.0, 8.0, 12.0, 16.0)
VEHICLE_RATE_HZ = 2500.0  # samples/s: above twice omega_d v_max / 2 pi (~530 Hz at 16 m/s)


def sinusoid_mixel(setup: Setup, pose: Pose, name: str = "sin") -> Mixel:
    omega_df = 2 * np.pi / MASK_PERIOD_M
    mask = masks_mod.sinusoid(omega_df, 0.5, 0.5, resolution=setup.mask_resolution, width_m=setup.mask_size_m)
    return Mixel(mask, setup.d_f_m, setup.detector_size_m, pose, name)


def road_video(setup: Setup, rng, out_dir: Path, show_progress: bool) -> dict:
    from ..render.screen_engine import response_maps
    from .common import read_out

    screen = setup.with_(screen_resolution=ROAD_VIDEO_RESOLUTION).screen()
    cam = Mincam((sinusoid_mixel(setup, Pose()),))
    maps = response_maps(cam, screen, samples_per_texel=64 if setup.quick else 256, seed=setup.seed)
    rows, cols = screen.shape
    n_frames = 128 if setup.quick else 256
    shifts = ROAD_VIDEO_SHIFTS_PX[::3] if setup.quick else ROAD_VIDEO_SHIFTS_PX
    road = objects.road_texture((rows, cols + max(shifts) * n_frames + 1), rng)
    pitch_m = screen.texel_size_m[0]
    omega_d_px = float(scene_frequency(2 * np.pi / MASK_PERIOD_M, setup.d_f_m, setup.depth_m)) * pitch_m
    v_min = FRAME_RATE_HZ * min(shifts)
    true_v, pred_v, plain_v, spectra = [], [], [], []
    for k in progress(shifts, desc="road video speeds", disable=not show_progress):
        crops = np.stack([road[:, i * k : i * k + cols] for i in range(n_frames)])
        m = maps.measure(crops)
        signal = read_out(m.irradiance_w_m2, m.irradiance_w_m2.min(0), setup, rng).frames_dn[:, 0]
        true_v.append(FRAME_RATE_HZ * k)
        v_max = FRAME_RATE_HZ * max(shifts)
        pred_v.append(_speed(signal, FRAME_RATE_HZ, omega_d_px, v_min, DIFFERENCE_ORDER, v_max))
        plain_v.append(_speed(signal, FRAME_RATE_HZ, omega_d_px, v_min, 0, v_max))
        spectra.append((signal, k))
    true_v, pred_v = np.array(true_v), np.array(pred_v)
    _plots(spectra, omega_d_px, true_v, pred_v, v_min, out_dir, "speed_road_video", "px/s")
    return {
        **speed_error_rates(pred_v, true_v),
        "estimator": "FFT peak (Hann window, sub-bin refinement) of P(t) - P(t - dt)",
        "plain_fft": {**speed_error_rates(np.array(plain_v), true_v), "predicted_speed_px_s": plain_v},
        "true_speed_px_s": true_v.tolist(),
        "predicted_speed_px_s": pred_v.tolist(),
        "omega_d_rad_per_px": omega_d_px,
        "frames_per_speed": n_frames,
        "frame_rate_hz": FRAME_RATE_HZ,
        "response_map_samples_per_texel": int(maps.meta["samples_per_texel"]),
    }


def vehicle(setup: Setup, rng, out_dir: Path, show_progress: bool) -> dict:
    """The physical version: a mixel at height d over a textured road moving at v."""
    from ..render.elements import road_elements, road_update
    from ..render.world import WorldRenderer
    from ..scene.road import Road
    from .common import read_out

    d = VEHICLE_HEIGHT_M
    cam = Mincam((sinusoid_mixel(setup, Pose((0.0, 0.0, d), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0))),))
    n_frames = 96 if setup.quick else 256
    speeds = VEHICLE_SPEEDS_M_S[::2] if setup.quick else VEHICLE_SPEEDS_M_S
    length = max(speeds) * n_frames / VEHICLE_RATE_HZ + 1.0  # travel plus 0.5 m margins [m]
    width = 0.6  # [m], wider than the field of view at this height
    road = Road(objects.road_texture((512, 4096), rng), length, width, sky_radiance_w_m2_sr=1.0)
    world = WorldRenderer(cam, road_elements(road), replicates=4)
    omega_d = float(scene_frequency(2 * np.pi / MASK_PERIOD_M, setup.d_f_m, d))
    spp = 1 << 17 if setup.quick else 1 << 19
    true_v, pred_v, plain_v, spectra = [], [], [], []
    for v in progress(speeds, desc="vehicle speeds", disable=not show_progress):
        irr = np.empty(n_frames)
        for i in range(n_frames):
            # the vehicle moves +x at v: the road under the mixel (at x = 0) moves -x, starting 0.5 m from its end
            world.update(road_update(road, length / 2 - 0.5 - v * i / VEHICLE_RATE_HZ))
            irr[i] = world.estimates(spp, seed=setup.seed).mean()  # same seed every frame: correlated noise
        signal = read_out(irr[:, None], np.array([irr.min()]), setup, rng).frames_dn[:, 0]
        true_v.append(v)
        pred_v.append(_speed(signal, VEHICLE_RATE_HZ, omega_d, min(speeds), DIFFERENCE_ORDER, max(speeds)))
        plain_v.append(_speed(signal, VEHICLE_RATE_HZ, omega_d, min(speeds), 0, max(speeds)))
        spectra.append((signal, v))
    true_v, pred_v = np.array(true_v), np.array(pred_v)
    _plots(spectra, omega_d, true_v, pred_v, min(speeds), out_dir, "speed_vehicle", "m/s", VEHICLE_RATE_HZ)
    return {
        **speed_error_rates(pred_v, true_v),
        "plain_fft": {**speed_error_rates(np.array(plain_v), true_v), "predicted_speed_m_s": plain_v},
        "true_speed_m_s": true_v.tolist(),
        "predicted_speed_m_s": pred_v.tolist(),
        "height_m": d,
        "omega_d_rad_per_m": omega_d,
        "frames_per_speed": n_frames,
        "frame_rate_hz": VEHICLE_RATE_HZ,
        "spp_per_frame": spp,
    }


def vehicle_trajectory(setup: Setup, rng, show_progress: bool) -> dict:
    """Two sinusoid mixels, one on each side of a vehicle turning on a circle, give the two side speeds; with
    the vehicle's width they give the turn radius and heading change (paper Sec. 4.3, last paragraph)."""
    from ..estimators import trajectory_from_speeds
    from ..render import scene_dicts as sd
    from ..render.world import WorldRenderer, transform_update
    from .common import read_out

    d, width, v, radius = VEHICLE_HEIGHT_M, 1.6, 10.0, 5.0  # [m], [m], [m/s], [m] (turning left)
    cam = Mincam(tuple(
        sinusoid_mixel(setup, Pose((0.0, side * width / 2, d), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)), name)
        for side, name in ((1, "left"), (-1, "right"))
    ))
    n_frames = 128 if setup.quick else 256
    size = v * n_frames / VEHICLE_RATE_HZ + width + 1.0
    road = objects.road_texture((512, 512), rng)  # ~7 mm texels: asphalt-scale grain
    road_matrix = Pose((size / 2 - 0.5, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0)).matrix() @ np.diag(
        [size / 2, size / 2, 1, 1])
    world = WorldRenderer(cam, {"road": sd.textured_plane(road, 2.0, 2.0, np.eye(4)), "sky": sd.sky(1.0)},
                          replicates=4)
    omega_d = float(scene_frequency(2 * np.pi / MASK_PERIOD_M, setup.d_f_m, d))
    spp = 1 << 18 if setup.quick else 1 << 19
    irr = np.empty((n_frames, 2))
    for i in progress(range(n_frames), desc="turning vehicle", disable=not show_progress):
        t = i / VEHICLE_RATE_HZ
        heading = v / radius * t
        centre = np.array([radius * np.sin(heading), radius * (1 - np.cos(heading))])  # vehicle on its circle
        world_to_vehicle = Pose((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (-np.sin(-heading), np.cos(-heading), 0.0))
        move = world_to_vehicle.matrix()
        move[:2, 3] = -move[:2, :2] @ centre
        # the textured_plane spans [-1, 1]^2 scaled by 1 here, so road_matrix carries the road's size
        world.update(transform_update("road", move @ road_matrix))
        irr[i] = world.estimates(spp, seed=setup.seed).mean(axis=0)
    dn = read_out(irr, irr.min(axis=0), setup, rng).frames_dn
    speeds = [_speed(dn[:, k], VEHICLE_RATE_HZ, omega_d, 0.5 * v, DIFFERENCE_ORDER, 1.5 * v) for k in range(2)]
    path = trajectory_from_speeds(np.array([speeds[0]]), np.array([speeds[1]]), width, n_frames / VEHICLE_RATE_HZ)
    true_left, true_right = v * (1 - width / (2 * radius)), v * (1 + width / (2 * radius))
    est_radius = float(path.turn_radius_m[0])
    return {
        "width_m": width,
        "true_turn_radius_m": radius,
        "estimated_turn_radius_m": est_radius,
        "turn_radius_error_pct": abs(est_radius / radius - 1) * 100,
        "true_side_speeds_m_s": [true_left, true_right],
        "estimated_side_speeds_m_s": speeds,
        "true_heading_change_rad": v / radius * n_frames / VEHICLE_RATE_HZ,
        "estimated_heading_change_rad": float(path.heading_change_rad[0]),
        "frames": n_frames,
        "frame_rate_hz": VEHICLE_RATE_HZ,
    }


def _speed(signal: np.ndarray, rate_hz: float, omega_d: float, v_min: float, order: int,
           v_max: float | None = None) -> float:
    """Speed from the FFT peak of the ``order``-th difference of the signal, searched between half the slowest
    and 1.5 x the fastest speed of interest (the band a speedometer is built for)."""
    f_min = 0.5 * omega_d * v_min / (2 * np.pi)
    f_max = None if v_max is None else min(rate_hz / 2, 1.5 * omega_d * v_max / (2 * np.pi))
    return float(speed_from_signal(np.diff(signal, n=order), rate_hz, omega_d, min_frequency_hz=f_min,
                                   max_frequency_hz=f_max))


def _plots(spectra, omega_d, true_v, pred_v, v_min, out_dir, stem, unit, rate=FRAME_RATE_HZ) -> None:
    from ..plots import plot_spectrum, plot_speed

    signal, v = spectra[len(spectra) // 2]
    speed = v * (FRAME_RATE_HZ if unit == "px/s" else 1.0)
    spec = spectrum(np.diff(signal, n=DIFFERENCE_ORDER), rate, min_frequency_hz=0.5 * omega_d * v_min / (2 * np.pi))
    plot_spectrum(spec, omega_d * speed, out_dir / f"{stem}_spectrum.png",
                  title=f"spectrum of P(t) - P(t - dt) at {speed:g} {unit}")
    plot_speed(true_v, pred_v, out_dir / f"{stem}_prediction.png", unit=unit)


def run(setup: Setup, out_dir: Path, show_progress: bool = False) -> dict:
    out_dir.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(setup.seed + 2)
    result = road_video(setup, rng, out_dir, show_progress)
    result["paper"] = PAPER["speed"]
    result["vehicle"] = vehicle(setup, rng, out_dir, show_progress)
    result["vehicle_trajectory"] = vehicle_trajectory(setup, rng, show_progress)
    return result
