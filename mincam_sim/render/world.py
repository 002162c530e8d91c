# TEMPORARY: deleted after the callers are ported
"""The old world entry point, a thin wrapper over :class:`~.simulation.Simulation` (which holds the world's
state) and the change solvers (``mincam_sim.render.solvers.change``), kept only while callers outside
``render/`` are ported. New code uses ``Simulation(mincam, world=elements).measure_changes(frames, background,
solver, budget)``."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..budget import Budget
from ..errors import InputError
from ..frames import FrameSink
from ..measurements import Measurements
from ..optics import Mincam
from . import backend
from .mincam_scene import CAMERA_KEY, SENSOR_KEY
from .simulation import Simulation, WorldParameters
from .solvers import PlainChange, StratifiedChange
from .solvers.change import (
    BACKGROUND_MIN_SPP,
    INFO_COLUMNS,
    MAX_SPP,
    RETRY_FACTOR,
    STRATA_EXPANSIONS,
    STRATA_SHARES,
    FallbackWarning,
    HeavyTailWarning,
)
from .updates import transform_update, vertex_update

ESTIMATORS = ("plain", "stratified")
__all__ = ["BACKGROUND_MIN_SPP", "CAMERA_KEY", "INFO_COLUMNS", "MAX_SPP", "RETRY_FACTOR", "SENSOR_KEY",
           "STRATA_EXPANSIONS", "STRATA_SHARES", "FallbackWarning", "HeavyTailWarning", "WorldParameters",
           "WorldRenderer", "transform_update", "vertex_update"]


class WorldRenderer:
    """TEMPORARY: a :class:`~.simulation.Simulation` of a world with its replicates; attributes are the
    simulation's (``params``, ``update``, ``scene``, ``sensor``, ``mincam_scene`` as ``world`` ...)."""

    def __init__(self, mincam: Mincam, elements: dict, replicates: int = 8, max_depth: int = 3,
                 camera: dict | None = None) -> None:
        if isinstance(replicates, bool) or not isinstance(replicates, (int, np.integer)) or replicates < 2:
            raise InputError(f"replicates must be an integer >= 2, got {replicates!r}")
        self.sim = Simulation(mincam, world=elements, max_depth=max_depth, camera=camera)
        self.replicates = int(replicates)

    def __getattr__(self, name: str):
        if name == "sim":
            raise AttributeError(name)
        return getattr(self.sim, name)

    def __setattr__(self, name: str, value) -> None:
        if name in ("sim", "replicates"):
            object.__setattr__(self, name, value)
        else:
            setattr(self.sim, name, value)

    @property
    def world(self):
        return self.sim.mincam_scene

    def estimates(self, spp: int, seed: int) -> np.ndarray:
        """(replicates, n_mixels) independent irradiance estimates [W/m^2], ``spp / replicates`` rays each."""
        return self.sim.mincam_scene.fast_estimates(spp, self.replicates, seed)

    def _change(self, moving):
        return self.sim.change_reach(moving)

    def measure_changes(self, frames: Sequence, background, spp: int = 1 << 16, seed: int = 0,
                        correlated: bool = True, out_dir: str | Path | None = None, show_progress: bool = False,
                        target_rel_stderr: float = 0.0, overwrite: bool = False, estimator: str = "plain",
                        strata_shares: Sequence[float] = STRATA_SHARES,
                        strata_expansions: Sequence[float] = STRATA_EXPANSIONS, guide_bounces: bool = True,
                        sink: FrameSink | None = None) -> tuple[Measurements, Measurements]:
        """TEMPORARY: ``Simulation.measure_changes(frames, background, PlainChange() | StratifiedChange(...),
        Budget(...))``; returns (dP, P)."""
        if estimator not in ESTIMATORS:
            raise InputError(f"estimator must be one of {ESTIMATORS}, got {estimator!r}")
        if not (isinstance(target_rel_stderr, (int, float)) and np.isfinite(target_rel_stderr)
                and target_rel_stderr >= 0):
            raise InputError(f"target_rel_stderr must be >= 0 (0 = use spp as given), got {target_rel_stderr!r}")
        solver = (PlainChange(correlated=correlated) if estimator == "plain" else
                  StratifiedChange(correlated=correlated, strata_shares=strata_shares,
                                   strata_expansions=strata_expansions, guide_bounces=guide_bounces))
        if isinstance(spp, bool) or not isinstance(spp, (int, np.integer)) or spp < 1:
            raise InputError(f"spp must be an integer >= 1 (rays per mixel per frame), got {spp!r}")
        if spp < self.replicates:
            raise InputError(f"spp = {spp} rays per mixel per frame is fewer than the {self.replicates} replicates "
                             "(each replicate needs rays of its own); raise spp or lower replicates")
        budget = Budget(spp=int(spp), target_rel_stderr=float(target_rel_stderr), replicates=self.replicates,
                        seed=int(seed))
        if out_dir is not None:
            raise InputError("out_dir= is gone: keep results with `with mincam_sim.Run(out_dir) as run: "
                             "run.measure(...)` (or run.measure_changes)")
        if sink is not None and getattr(sink, "persistent", False) and getattr(sink, "identity", 0) is None:
            sink.identity = _identity(self.sim, frames, solver, budget, background)
        ch = self.sim.measure_changes(frames, background, solver, budget, sink=sink, show_progress=show_progress)
        return ch.dp, ch.p


def _identity(sim, frames, solver, budget, background) -> dict:
    """TEMPORARY: the identity ``mincam_sim.run.Run`` builds, for an old caller's unidentified store sink."""
    from ..identity import run_identity

    return run_identity(sim.identity(), solver.identity(), budget.describe(), sim.frames_identity(frames, background),
                        backend.variant())
