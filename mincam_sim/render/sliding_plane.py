# TEMPORARY: deleted after the callers are ported
"""The old sliding-plane entry point: :class:`~.solvers.plane_replay.SlidingPlane` over a ``WorldRenderer``'s
simulation. New code uses ``Simulation(...).measure(frames, solver=PlaneReplay(plane), budget=...)``."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .solvers.plane_replay import PLANE_TOLERANCE
from .solvers.plane_replay import SlidingPlane as _SlidingPlane

__all__ = ["PLANE_TOLERANCE", "SlidingPlane"]


class SlidingPlane(_SlidingPlane):
    """TEMPORARY: :class:`~.solvers.plane_replay.SlidingPlane` of ``world.sim`` (a ``WorldRenderer``) or of a
    Simulation, with the renderer's replicates by default."""

    def __init__(self, world, name: str, placements_m: Sequence[np.ndarray], spp: int, seed: int,
                 replicates: int | None = None) -> None:
        if replicates is None:
            replicates = getattr(world, "replicates", 8)
        super().__init__(getattr(world, "sim", world), name, placements_m, spp, seed, replicates)
