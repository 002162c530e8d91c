"""Test helpers: world scenes through the front door (``Simulation`` and the change solvers), in the (dP, P)
shape the render tests compare."""

from __future__ import annotations

import mincam_sim as ms


def estimates(sim: ms.Simulation, spp: int, seed: int, replicates: int = 8):
    """(replicates, n_mixels) estimates of the scene as it stands: the aperture solver's kernel."""
    return sim.mincam_scene.fast_estimates(spp, replicates, seed)


def changes(sim: ms.Simulation, frames, background, spp: int = 1 << 16, seed: int = 0, solver=None,
            replicates: int = 8, target_rel_stderr: float = 0.0, show_progress: bool = False):
    """(dP, P) of ``sim.measure_changes`` with ``solver`` (default the plain change solver) and this budget."""
    budget = ms.Budget(spp=spp, seed=seed, replicates=replicates, target_rel_stderr=target_rel_stderr)
    ch = sim.measure_changes(frames, background, solver or ms.PlainChange(), budget, show_progress=show_progress)
    return ch.dp, ch.p
