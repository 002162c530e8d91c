"""Paper Sec. 4.2: naive tracking of wind-up toys with four mixels (x, 1 - x, y, 1 - y), calibrated on a grid
of white squares on the 50" screen (3rd-degree 2D polynomial)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mincam_sim.estimation.calibration import Calibration2D
from mincam_sim.estimation.estimators import track_4
from mincam_sim.experiments.base import Experiment, ExperimentResult, PaperNumbers
from mincam_sim.experiments.ground_truth import GroundTruthCamera
from mincam_sim.experiments.layouts import tracking_mincam
from mincam_sim.experiments.pipeline import LocateOptions, locate_in_world
from mincam_sim.experiments.screen_calibration import (
    fit_calibration_2d,
    screen_sweep_2d,
    sweep_change_dn,
    visible_sweep,
)
from mincam_sim.experiments.setup import Setup
from mincam_sim.experiments.tabletop_world import (
    DEFAULT_LIGHT_SIZE_M,
    DEFAULT_TABLE_ALBEDO,
    check_contrast,
    check_spp_fraction,
    make_tabletop,
    placed_meshes,
    tabletop_world,
    with_height_scale,
)
from mincam_sim.paper import CALIBRATION_SQUARE_M, TRACKING_AVG_ERROR_PCT, TRACKING_MAX_ERROR_PCT
from mincam_sim.plotting.plots import plot_calibration_2d, plot_overlays, plot_tracks
from mincam_sim.render.scene.elements import toy_updates
from mincam_sim.scene import objects
from mincam_sim.storage.atomic import atomic_save_npz


@dataclass(frozen=True)
class TrackingParams:
    """Parameters of the tracking experiment (``[tracking]`` in a reproduce config).

    Attributes
    ----------
    toys : tuple of str
        Wind-up toys, one path each (``objects.windup_toy`` kinds).
    toy_size_m : float
        Toy size [m].
    frames_per_toy : int
        Frames of each toy's random smooth path.
    frame_interval_s : float
        Time between frames [s]; toys walk at ``toy_speed_m_s``.
    toy_speed_m_s : float
        Walking speed [m/s].
    reach_fraction : float
        Paths stay within this fraction of the calibrated field around the centre.
    calibration_grid : int
        Calibration squares per axis (a grid clipped to the field's disc).
    calibration_square_m : float
        Side of the calibration square [m].
    calibration_rel_stderr : float
        Target relative standard error of the rendered calibration sweep.
    table_albedo : float
        Mean albedo of the printed table (the paper does not describe its background; 0.4, mid-grey, is this
        simulator's choice; 0.1 is a dark table). It sets the contrast: a bright toy's brightening on a grey
        table is largely cancelled by its shadow and dark sides.
    toy_albedos : tuple of float
        Albedo of each toy, one per entry of ``toys``; empty (the default): each kind's own
        (:data:`~mincam_sim.scene.objects.DEFAULT_TOY_ALBEDO`: robot 0.75, chick 0.9, frog 0.7).
    toy_height_scale : float
        Scale of the toys' heights (1: as modelled; e.g. 0.02: flat prints of their footprints, no shadow).
    light_size_m : float
        Side of the square area light 1.5 m over the table [m] (the paper's lamp is not described).
    ground_truth : {"object", "change"}
        What the headline rates are scored against: the centroid of the object in the ground-truth camera (the
        paper's definition) or the centroid of the binary change (object and shadow); both are reported.
    spp_fraction : float
        Share of the set-up's tabletop budget (``Setup.spp``) the toys' dP spends, in (0, 1]; default all of it.
        A quarter cuts ``reproduce all``'s CPU time by ~21 % but raises the Monte Carlo part of the positions'
        sigma from 0.20x to 0.39x the sensor's on the grey table (+7 % to the total) and from 0.29x to 0.65x on
        the dark one (+19 %), and moves some table numbers by more than their Monte Carlo spread
        (docs/experiments.md, "The tabletop's Monte Carlo budget").
    """

    toys: tuple[str, ...] = ("robot", "chick", "frog")
    toy_size_m: float = 0.07
    frames_per_toy: int = 100  # full mode: a 300-frame video
    frame_interval_s: float = 0.5
    toy_speed_m_s: float = 0.04
    reach_fraction: float = 0.4
    calibration_grid: int = 15
    calibration_square_m: float = CALIBRATION_SQUARE_M
    calibration_rel_stderr: float = 1e-3
    table_albedo: float = DEFAULT_TABLE_ALBEDO
    toy_albedos: tuple[float, ...] = ()
    toy_height_scale: float = 1.0
    light_size_m: float = DEFAULT_LIGHT_SIZE_M
    ground_truth: str = "object"
    spp_fraction: float = 1.0

    def __post_init__(self) -> None:
        check_spp_fraction(self.spp_fraction)
        check_contrast(self.table_albedo, self.toy_albedos, self.light_size_m, self.ground_truth, "toy_albedos")
        if self.toy_albedos and len(self.toy_albedos) != len(self.toys):
            raise ValueError(f"toy_albedos must give one albedo per toy: toys lists {len(self.toys)}, "
                             f"toy_albedos {len(self.toy_albedos)}; set both, or leave toy_albedos out (each "
                             "kind's own albedo)")
        for key in ("toy_size_m", "frame_interval_s", "toy_speed_m_s", "calibration_square_m",
                    "calibration_rel_stderr", "toy_height_scale"):
            if not getattr(self, key) > 0:
                raise ValueError(f"{key} must be > 0, got {getattr(self, key)!r}")
        if not 0 < self.reach_fraction <= 0.5:
            raise ValueError(f"reach_fraction must be in (0, 0.5], got {self.reach_fraction!r}")
        if not 0 < self.toy_size_m <= 0.2:
            raise ValueError(f"toy_size_m must be in (0, 0.2] m (a toy on the 50 cm field; the paper's are ~7 cm), "
                             f"got {self.toy_size_m!r}")
        if self.frames_per_toy < 2 or self.calibration_grid < 4 or not self.toys:
            raise ValueError("need frames_per_toy >= 2 (a path), calibration_grid >= 4 and at least one toy")


@dataclass
class TrackingScene:
    """Toys walking one after the other: the tabletop, per-frame placements, which toy each frame shows."""

    table: object
    frames: list
    toy_of_frame: np.ndarray
    background: dict
    meshes: list  # per frame: (world vertices, faces) of the placed toy (the object ground truth)


class Tracking(Experiment):
    """Four mixels (ramps, Eq. 7 + cubic 2D calibration) track wind-up toys on a table."""

    name = "tracking"
    paper_section = "4.2"
    paper = PaperNumbers(max_error_pct=TRACKING_MAX_ERROR_PCT, avg_error_pct=TRACKING_AVG_ERROR_PCT)
    Params = TrackingParams
    quick_overrides = {"toys": ("robot", "chick"), "frames_per_toy": 8, "calibration_grid": 9,
                       "calibration_rel_stderr": 3e-3}
    seed_offset = 1
    version = 2  # 2: its dP budget a share of the set-up's (spp_fraction)
    study_version = 2  # 2: its dP budget a share of the set-up's (spp_fraction)
    study_metrics = ("avg_error_pct", "max_error_pct", "rms_error_pct", "noise_sigma_median_pct", "unscored_frames_pct",
                     "missed_frames", "false_alarm_frames")
    study_seconds = (60.0, 1800.0)

    def calibrate(self, setup: Setup, params: TrackingParams, rng: np.random.Generator, out_dir: Path) -> dict:
        """A grid of white squares on the screen; fit the bivariate cubic from Eq. 7's output to positions."""
        cam = tracking_mincam(setup)
        sweep, n_unseen = visible_sweep(cam, setup, screen_sweep_2d(setup, params.calibration_grid,
                                                                     params.calibration_square_m))
        change, reached = sweep_change_dn(cam, setup, sweep, rng, params.calibration_rel_stderr)
        observed = track_4(change)
        cal = fit_calibration_2d(observed, sweep.positions_m, {"experiment": self.name, "depth_m": setup.depth_m,
                                                               "spacing_m": setup.spacing_m})
        cal.to_json(out_dir / "tracking_calibration.json")
        return {"true_m": sweep.positions_m, "observed": observed, "calibration": cal, "mc_rel_stderr": reached,
                "points_outside_view": n_unseen}

    def scene(self, setup: Setup, params: TrackingParams, rng: np.random.Generator) -> TrackingScene:
        toys = {kind: with_height_scale(objects.windup_toy(kind, size_m=params.toy_size_m, albedo=albedo),
                                        params.toy_height_scale)
                for kind, albedo in zip(params.toys, params.toy_albedos or (None,) * len(params.toys), strict=True)}
        table = make_tabletop(setup, toys, rng, params.table_albedo, params.light_size_m)
        frames, sequence, meshes = [], [], []
        reach = params.reach_fraction * setup.field_m
        for k, kind in enumerate(params.toys):
            path = objects.random_smooth_path(np.random.default_rng(setup.seed + 10 + k), params.frames_per_toy,
                                              dt_s=params.frame_interval_s, bounds_m=((-reach, reach), (-reach, reach)),
                                              speed_m_s=params.toy_speed_m_s)
            for i in range(params.frames_per_toy):
                placement = {kind: (path.positions_m[i], path.headings_rad[i])}
                frames.append(toy_updates(table, placement))
                meshes.append(placed_meshes(table, placement))
                sequence.append(kind)
        return TrackingScene(table, frames, np.array(sequence), toy_updates(table, {}), meshes)

    def run(self, setup: Setup, params: TrackingParams, out_dir: Path,
            show_progress: bool = False) -> ExperimentResult:
        out_dir.mkdir(parents=True, exist_ok=True)
        rng = self.streams(setup, ("calibration", "scene", "readout"))
        cal = self.calibrate(setup, params, rng["calibration"], out_dir)
        scene = self.scene(setup, params, rng["scene"])
        camera = GroundTruthCamera.for_setup(setup)
        world = tabletop_world(setup, scene.table, tracking_mincam(setup), camera)
        truth_world = tabletop_world(setup, scene.table, tracking_mincam(setup), camera)  # the ground truth's own
        calibration: Calibration2D = cal["calibration"]

        def predict(c, min_total_dn):
            return calibration.apply(track_4(c, min_total_dn))

        def outside(c, min_total_dn):
            return calibration.outside_range(track_4(c, min_total_dn))

        options = LocateOptions(predict, extrapolated=outside, objects=scene.meshes,
                                ground_truth=params.ground_truth, groups=scene.toy_of_frame.tolist(),
                                spp_fraction=params.spp_fraction, show_progress=show_progress)
        found = locate_in_world(world, camera, scene.frames, scene.background, setup, rng["readout"], options,
                                truth_world)
        a = found.arrays
        predicted, truth = a["predicted_m"], a["truth_m"]
        plot_calibration_2d(cal["true_m"], cal["observed"], calibration, out_dir / "tracking_calibration.png")
        plot_tracks(predicted, truth, scene.toy_of_frame, out_dir / "tracking_paths.png")
        chosen = found.example_frames()
        plot_overlays([found.images[i] for i in chosen], [(predicted[i], truth[i]) for i in chosen],
                      camera.half_extent_m, out_dir / "tracking_frames.png", frame_numbers=chosen,
                      title="tracking wind-up toys", field_m=setup.field_m)
        atomic_save_npz(out_dir / "tracking_data.npz", **a)
        return ExperimentResult.from_rates(self.name, found.summary, self.paper, {
            "toys": list(params.toys),
            "calibration_points": len(cal["true_m"]),
            "calibration_points_outside_view": cal["points_outside_view"],
            "calibration_rms_residual_m": np.asarray(calibration.rms_residual_m).tolist(),  # (x, y)
            "calibration_mc_worst_rel_stderr": cal["mc_rel_stderr"],
        })
