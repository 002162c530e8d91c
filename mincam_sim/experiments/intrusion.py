"""Paper Sec. 4.1: 1D intrusion detection at a finish line with two mixels, calibrated on a 50" screen."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import objects
from ..calibration import Calibration1D
from ..estimators import intrusion_position
from ..plots import plot_calibration_1d, plot_overlays
from ..render.elements import toy_updates
from .base import Experiment, ExperimentResult, PaperNumbers
from .ground_truth import GroundTruthCamera
from .layouts import intrusion_mincam
from .pipeline import locate_in_world
from .screen_calibration import fit_calibration_1d, screen_sweep_1d, sweep_change_dn, visible_sweep
from .setup import Setup
from .tabletop_world import make_tabletop, tabletop_world


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
    """

    boundary_x_m: float = -0.1378
    band_m: float = 0.03
    calibration_positions: int = 51
    calibration_square_m: float = 0.03
    calibration_rel_stderr: float = 1e-3
    frame_rate_hz: float = 125.0  # full mode: a >= 300-frame video (the slower car's 2.4 s run)
    lanes_y_m: tuple[float, ...] = (-0.12, 0.07)
    speeds_m_s: tuple[float, ...] = (0.12, 0.09)
    start_distance_m: float = 0.12
    overrun_m: float = 0.1

    def __post_init__(self) -> None:
        for key in ("band_m", "calibration_square_m", "calibration_rel_stderr", "frame_rate_hz"):
            if not getattr(self, key) > 0:
                raise ValueError(f"{key} must be > 0, got {getattr(self, key)!r}")
        if self.calibration_positions < 5:
            raise ValueError(f"calibration_positions must be >= 5 (a cubic needs 4), got {self.calibration_positions}")
        if len(self.lanes_y_m) != 2 or len(self.speeds_m_s) != 2:
            raise ValueError("lanes_y_m and speeds_m_s must each list the two cars' values")


@dataclass
class IntrusionScene:
    """The race: the tabletop, per-frame toy placements and the empty background."""

    table: object
    frames: list
    background: dict


class Intrusion(Experiment):
    """Two mixels (band ramps y | 1 - y, Eq. 4) locate toy cars crossing a finish line."""

    name = "intrusion"
    paper_section = "4.1"
    paper = PaperNumbers(max_error_pct=11.42, avg_error_pct=4.83)
    Params = IntrusionParams
    quick_overrides = {"calibration_positions": 26, "calibration_rel_stderr": 3e-3, "frame_rate_hz": 5.0}
    seed_offset = 0

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
        cars = {"car_a": objects.toy_car(albedo=0.9), "car_b": objects.toy_car(albedo=0.75)}
        table = make_tabletop(setup, cars, rng)
        car_a, car_b = objects.race_pair(finish_line_x_m=params.boundary_x_m, lanes_y_m=params.lanes_y_m,
                                         speeds_m_s=params.speeds_m_s, start_distance_m=params.start_distance_m,
                                         overrun_m=params.overrun_m, frame_rate_hz=params.frame_rate_hz)
        frames = [toy_updates(table, {"car_a": (car_a.positions_m[i], car_a.headings_rad[i]),
                                     "car_b": (car_b.positions_m[i], car_b.headings_rad[i])})
                  for i in range(len(car_a.times_s))]
        return IntrusionScene(table, frames, toy_updates(table, {}))

    def run(self, setup: Setup, params: IntrusionParams, out_dir: Path,
            show_progress: bool = False) -> ExperimentResult:
        out_dir.mkdir(parents=True, exist_ok=True)
        rng = self.streams(setup, ("calibration", "scene", "readout"))
        cal = self.calibrate(setup, params, rng["calibration"], out_dir)
        scene = self.scene(setup, params, rng["scene"])
        camera = GroundTruthCamera.for_setup(setup)
        cam = intrusion_mincam(setup, params.boundary_x_m, params.band_m)
        world = tabletop_world(setup, scene.table, cam, camera)
        calibration: Calibration1D = cal["calibration"]

        def predict(c, min_total_dn):
            return calibration.apply(intrusion_position(c[:, 0], c[:, 1], min_total_dn))

        def outside(c, min_total_dn):
            return calibration.outside_range(intrusion_position(c[:, 0], c[:, 1], min_total_dn))

        rows, cols = np.indices((camera.pixels, camera.pixels))
        xy = camera.pixel_to_table(rows, cols, (camera.pixels, camera.pixels))
        band = np.abs(xy[..., 0] - params.boundary_x_m) <= params.band_m / 2
        found = locate_in_world(world, camera, scene.frames, scene.background, setup, rng["readout"], predict,
                                setup.tabletop_spp, region=band, axis=1, show_progress=show_progress,
                                extrapolated=outside)
        a = found.arrays
        plot_calibration_1d(cal["true_m"], cal["change_dn"], cal["observed"], calibration,
                            out_dir / "intrusion_calibration.png", names=("y", "1-y"))
        chosen = found.example_frames()
        line = params.boundary_x_m
        plot_overlays([found.images[i] for i in chosen],
                      [(np.array([line, a["predicted_m"][i]]), np.array([line, a["truth_m"][i]])) for i in chosen],
                      camera.half_extent_m, out_dir / "intrusion_frames.png", frame_numbers=chosen,
                      boundary_x_m=line, title="intrusion at the finish line", field_m=setup.field_m)
        np.savez(out_dir / "intrusion_data.npz", **a)
        return ExperimentResult.from_rates(self.name, found.summary, self.paper, {
            "calibration_rms_residual_m": calibration.rms_residual_m,
            "calibration_mc_worst_rel_stderr": cal["mc_rel_stderr"],
            "calibration_points": len(cal["true_m"]),
            "calibration_points_outside_view": cal["points_outside_view"],
        })
