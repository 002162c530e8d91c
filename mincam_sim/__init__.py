"""mincam_sim: physically-based optical simulator for minimalist cameras (mixels), rendered with Mitsuba 3.

Units are SI throughout: metres, radians, W/m^2 (irradiance), W m^-2 sr^-1 (radiance), seconds.
Only ``mincam_sim.render`` imports mitsuba / drjit; everything else is pure numpy.

The front door: ``Simulation(mincam, screen=... | world=...)`` with a solver (``ResponseMap``, ``Aperture``,
``Reference``, ``StratifiedChange``, ``PlainChange``, ``PlaneReplay``; ``DotProduct``, the idealised model) and a
``Budget``; ``Run(out_dir)`` keeps results.
These names load the renderer on first use (``import mincam_sim`` itself stays pure numpy).
"""

from mincam_sim.budget import Budget
from mincam_sim.changes import Changes, RunInfo
from mincam_sim.errors import ConfigError, InputError, MincamError
from mincam_sim.llvm_path import configure_libllvm
from mincam_sim.masks import Mask
from mincam_sim.measurements import Measurements
from mincam_sim.model.geometry import Pose, look_at
from mincam_sim.model.optics import Mincam, Mixel, cross_layout, layout, pair_layout, single
from mincam_sim.scene.display import Screen, grid_sweep, line_sweep, white_square

configure_libllvm()  # before the user imports drjit: it picks its libLLVM then (the system's may be too old)

_LAZY = {
    "Simulation": "mincam_sim.render.simulation",
    "Reference": "mincam_sim.render.solvers",
    "Aperture": "mincam_sim.render.solvers",
    "ResponseMap": "mincam_sim.render.solvers",
    "PlainChange": "mincam_sim.render.solvers",
    "StratifiedChange": "mincam_sim.render.solvers",
    "PlaneReplay": "mincam_sim.render.solvers",
    "DotProduct": "mincam_sim.render.solvers",
    "Run": "mincam_sim.runs.run",
    # building a world: updates by name (world coordinates), scene pieces, the experiments' tabletop and toys
    "vertex_update": "mincam_sim.render.scene.updates",
    "transform_update": "mincam_sim.render.scene.updates",
    "mesh_object": "mincam_sim.render.scene.scene_dicts",
    "area_light": "mincam_sim.render.scene.scene_dicts",
    "textured_plane": "mincam_sim.render.scene.scene_dicts",
    "sky": "mincam_sim.render.scene.scene_dicts",
    "pinhole_camera": "mincam_sim.render.scene.scene_dicts",
    "tabletop_elements": "mincam_sim.render.scene.elements",
    "toy_updates": "mincam_sim.render.scene.elements",
    "Tabletop": "mincam_sim.scene.tabletop",
    "load_mesh": "mincam_sim.scene.objects",
    "mesh_at": "mincam_sim.scene.objects",
    "Trajectory": "mincam_sim.scene.objects",
}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'mincam_sim' has no attribute {name!r}")

__all__ = [
    "Aperture",
    "DotProduct",
    "Tabletop",
    "Trajectory",
    "area_light",
    "load_mesh",
    "mesh_at",
    "mesh_object",
    "pinhole_camera",
    "sky",
    "tabletop_elements",
    "textured_plane",
    "toy_updates",
    "transform_update",
    "vertex_update",
    "Budget",
    "Changes",
    "ConfigError",
    "InputError",
    "Mask",
    "Measurements",
    "MincamError",
    "PlainChange",
    "Reference",
    "ResponseMap",
    "Run",
    "RunInfo",
    "Simulation",
    "StratifiedChange",
    "PlaneReplay",
    "Mincam",
    "Mixel",
    "Pose",
    "Screen",
    "cross_layout",
    "grid_sweep",
    "layout",
    "line_sweep",
    "look_at",
    "pair_layout",
    "single",
    "white_square",
]
__version__ = "0.7.0.dev0"
