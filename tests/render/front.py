"""Test helpers: world scenes through the front door (``Simulation`` and the change solvers), in the (dP, P)
shape the render tests compare."""

from __future__ import annotations

import numpy as np

import mincam_sim as ms
from mincam_sim import Pose
from mincam_sim.model.optics import cross_layout
from mincam_sim.render.scene import scene_dicts as sd


def estimates(sim: ms.Simulation, spp: int, seed: int, replicates: int = 8):
    """(replicates, n_mixels) estimates of the scene as it stands: the aperture solver's kernel."""
    return sim.mincam_scene.fast_estimates(spp, replicates, seed)


def changes(sim: ms.Simulation, frames, background, spp: int = 1 << 16, seed: int = 0, solver=None,
            replicates: int = 8, target_rel_stderr: float = 0.0, show_progress: bool = False):
    """(dP, P) of ``sim.measure_changes`` with ``solver`` (default the plain change solver) and this budget."""
    budget = ms.Budget(spp=spp, seed=seed, replicates=replicates, target_rel_stderr=target_rel_stderr)
    ch = sim.measure_changes(frames, background, solver or ms.PlainChange(), budget, show_progress=show_progress)
    return ch.dp, ch.p


def tilted_table_world() -> ms.Simulation:
    """A change-free scene for checking P itself: a tilted cross mincam 0.3 m over a textured table under an
    area light."""
    cam = cross_layout(center=Pose((0.0, 0.0, 0.3), (0.1, 0.05, -1.0), (0.0, 1.0, 0.0)))
    rng = np.random.default_rng(3)
    elements = {
        "table": sd.textured_plane(np.clip(0.4 + 0.2 * rng.standard_normal((16, 16)), 0, 1), 1.0, 1.0,
                                   Pose((0, 0, 0), (0, 0, 1)).matrix()),
        "light": sd.area_light(0.4, 0.4, Pose((0.1, 0, 1.0), (0, 0, -1)).matrix(), 10.0),
    }
    return ms.Simulation(cam, world=elements)
