"""The solver base class and its plan: what every estimator of the mixel integral gives the front door.

A :class:`Solver` is a small frozen dataclass of options. :meth:`Solver.plan` looks at a
:class:`~mincam_sim.render.simulation.Simulation`, the frames and a :class:`~mincam_sim.budget.Budget`, resolves
the budget (pilots, target searches) and returns a :class:`Plan`: how many rows (frames) it measures, their
columns, the rows themselves (``rows(pending)``, for the frames still to do), and the typed result built from every
row (``result(values, errors)``). :meth:`Simulation.measure` runs a plan through a
:class:`~mincam_sim.frames.FrameSink`; a :class:`mincam_sim.runs.run.Run` hands it a store that resumes.

The display ray solvers (:class:`~.aperture.Aperture` and :class:`~.reference.Reference`) share
:class:`DisplayRayPlan` here: each says only how one frame's replicate estimates are traced.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass
from typing import Any, ClassVar

import numpy as np

from mincam_sim.budget import Budget
from mincam_sim.errors import InputError
from mincam_sim.measurements import Measurements
from mincam_sim.progress import progress
from mincam_sim.render import backend
from mincam_sim.render.kernels.mask_eval import mask_model_meta
from mincam_sim.render.kernels.monte_carlo import (
    check_counts,
    derive_seed,
    pilot_to_target,
    replicate_mean_stderr,
    warn_target_missed,
    warn_unreached,
    worst_relative_stderr,
)
from mincam_sim.render.scene.mincam_scene import geometry_meta

Row = tuple[Any, np.ndarray, np.ndarray]
DEFAULT_RAY_REPLICATES = 8  # display rays: independent groups per measurement
MAX_DISPLAY_SPP = 1 << 28  # cap of a display ray solver's target search


class Plan:
    """A measurement with its budget resolved.

    Attributes
    ----------
    n_rows : int
        Rows (frames) it measures.
    columns : list of str
        The columns of a row (the mixels, or a change run's dP, P, flags and info).
    """

    n_rows: int
    columns: list[str]

    def rows(self, pending: np.ndarray) -> Iterator[Row]:
        """``(indices, values, stderr)`` of the frames in ``pending``, one frame or one chunk at a time."""
        raise NotImplementedError

    def result(self, values: np.ndarray, errors: np.ndarray):
        """The typed result (:class:`~mincam_sim.measurements.Measurements` or
        :class:`~mincam_sim.changes.Changes`) from every row, with what it says about itself."""
        raise NotImplementedError


@dataclass(frozen=True)
class Solver:
    """Base of every solver: ``name`` is what results record; ``scenes`` which scene kinds it solves;
    ``changes`` whether it measures changes against a background (``Simulation.measure_changes``)."""

    name: ClassVar[str] = "solver"
    scenes: ClassVar[tuple[str, ...]] = ()
    changes: ClassVar[bool] = False
    #: The :class:`~mincam_sim.budget.Budget` fields this solver reads; one it does not read is ignored, with one
    #: warning when set (``Simulation`` checks).
    budget_reads: ClassVar[tuple[str, ...]] = ("spp", "target_rel_stderr", "replicates", "seed", "max_spp")

    def budget_fields(self, kind: str) -> tuple[str, ...]:
        """The budget fields this solver reads on ``kind`` scenes (``"display"`` or ``"world"``)."""
        return self.budget_reads

    def identity(self) -> dict:
        """What of this solver determines the numbers: its name and every option (JSON-able)."""
        return {"solver": self.name, **{k: _jsonable(v) for k, v in asdict(self).items()}}

    def check(self, kind: str, changes: bool) -> None:
        """Refuse a scene kind this solver does not solve, or the wrong measurement (absolute or changes)."""
        if kind not in self.scenes:
            raise InputError(f"the {self.name} solver does not solve {kind} scenes; use one of its kinds: "
                             f"{', '.join(self.scenes)}")
        if changes and not self.changes:
            raise InputError(f"measure_changes needs a change solver (StratifiedChange or PlainChange), got "
                             f"{self.name}")
        if self.changes and not changes:
            raise InputError(f"the {self.name} solver measures changes against a background: use "
                             "measure_changes(frames, background, solver=...)")

    def plan(self, sim, frames, budget: Budget, *, background=None, cache=None, show_progress: bool = False) -> Plan:
        """The ``Plan`` of measuring ``frames`` in ``sim`` with ``budget`` (``background``: change solvers;
        ``cache``: a content cache for intermediate results such as response maps)."""
        raise NotImplementedError


def _jsonable(value):
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


class DisplayRaySolver(Solver):
    """A display solver that traces rays per frame (its :meth:`estimates`); plans are :class:`DisplayRayPlan`."""

    form: ClassVar[str] = ""
    estimator: ClassVar[str] = ""

    def prepare(self, scene) -> None:
        """Build what the estimates need before the first frame."""

    def estimates(self, scene, spp: int, replicates: int, seed: int) -> np.ndarray:
        """(replicates, n_mixels) independent estimates of the frame on the screen, ``spp / replicates`` rays each."""
        raise NotImplementedError

    def meta(self) -> dict:
        return {}

    def plan(self, sim, frames, budget: Budget, *, background=None, cache=None, show_progress: bool = False):
        return DisplayRayPlan(self, sim, frames, budget, show_progress)


class DisplayRayPlan(Plan):
    """A display ray solver at ``spp`` rays per mixel per frame, or at the count its pilots extrapolate to the
    target (:func:`..estimation.pilot_to_target`, on up to 4 frames spread over the run)."""

    def __init__(self, solver: DisplayRaySolver, sim, frames, budget: Budget, show_progress: bool) -> None:
        self.solver, self.sim, self.show_progress = solver, sim, show_progress
        self.frames, self.replicates = sim.frame_source(frames), budget.replicates_or(DEFAULT_RAY_REPLICATES)
        check_counts(1, self.replicates)
        self.scene = sim.display_scene(solver.form)
        solver.prepare(self.scene)
        self.seed, self.target = budget.seed, budget.target_rel_stderr
        self.cap = budget.max_spp or MAX_DISPLAY_SPP  # the target search's cap, rays per mixel per frame
        self.n_rows, self.columns = len(self.frames), list(sim.mincam.names)
        spp, self.provenance = budget.rays(), {}
        if self.target > 0:
            pilot_spp = self.replicates * 2048
            pilot_idx = np.unique(np.linspace(0, len(self.frames) - 1, min(4, len(self.frames))).astype(int))
            pilot_frames = self.frames[pilot_idx]

            def pilot(samples: int):
                return self._measure(pilot_frames, samples, derive_seed(self.seed, "pilot"))

            spp, trail = pilot_to_target(pilot, pilot_spp, self.target, self.cap, significance=0.0)
            self.provenance.update(pilot_spp=pilot_spp, pilot_trail=trail)
        self.spp = int(spp)

    def _measure(self, frames: np.ndarray, spp: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
        check_counts(spp, self.replicates)
        values, errors = [], []
        for frame in frames:
            self.scene.set_frame(self.sim.screen.check_frame(frame))
            mean, err = replicate_mean_stderr(self.solver.estimates(self.scene, spp, self.replicates, seed))
            values.append(mean)
            errors.append(err)
        return np.array(values), np.array(errors)

    def rows(self, pending: np.ndarray) -> Iterator[Row]:
        for i in progress([pending[i : i + 1] for i in range(len(pending))], desc=f"{self.solver.form}: frames",
                          disable=not self.show_progress, total=len(pending), unit="frame"):
            values, errors = self._measure(self.frames[i], self.spp, self.seed)
            yield i, values, errors

    def result(self, values: np.ndarray, errors: np.ndarray) -> Measurements:
        mincam, replicates = self.sim.mincam, self.replicates
        meta = {"form": self.solver.form, "estimator": self.solver.estimator,
                "spp_per_mixel_per_frame": int(replicates * max(1, -(-self.spp // replicates))),
                "replicates": replicates, "seed": self.seed,
                "units": "W/m^2 (irradiance averaged over the detector)",
                "masks": {m.name: mask_model_meta(m.mask) for m in mincam},
                **backend.describe(), **geometry_meta(mincam, self.sim.screen), **self.solver.meta(),
                "target_rel_stderr": self.target, "spp": self.spp, **self.provenance}
        return finish_display(Measurements(values, errors, mincam.names, meta), self.solver, self.target, self.spp,
                              self.cap)


def finish_display(result: Measurements, solver: Solver, target: float, used: int, cap: int,
                   warn_unseen: Callable[[Measurements], None] = warn_unreached) -> Measurements:
    """A display result with the reached noise in its meta and the solver's name, and the warnings of a missed
    target or an unseen measurement (``warn_unseen``: a solver that can tell why a value was not seen says it)."""
    result.meta["solver"] = solver.name
    result.meta["reached_rel_stderr"] = worst_relative_stderr(result.irradiance_w_m2, result.stderr_w_m2)
    warn_target_missed(result.meta["reached_rel_stderr"], target, used, cap)
    warn_unseen(result)
    return result


def check_update_frames(frames) -> Sequence:
    """World frames as a list of parameter-update dicts (:func:`.world_input.check_frames`)."""
    from mincam_sim.render.scene.world_input import check_frames

    check_frames(frames, {})
    return frames


__all__ = ["DisplayRayPlan", "DisplayRaySolver", "Plan", "Solver"]
