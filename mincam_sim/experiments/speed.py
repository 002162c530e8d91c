"""Paper Sec. 4.3: speed from one mixel with a sinusoid mask.

* road video (the paper's experiment): a road texture crop slides across the 50" screen by k display pixels
  per frame at 30 frames/s; speed in px/s; the stationary mixel's signal P(t) -> FFT peak -> v = omega_p/omega_d.
* vehicle (its physical version): the mixel looks down from height d at a textured road plane that moves at
  v m/s under an overcast sky (the plane moves by a parameter update per frame).

omega_d = omega_df d_f / d is the estimator's model (Eq. 10); the signal itself comes from rays.

The mask's constant term A0 lets the road's coarse structure (patches, lane dashes) through at temporal
frequencies below omega_d v, and on textured roads the plain periodogram peak often lands there. The
estimator therefore takes the FFT peak of the frame-to-frame difference P(t) - P(t - dt) (a high-pass with
``|H| ~ omega`` at low frequencies); ``plain_fft`` reports the paper's plain windowed FFT of P(t) as well.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mincam_sim.budget import Budget
from mincam_sim.errors import ConfigError
from mincam_sim.estimation.estimators import (
    AliasingError,
    check_below_nyquist,
    nyquist_speed,
    scene_frequency,
    spectrum,
    speed_from_signal,
    trajectory_from_speeds,
)
from mincam_sim.estimation.metrics import speed_error_rates
from mincam_sim.experiments.base import Experiment, ExperimentResult, PaperNumbers
from mincam_sim.experiments.display_timing import DisplayTiming, displayed_readings, sample_times_s
from mincam_sim.experiments.layouts import sinusoid_mixel
from mincam_sim.experiments.setup import Setup
from mincam_sim.model.geometry import Pose
from mincam_sim.model.optics import Mincam
from mincam_sim.model.readout import read_out
from mincam_sim.paper import SPEED_AVG_ERROR_PCT, SPEED_MAX_ERROR_PCT
from mincam_sim.plotting.plots import plot_spectrum, plot_speed
from mincam_sim.progress import progress
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.elements import road_elements
from mincam_sim.render.simulation import Simulation
from mincam_sim.render.solvers import PlaneReplay
from mincam_sim.scene import objects
from mincam_sim.scene.road import Road


@dataclass(frozen=True)
class SpeedParams:
    """Parameters of the speed experiment (``[speed]`` in a reproduce config).

    Attributes
    ----------
    mask_period_m : float
        Sinusoid period on the mask [m]: 10 periods across the 2 mm mask, 5 cm at 0.5 m.
    difference_order : int
        The estimator works on the ``difference_order``-th difference of P(t) (0 = the paper's plain FFT).
    video_frame_rate_hz : float
        Frame rate of the road video on the screen.
    video_shifts_px : tuple of int
        Road crop shift per frame [display px]: one speed each.
    video_resolution : tuple of int
        Display pixels (columns, rows) of the road video: ~23 px per mask period at 0.5 m.
    video_frames : int
        Frames per speed.
    video_samples_per_texel : int
        Response-map samples per display texel.
    vehicle_height_m : float
        Height of the mixel over the road [m].
    vehicle_speeds_m_s : tuple of float
        Speeds of the physical vehicle [m/s].
    vehicle_rate_hz : float
        Mixel sample rate [1/s]: above the Nyquist rate 2 x omega_d v_max / (2 pi) (the signal is ~530 Hz at 16
        m/s, so > ~1070 Hz); :func:`check_nyquist` refuses speeds at or above the limit.
    vehicle_frames, vehicle_spp : int
        Samples per speed and rays per sample.
    turn_frames, turn_spp : int
        The same for the two-mixel turning vehicle.
    display_refresh_hz, display_sample_rate_hz, display_exposure_s, display_jitter_s : float
        The paper-like timing of the road video, reported beside the ideal one (one reading per video frame,
        at its instant): the video on a display refreshing at ``display_refresh_hz`` (sample-and-hold), read
        by a mixel on its own clock (random phase) at ``display_sample_rate_hz``, integrating
        ``display_exposure_s`` per reading, its instants jittered by ``display_jitter_s`` rms
        (:mod:`.display_timing`). The paper gives none of these; the defaults (60 Hz, 30 readings/s, 20 ms,
        2 ms) are this simulator's guess at a camera sampling a 30 frames/s video asynchronously.
    display_timing_draws : int
        Independent draws of the timing (phase, jitter, read-out noise) on the same rendered video; the headline
        of ``display_timing`` is draw 0, ``display_timing.draws`` summarises them all.
    """

    mask_period_m: float = 0.2e-3
    difference_order: int = 1
    video_frame_rate_hz: float = 30.0
    video_shifts_px: tuple[int, ...] = (2, 3, 4, 5, 6, 7, 8, 9, 10)
    video_resolution: tuple[int, ...] = (512, 288)
    video_frames: int = 256
    video_samples_per_texel: int = 256
    vehicle_height_m: float = 0.3
    vehicle_speeds_m_s: tuple[float, ...] = (4.0, 8.0, 12.0, 16.0)
    vehicle_rate_hz: float = 2500.0
    vehicle_frames: int = 256
    vehicle_spp: int = 1 << 19
    turn_frames: int = 256
    turn_spp: int = 1 << 19
    display_refresh_hz: float = 60.0
    display_sample_rate_hz: float = 30.0
    display_exposure_s: float = 0.02
    display_jitter_s: float = 0.002
    display_timing_draws: int = 32

    def timing(self) -> DisplayTiming:
        """The paper-like display timing (raises ``ValueError`` naming the field if it is inconsistent)."""
        return DisplayTiming(self.display_refresh_hz, self.display_sample_rate_hz, self.display_exposure_s,
                             self.display_jitter_s)

    def __post_init__(self) -> None:
        if self.display_timing_draws < 1:
            raise ValueError(f"display_timing_draws must be >= 1, got {self.display_timing_draws!r}")
        try:
            self.timing()
        except ValueError as err:
            raise ValueError(f"display timing: {err} (fields display_refresh_hz, display_sample_rate_hz, "
                             "display_exposure_s, display_jitter_s)") from None
        for key in ("mask_period_m", "video_frame_rate_hz", "vehicle_height_m", "vehicle_rate_hz"):
            if not getattr(self, key) > 0:
                raise ValueError(f"{key} must be > 0, got {getattr(self, key)!r}")
        if min(self.video_shifts_px) < 1 or min(self.vehicle_speeds_m_s) <= 0:
            raise ValueError("video_shifts_px must be >= 1 px and vehicle_speeds_m_s > 0")
        if len(self.video_resolution) != 2:
            raise ValueError(f"video_resolution must be [columns, rows], got {list(self.video_resolution)}")
        if min(self.video_frames, self.vehicle_frames, self.turn_frames) < 16:
            raise ValueError("video_frames, vehicle_frames and turn_frames must be >= 16 (an FFT needs samples)")


def _speed(signal: np.ndarray, rate_hz: float, omega_d: float, v_min: float, order: int,
           v_max: float | None = None) -> float:
    """Speed from the FFT peak of the ``order``-th difference of the signal, searched between half the slowest
    and 1.5 x the fastest speed of interest (the band a speedometer is built for)."""
    f_min = 0.5 * omega_d * v_min / (2 * np.pi)
    f_max = None if v_max is None else min(rate_hz / 2, 1.5 * omega_d * v_max / (2 * np.pi))
    return float(speed_from_signal(np.diff(signal, n=order), rate_hz, omega_d, min_frequency_hz=f_min,
                                   max_frequency_hz=f_max))


TURN_WIDTH_M, TURN_SPEED_M_S, TURN_RADIUS_M = 1.6, 10.0, 5.0  # the turning vehicle: mixel separation, speed, radius


def video_omega_d_rad_per_px(setup: Setup, params: SpeedParams) -> float:
    """Mask frequency on the screen in rad per display pixel (Eq. 10 times the pixel pitch)."""
    screen = setup.with_(screen_resolution=tuple(params.video_resolution)).screen()
    omega_d = float(scene_frequency(2 * np.pi / params.mask_period_m, setup.d_f_m, setup.depth_m))
    return omega_d * screen.texel_size_m[0]


def check_nyquist(setup: Setup, params: SpeedParams) -> dict:
    """Refuse (:class:`~mincam_sim.errors.ConfigError`) speeds the sampled sinusoid cannot measure (at or above
    the Nyquist limit ``pi f_s / omega_d``, where the FFT peak would report an aliased, wrong speed); return the
    limits."""
    video = nyquist_speed(params.video_frame_rate_hz, video_omega_d_rad_per_px(setup, params))
    vehicle_omega = float(scene_frequency(2 * np.pi / params.mask_period_m, setup.d_f_m, params.vehicle_height_m))
    vehicle = nyquist_speed(params.vehicle_rate_hz, vehicle_omega)
    turn_fastest = TURN_SPEED_M_S * (1 + TURN_WIDTH_M / (2 * TURN_RADIUS_M))  # the outer side
    checks = (
        ("[speed] video_shifts_px x video_frame_rate_hz (px/s)",
         params.video_frame_rate_hz * max(params.video_shifts_px), params.video_frame_rate_hz,
         video_omega_d_rad_per_px(setup, params)),
        ("[speed] video_shifts_px x video_frame_rate_hz (px/s, read at display_sample_rate_hz)",
         params.video_frame_rate_hz * max(params.video_shifts_px), params.display_sample_rate_hz,
         video_omega_d_rad_per_px(setup, params)),
        ("[speed] vehicle_speeds_m_s (with vehicle_rate_hz)", max(params.vehicle_speeds_m_s),
         params.vehicle_rate_hz, vehicle_omega),
        (f"the turning vehicle's outer side speed (vehicle_rate_hz; {TURN_SPEED_M_S:g} m/s on a "
         f"{TURN_RADIUS_M:g} m circle)", turn_fastest, params.vehicle_rate_hz, vehicle_omega),
    )
    for what, fastest, rate, omega in checks:
        try:
            check_below_nyquist(fastest, rate, omega, what)
        except AliasingError as err:
            raise ConfigError(str(err)) from None
    return {"video_nyquist_speed_px_s": video, "vehicle_nyquist_speed_m_s": vehicle}


class Speed(Experiment):
    """One sinusoid mixel (Eq. 9-14): speed of a road video on the screen and of a physical vehicle; two mixels
    give a turning vehicle's trajectory."""

    name = "speed"
    paper_section = "4.3"
    paper = PaperNumbers(max_error_pct=SPEED_MAX_ERROR_PCT, avg_error_pct=SPEED_AVG_ERROR_PCT)
    Params = SpeedParams
    quick_overrides = {"video_frames": 128, "video_shifts_px": (2, 5, 8), "video_samples_per_texel": 64,
                       "vehicle_frames": 96, "vehicle_speeds_m_s": (4.0, 12.0), "vehicle_spp": 1 << 17,
                       "turn_frames": 128, "turn_spp": 1 << 18}
    seed_offset = 2
    version = 2  # the vehicles' roads replayed (SlidingPlane): the turn's bounce directions are drawn anew
    study_version = 2
    study_metrics = ("avg_error_pct", "max_error_pct")
    study_seconds = (120.0, 1800.0)

    def scene(self, setup: Setup, params: SpeedParams, rng: np.random.Generator) -> np.ndarray:
        """The road texture of the video: long enough for the fastest shift over all frames."""
        cols, rows = params.video_resolution
        return objects.road_texture((rows, cols + max(params.video_shifts_px) * params.video_frames + 1), rng)

    def road_video(self, setup: Setup, params: SpeedParams, rng: np.random.Generator, out_dir: Path,
                   show_progress: bool) -> dict:
        """The paper's experiment: a road crop slides across the screen by k px per frame."""
        screen = setup.with_(screen_resolution=tuple(params.video_resolution)).screen()
        cam = Mincam((sinusoid_mixel(setup, params.mask_period_m, Pose()),))
        maps = Simulation(cam, screen=screen).response_maps(
            Budget(samples_per_texel=params.video_samples_per_texel, seed=setup.seed))
        rows, cols = screen.shape
        road = self.scene(setup, params, rng)
        shifts = params.video_shifts_px
        rate = params.video_frame_rate_hz
        omega_d_px = video_omega_d_rad_per_px(setup, params)
        v_min, v_max = rate * min(shifts), rate * max(shifts)
        timing = params.timing()
        draw_rngs = self.streams(setup, ("video", "display_timing"))["display_timing"].spawn(
            params.display_timing_draws)  # one stream per draw: draw 0 is the same whatever their number
        true_v, pred_v, plain_v, spectra = [], [], [], []
        timed_v = np.empty((params.display_timing_draws, len(shifts)))
        for j, k in enumerate(progress(shifts, desc="road video speeds", disable=not show_progress)):
            crops = np.stack([road[:, i * k : i * k + cols] for i in range(params.video_frames)])
            m = maps.measure(crops)
            signal = read_out(m.irradiance_w_m2, m.irradiance_w_m2.min(0), setup.sensor(), rng,
                              setup.exposure_fill).frames_dn[:, 0]
            true_v.append(rate * k)
            pred_v.append(_speed(signal, rate, omega_d_px, v_min, params.difference_order, v_max))
            plain_v.append(_speed(signal, rate, omega_d_px, v_min, 0, v_max))
            spectra.append((signal, rate * k))
            for d, draw_rng in enumerate(draw_rngs):
                times = sample_times_s(timing, params.video_frames / rate, rate, draw_rng)
                shown = displayed_readings(m.irradiance_w_m2, rate, timing.refresh_rate_hz, times, timing.exposure_s)
                timed = read_out(shown, shown.min(0), setup.sensor(), draw_rng, setup.exposure_fill).frames_dn[:, 0]
                timed_v[d, j] = _speed(timed, timing.sample_rate_hz, omega_d_px, v_min, params.difference_order,
                                       v_max)
        true_v, pred_v = np.array(true_v), np.array(pred_v)
        draws = [speed_error_rates(v, true_v) for v in timed_v]
        draw_max = np.array([r["max_error_pct"] for r in draws])
        draw_avg = np.array([r["avg_error_pct"] for r in draws])
        self._plots(spectra, omega_d_px, true_v, pred_v, v_min, out_dir, "speed_road_video", "px/s", rate,
                    params.difference_order)
        plot_speed(true_v, timed_v[0], out_dir / "speed_road_video_display_prediction.png", unit="px/s")
        return {
            "timing": "ideal: one instantaneous reading per video frame, at its instant",
            "display_timing": {
                **draws[0],
                "timing": (f"paper-like: {rate:g} frames/s held on a {timing.refresh_rate_hz:g} Hz display, read "
                           f"asynchronously at {timing.sample_rate_hz:g}/s (random phase), "
                           f"{timing.exposure_s * 1e3:g} ms exposure, {timing.jitter_s * 1e3:g} ms rms jitter"),
                "refresh_rate_hz": timing.refresh_rate_hz,
                "sample_rate_hz": timing.sample_rate_hz,
                "exposure_s": timing.exposure_s,
                "jitter_s": timing.jitter_s,
                "predicted_speed_px_s": timed_v[0].tolist(),
                "draws": {
                    "count": params.display_timing_draws,
                    "max_error_pct": draw_max.tolist(),
                    "avg_error_pct": draw_avg.tolist(),
                    "median_max_error_pct": float(np.median(draw_max)),
                    "median_avg_error_pct": float(np.median(draw_avg)),
                    "draws_with_a_speed_off_by_over_20_pct": int((draw_max > 20).sum()),
                },
            },
            **speed_error_rates(pred_v, true_v),
            "estimator": f"FFT peak (Hann window, sub-bin refinement) of the order-{params.difference_order} "
                         "difference of P(t)",
            "plain_fft": {**speed_error_rates(np.array(plain_v), true_v), "predicted_speed_px_s": plain_v},
            "true_speed_px_s": true_v.tolist(),
            "predicted_speed_px_s": pred_v.tolist(),
            "omega_d_rad_per_px": omega_d_px,
            "frames_per_speed": params.video_frames,
            "frame_rate_hz": rate,
            "response_map_samples_per_texel": int(maps.meta["samples_per_texel"]),
        }

    def vehicle(self, setup: Setup, params: SpeedParams, rng: np.random.Generator, out_dir: Path,
                show_progress: bool) -> dict:
        """The physical version: a mixel at height d over a textured road moving at v."""
        d, rate, n_frames = params.vehicle_height_m, params.vehicle_rate_hz, params.vehicle_frames
        cam = Mincam((sinusoid_mixel(setup, params.mask_period_m,
                                     Pose((0.0, 0.0, d), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0))),))
        speeds = params.vehicle_speeds_m_s
        length = max(speeds) * n_frames / rate + 1.0  # travel plus 0.5 m margins [m]
        width = 0.6  # [m], wider than the field of view at this height
        road = Road(objects.road_texture((512, 4096), rng), length, width, sky_radiance_w_m2_sr=1.0)
        sim = Simulation(cam, world=road_elements(road))
        omega_d = float(scene_frequency(2 * np.pi / params.mask_period_m, setup.d_f_m, d))
        # the vehicle moves +x at v: the road under the mixel (x = 0) moves -x, starting 0.5 m from its end
        frames = [{"road.to_world": road.matrix_at(length / 2 - 0.5 - v * i / rate)} for v in speeds
                  for i in range(n_frames)]
        # the road slides in its plane: its rays traced once, every frame replayed (same seed: correlated frames);
        # one measure over every speed's frames, so that one replay covers them all
        budget = Budget(spp=params.vehicle_spp, replicates=4, seed=setup.seed)
        irr_all = sim.measure(frames, solver=PlaneReplay("road"), budget=budget).irradiance_w_m2[:, 0]
        true_v, pred_v, plain_v, spectra = [], [], [], []
        for j, v in enumerate(progress(speeds, desc="vehicle speeds", disable=not show_progress)):
            irr = irr_all[j * n_frames:(j + 1) * n_frames]
            signal = read_out(irr[:, None], np.array([irr.min()]), setup.sensor(), rng,
                              setup.exposure_fill).frames_dn[:, 0]
            true_v.append(v)
            pred_v.append(_speed(signal, rate, omega_d, min(speeds), params.difference_order, max(speeds)))
            plain_v.append(_speed(signal, rate, omega_d, min(speeds), 0, max(speeds)))
            spectra.append((signal, v))
        true_v, pred_v = np.array(true_v), np.array(pred_v)
        self._plots(spectra, omega_d, true_v, pred_v, min(speeds), out_dir, "speed_vehicle", "m/s", rate,
                    params.difference_order)
        return {
            **speed_error_rates(pred_v, true_v),
            "plain_fft": {**speed_error_rates(np.array(plain_v), true_v), "predicted_speed_m_s": plain_v},
            "true_speed_m_s": true_v.tolist(),
            "predicted_speed_m_s": pred_v.tolist(),
            "height_m": d,
            "omega_d_rad_per_m": omega_d,
            "frames_per_speed": n_frames,
            "frame_rate_hz": rate,
            "spp_per_frame": params.vehicle_spp,
        }

    def vehicle_trajectory(self, setup: Setup, params: SpeedParams, rng: np.random.Generator,
                           show_progress: bool) -> dict:
        """Two sinusoid mixels, one on each side of a vehicle turning on a circle, give the two side speeds;
        with the vehicle's width they give the turn radius and heading change (paper Sec. 4.3, last paragraph)."""
        d, width, v, radius = params.vehicle_height_m, TURN_WIDTH_M, TURN_SPEED_M_S, TURN_RADIUS_M  # turning left
        rate, n_frames = params.vehicle_rate_hz, params.turn_frames
        cam = Mincam(tuple(
            sinusoid_mixel(setup, params.mask_period_m,
                           Pose((0.0, side * width / 2, d), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)), name)
            for side, name in ((1, "left"), (-1, "right"))
        ))
        size = v * n_frames / rate + width + 1.0
        road = objects.road_texture((512, 512), rng)  # ~7 mm texels: asphalt-scale grain
        road_matrix = Pose((size / 2 - 0.5, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0)).matrix() @ np.diag(
            [size / 2, size / 2, 1, 1])
        sim = Simulation(cam, world={"road": sd.textured_plane(road, 2.0, 2.0, np.eye(4)), "sky": sd.sky(1.0)})
        omega_d = float(scene_frequency(2 * np.pi / params.mask_period_m, setup.d_f_m, d))
        placements = []
        for i in range(n_frames):
            heading = v / radius * i / rate
            centre = np.array([radius * np.sin(heading), radius * (1 - np.cos(heading))])  # vehicle on its circle
            world_to_vehicle = Pose((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (-np.sin(-heading), np.cos(-heading), 0.0))
            move = world_to_vehicle.matrix()
            move[:2, 3] = -move[:2, :2] @ centre
            # the textured_plane spans [-1, 1]^2 scaled by 1 here, so road_matrix carries the road's size
            placements.append(move @ road_matrix)
        irr = sim.measure([{"road.to_world": m} for m in placements], solver=PlaneReplay("road"),  # turns in its plane
                          budget=Budget(spp=params.turn_spp, replicates=4, seed=setup.seed)).irradiance_w_m2
        dn = read_out(irr, irr.min(axis=0), setup.sensor(), rng, setup.exposure_fill).frames_dn
        speeds = [_speed(dn[:, k], rate, omega_d, 0.5 * v, params.difference_order, 1.5 * v) for k in range(2)]
        path = trajectory_from_speeds(np.array([speeds[0]]), np.array([speeds[1]]), width, n_frames / rate)
        true_left, true_right = v * (1 - width / (2 * radius)), v * (1 + width / (2 * radius))
        est_radius = float(path.turn_radius_m[0])
        return {
            "width_m": width,
            "true_turn_radius_m": radius,
            "estimated_turn_radius_m": est_radius,
            "turn_radius_error_pct": abs(est_radius / radius - 1) * 100,
            "true_side_speeds_m_s": [true_left, true_right],
            "estimated_side_speeds_m_s": speeds,
            "true_heading_change_rad": v / radius * n_frames / rate,
            "estimated_heading_change_rad": float(path.heading_change_rad[0]),
            "frames": n_frames,
            "frame_rate_hz": rate,
        }

    @staticmethod
    def _plots(spectra, omega_d, true_v, pred_v, v_min, out_dir, stem, unit, rate, order) -> None:
        signal, speed = spectra[len(spectra) // 2]
        spec = spectrum(np.diff(signal, n=order), rate, min_frequency_hz=0.5 * omega_d * v_min / (2 * np.pi))
        plot_spectrum(spec, omega_d * speed, out_dir / f"{stem}_spectrum.png",
                      title=f"spectrum of P(t) - P(t - dt) at {speed:g} {unit}")
        plot_speed(true_v, pred_v, out_dir / f"{stem}_prediction.png", unit=unit)

    def run(self, setup: Setup, params: SpeedParams, out_dir: Path, show_progress: bool = False) -> ExperimentResult:
        out_dir.mkdir(parents=True, exist_ok=True)
        limits = check_nyquist(setup, params)  # before any rendering
        rng = self.rng(setup)
        video = self.road_video(setup, params, rng, out_dir, show_progress)
        video["nyquist_speed_px_s"] = limits["video_nyquist_speed_px_s"]
        vehicle_limit = limits["vehicle_nyquist_speed_m_s"]
        vehicle = self.vehicle(setup, params, rng, out_dir, show_progress)
        trajectory = self.vehicle_trajectory(setup, params, rng, show_progress)
        vehicle["nyquist_speed_m_s"] = vehicle_limit
        return ExperimentResult.from_rates(self.name, video, self.paper,
                                           {"vehicle": vehicle, "vehicle_trajectory": trajectory})
