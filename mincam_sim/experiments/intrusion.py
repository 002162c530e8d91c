"""Paper Sec. 4.1: 1D intrusion detection at a finish line with two mixels, calibrated on a 50" screen."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mincam_sim.estimation.calibration import Calibration1D
from mincam_sim.estimation.estimators import intrusion_position
from mincam_sim.experiments.base import Experiment, ExperimentResult, PaperNumbers
from mincam_sim.experiments.ground_truth import GroundTruthCamera
from mincam_sim.experiments.layouts import intrusion_mincam
from mincam_sim.experiments.pipeline import LocateOptions, locate_in_world
from mincam_sim.experiments.screen_calibration import (
    fit_calibration_1d,
    screen_sweep_1d,
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
)
from mincam_sim.paper import (
    CALIBRATION_SQUARE_M,
    INTRUSION_AVG_ERROR_PCT,
    INTRUSION_BOUNDARY_X_M,
    INTRUSION_MAX_ERROR_PCT,
)
from mincam_sim.plotting.plots import plot_calibration_1d, plot_overlays
from mincam_sim.render.scene.elements import toy_updates
from mincam_sim.scene import objects
from mincam_sim.storage.atomic import atomic_save_npz


@dataclass(frozen=True)
class IntrusionParams:
    """Parameters of the intrusion experiment (``[intrusion]`` in a reproduce config).

    Attributes
    ----------
    boundary_x_m : float
        The finish line ``x = boundary_x_m`` [m] (paper: x0 = -13.78 cm).
    band_m : float
        Width of the boundary band the masks look at [m].
    calibration_positions : int
        White squares along the boundary on the screen.
    calibration_square_m : float
        Side of the calibration square [m].
    calibration_rel_stderr : float
        Target relative standard error of the rendered calibration sweep.
    frame_rate_hz : float
        Frames per second of the race video.
    lanes_y_m, speeds_m_s : tuple of float
        The two cars' lanes [m] and speeds [m/s].
    start_distance_m, overrun_m : float
        Where the race starts before the line and how far it runs past it [m].
    table_albedo : float
        Mean albedo of the printed table (the paper does not describe it; 0.4 is this simulator's choice).
    car_albedos : tuple of float
        Albedo of the two cars.
    car_height_m : float
        Height of the toy cars [m] (their shadows and parallax grow with it).
    light_size_m : float
        Side of the square area light 1.5 m over the table [m].
    ground_truth : {"object", "change"}
        The headline's ground truth: the centroid of the cars' part in the band as the ground-truth camera sees
        it (the paper's) or of the binary change there (with the shadow); both are reported.
    spp_fraction : float
        Share of the set-up's tabletop budget (``Setup.spp``) the race's dP spends, in (0, 1]. All of it: the
        pair's positions are limited by this Monte Carlo noise (full mode, seed 0, median over the scored frames:
        its position sigma is 3.2x the sensor's at the whole budget, 8.9x at a quarter; docs/experiments.md).
    """

    boundary_x_m: float = INTRUSION_BOUNDARY_X_M
    band_m: float = 0.03
    calibration_positions: int = 51
    calibration_square_m: float = CALIBRATION_SQUARE_M
    calibration_rel_stderr: float = 1e-3
    frame_rate_hz: float = 125.0  # full mode: a >= 300-frame video (the slower car's 2.4 s run)
    lanes_y_m: tuple[float, ...] = (-0.12, 0.07)
    speeds_m_s: tuple[float, ...] = (0.12, 0.09)
    start_distance_m: float = 0.12
    overrun_m: float = 0.1
    table_albedo: float = DEFAULT_TABLE_ALBEDO
    car_albedos: tuple[float, ...] = (0.9, 0.75)
    car_height_m: float = 0.035
    light_size_m: float = DEFAULT_LIGHT_SIZE_M
    ground_truth: str = "object"
    spp_fraction: float = 1.0

    def __post_init__(self) -> None:
        check_spp_fraction(self.spp_fraction)
        check_contrast(self.table_albedo, self.car_albedos, self.light_size_m, self.ground_truth, "car_albedos")
        if len(self.car_albedos) != 2:
            raise ValueError(f"car_albedos must list the two cars' albedos, got {list(self.car_albedos)}")
        if not 0.02 < self.car_height_m <= 0.2:
            raise ValueError(f"car_height_m must be in (0.02, 0.2] m (the wheels are 2 cm high), got "
                             f"{self.car_height_m!r}")
        for key in ("band_m", "calibration_square_m", "calibration_rel_stderr", "frame_rate_hz", "start_distance_m",
                    "overrun_m"):
            if not getattr(self, key) > 0:
                raise ValueError(f"{key} must be > 0, got {getattr(self, key)!r}")
        if self.calibration_positions < 5:
            raise ValueError(f"calibration_positions must be >= 5 (a cubic needs 4), got {self.calibration_positions}")
        if len(self.lanes_y_m) != 2 or len(self.speeds_m_s) != 2:
            raise ValueError("lanes_y_m and speeds_m_s must each list the two cars' values")
        for k, v in enumerate(self.speeds_m_s):
            if not (np.isfinite(v) and 0 < v <= 10):
                raise ValueError(f"speeds_m_s[{k}] must be a car's speed in m/s, > 0 and <= 10, got {v!r}")
        if not (np.isfinite(self.boundary_x_m) and abs(self.boundary_x_m) < 1.0):
            raise ValueError(f"boundary_x_m must lie in the calibrated field (|x| < 1 m; the paper's is "
                             f"{INTRUSION_BOUNDARY_X_M}), got {self.boundary_x_m!r}")


@dataclass
class IntrusionScene:
    """The race: the tabletop, per-frame toy placements and the empty background."""

    table: object
    frames: list
    background: dict
    meshes: list  # per frame: (world vertices, faces) of both cars (the object ground truth)


class Intrusion(Experiment):
    """Two mixels (band ramps y | 1 - y, Eq. 4) locate toy cars crossing a finish line."""

    name = "intrusion"
    paper_section = "4.1"
    paper = PaperNumbers(max_error_pct=INTRUSION_MAX_ERROR_PCT, avg_error_pct=INTRUSION_AVG_ERROR_PCT)
    Params = IntrusionParams
    quick_overrides = {"calibration_positions": 26, "calibration_rel_stderr": 3e-3, "frame_rate_hz": 5.0}
    seed_offset = 0
    study_metrics = ("avg_error_pct", "max_error_pct", "rms_error_pct", "noise_sigma_median_pct", "unscored_frames_pct",
                     "missed_frames", "false_alarm_frames")
    study_seconds = (60.0, 1200.0)

    def calibrate(self, setup: Setup, params: IntrusionParams, rng: np.random.Generator,
                  out_dir: Path) -> dict:
        """Sweep a white square along the boundary on the screen; fit the cubic f(x_obs) -> true position."""
        cam = intrusion_mincam(setup, params.boundary_x_m, params.band_m)
        sweep = screen_sweep_1d(setup, params.boundary_x_m, params.calibration_positions, params.calibration_square_m)
        sweep, n_unseen = visible_sweep(cam, setup, sweep)
        change, reached = sweep_change_dn(cam, setup, sweep, rng, params.calibration_rel_stderr)
        observed = intrusion_position(change[:, 0], change[:, 1])
        true = sweep.positions_m[:, 1]
        cal = fit_calibration_1d(observed, true, {"experiment": self.name, "boundary_x_m": params.boundary_x_m,
                                                  "depth_m": setup.depth_m, "spacing_m": setup.spacing_m})
        cal.to_json(out_dir / "intrusion_calibration.json")
        return {"true_m": true, "change_dn": change, "observed": observed, "calibration": cal,
                "mc_rel_stderr": reached, "points_outside_view": n_unseen}

    def scene(self, setup: Setup, params: IntrusionParams, rng: np.random.Generator) -> IntrusionScene:
        cars = {name: objects.toy_car(height_m=params.car_height_m, albedo=albedo)
                for name, albedo in zip(("car_a", "car_b"), params.car_albedos, strict=True)}
        table = make_tabletop(setup, cars, rng, params.table_albedo, params.light_size_m)
        car_a, car_b = objects.race_pair(finish_line_x_m=params.boundary_x_m, lanes_y_m=params.lanes_y_m,
                                         speeds_m_s=params.speeds_m_s, start_distance_m=params.start_distance_m,
                                         overrun_m=params.overrun_m, frame_rate_hz=params.frame_rate_hz)
        placements = [{"car_a": (car_a.positions_m[i], car_a.headings_rad[i]),
                       "car_b": (car_b.positions_m[i], car_b.headings_rad[i])} for i in range(len(car_a.times_s))]
        frames = [toy_updates(table, p) for p in placements]
        return IntrusionScene(table, frames, toy_updates(table, {}), [placed_meshes(table, p) for p in placements])

    @staticmethod
    def cars_in_band(scene: IntrusionScene, camera: GroundTruthCamera, boundary_x_m: float,
                     band_m: float) -> list[str]:
        """Per frame, which car the ground-truth camera sees in the boundary band: "car_a", "car_b", "both"
        or "neither" (from the x extent of each car's projected vertices)."""
        labels = []
        for meshes in scene.meshes:
            inside = []
            for name, (vertices, _) in zip(("car_a", "car_b"), meshes, strict=True):
                x = camera.project_to_table(vertices)[:, 0]
                if x.max() >= boundary_x_m - band_m / 2 and x.min() <= boundary_x_m + band_m / 2:
                    inside.append(name)
            labels.append("both" if len(inside) == 2 else inside[0] if inside else "neither")
        return labels

    def run(self, setup: Setup, params: IntrusionParams, out_dir: Path,
            show_progress: bool = False) -> ExperimentResult:
        out_dir.mkdir(parents=True, exist_ok=True)
        rng = self.streams(setup, ("calibration", "scene", "readout"))
        cal = self.calibrate(setup, params, rng["calibration"], out_dir)
        scene = self.scene(setup, params, rng["scene"])
        camera = GroundTruthCamera.for_setup(setup)
        cam = intrusion_mincam(setup, params.boundary_x_m, params.band_m)
        world = tabletop_world(setup, scene.table, cam, camera)
        truth_world = tabletop_world(setup, scene.table, cam, camera)  # the ground truth's own scene
        calibration: Calibration1D = cal["calibration"]

        def predict(c, min_total_dn):
            return calibration.apply(intrusion_position(c[:, 0], c[:, 1], min_total_dn))

        def outside(c, min_total_dn):
            return calibration.outside_range(intrusion_position(c[:, 0], c[:, 1], min_total_dn))

        rows, cols = np.indices((camera.pixels, camera.pixels))
        xy = camera.pixel_to_table(rows, cols, (camera.pixels, camera.pixels))
        band = np.abs(xy[..., 0] - params.boundary_x_m) <= params.band_m / 2
        options = LocateOptions(predict, region=band, axis=1, extrapolated=outside,
                                objects=scene.meshes, ground_truth=params.ground_truth,
                                groups=self.cars_in_band(scene, camera, params.boundary_x_m, params.band_m),
                                spp_fraction=params.spp_fraction, show_progress=show_progress)
        found = locate_in_world(world, camera, scene.frames, scene.background, setup, rng["readout"], options,
                                truth_world)
        a = found.arrays
        plot_calibration_1d(cal["true_m"], cal["change_dn"], cal["observed"], calibration,
                            out_dir / "intrusion_calibration.png", names=("y", "1-y"))
        chosen = found.example_frames()
        line = params.boundary_x_m
        plot_overlays([found.images[i] for i in chosen],
                      [(np.array([line, a["predicted_m"][i]]), np.array([line, a["truth_m"][i]])) for i in chosen],
                      camera.half_extent_m, out_dir / "intrusion_frames.png", frame_numbers=chosen,
                      boundary_x_m=line, title="intrusion at the finish line", field_m=setup.field_m)
        atomic_save_npz(out_dir / "intrusion_data.npz", **a)
        return ExperimentResult.from_rates(self.name, found.summary, self.paper, {
            "calibration_rms_residual_m": calibration.rms_residual_m,
            "calibration_mc_worst_rel_stderr": cal["mc_rel_stderr"],
            "calibration_points": len(cal["true_m"]),
            "calibration_points_outside_view": cal["points_outside_view"],
        })
