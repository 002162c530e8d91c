"""The aperture solver: rays from each detector through its mask aperture, all mixels in one kernel.

Displays: a frame's replicate estimates by the ``mixel_sensor`` plugin (the fast form) over the frame on the
screen. Worlds: each frame's parameter updates applied to the scene as built, then the same kernel
(absolute ``P`` per frame; changes against a background are the change solvers').
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from mincam_sim.budget import Budget
from mincam_sim.measurements import Measurements
from mincam_sim.render import backend
from mincam_sim.render.kernels.change_geometry import moving_shapes
from mincam_sim.render.kernels.monte_carlo import replicate_mean_stderr, warn_unreached
from mincam_sim.render.scene.world_checks import EngulfWatch
from mincam_sim.render.solvers.base import DisplayRaySolver, Plan, Row, check_update_frames

DEFAULT_WORLD_REPLICATES = 8


@dataclass(frozen=True)
class Aperture(DisplayRaySolver):
    """Rays from the detector through the mask aperture, all mixels in one kernel (the fast form)."""

    name: ClassVar[str] = "aperture"
    scenes: ClassVar[tuple[str, ...]] = ("display", "world")
    form: ClassVar[str] = "fast"
    estimator: ClassVar[str] = "mixel_sensor_path"

    def budget_fields(self, kind: str) -> tuple[str, ...]:
        # a world frame is traced once at the budget's rays: no target search, so no cap
        return self.budget_reads if kind == "display" else ("spp", "replicates", "seed")

    def prepare(self, scene) -> None:
        backend.require_jit("The fast mixel sensor (a Python Mitsuba plugin)")
        _ = scene.fast_scene

    def estimates(self, scene, spp: int, replicates: int, seed: int) -> np.ndarray:
        return scene.fast_estimates(spp, replicates, seed)

    def plan(self, sim, frames, budget: Budget, *, background=None, cache=None, show_progress: bool = False) -> Plan:
        if sim.kind == "display":
            return super().plan(sim, frames, budget, show_progress=show_progress)
        return WorldAperturePlan(self, sim, frames, budget)


class WorldAperturePlan(Plan):
    """Each frame's updates on top of the scene as built, traced with the budget's rays and seed; the scene is
    left as built."""

    def __init__(self, solver: Aperture, sim, frames, budget: Budget) -> None:
        self.solver, self.sim, self.frames = solver, sim, check_update_frames(frames)
        self.budget, self.replicates = budget, budget.replicates_or(DEFAULT_WORLD_REPLICATES)
        self.as_built = sim.complete_background(self.frames, {})
        self.n_rows, self.columns = len(self.frames), list(sim.mincam.names)
        self.engulf = EngulfWatch(sim.scene_mincam, sim.known_parts)  # a moved shape closing round a mixel: said once

    def estimates(self, pending: np.ndarray) -> Iterator[tuple[int, np.ndarray]]:
        """(frame index, (replicates, n_mixels) estimates) of each pending frame."""
        sim = self.sim
        try:
            for i in pending:
                sim.update(self.as_built)
                sim.update(self.frames[int(i)])
                shapes = sim.shapes_by_id
                self.engulf.check(sim.scene, [shapes[name] for name in sorted(moving_shapes([self.frames[int(i)]]))
                                              if name in shapes], f"frame {int(i)}")
                yield int(i), sim.mincam_scene.fast_estimates(self.budget.rays(), self.replicates, self.budget.seed)
        finally:
            sim.update(self.as_built)

    def rows(self, pending: np.ndarray) -> Iterator[Row]:
        for i, estimates in self.estimates(pending):
            mean, err = replicate_mean_stderr(estimates)
            yield [i], mean[None], err[None]

    def result(self, values: np.ndarray, errors: np.ndarray) -> Measurements:
        meta = {"solver": self.solver.name, "form": "fast_world", "seed": self.budget.seed,
                "replicates": self.replicates, "spp_per_mixel_per_frame": self.budget.rays(), **self.sim.world_meta()}
        shape = (self.n_rows, len(self.columns))  # (0, n_mixels) for no frames
        m = Measurements(values.reshape(shape), errors.reshape(shape), self.sim.mincam.names, meta)
        warn_unreached(m)  # 0 +/- 0: nothing lit was reached, not a certain zero
        return m


__all__ = ["Aperture", "WorldAperturePlan"]
