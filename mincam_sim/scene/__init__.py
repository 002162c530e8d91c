"""Pure scene descriptions (no renderer): displays and sweeps, tabletops, roads.

The render layer (:mod:`mincam_sim.render`) turns them into Mitsuba elements; nothing here imports Mitsuba.
Files:

* ``display.py``: flat emissive displays and the frames shown on them (pure numpy).
* ``objects.py``: scene content for the paper's experiments: toy meshes, printed/road textures and object
  trajectories.
* ``road.py``: a textured road under an overcast sky, moving under a mixel (pure description, metres and seconds).
* ``tabletop.py``: a tabletop world, described without any renderer: a printed background, an area light, toys that
  move.
"""

from mincam_sim.scene.display import Screen, Sweep, grid_sweep, line_sweep

# Tabletop and Road load trimesh (about 2 s) on first use, not with the package: a command starts faster, and
# Ctrl-C in its first seconds is not caught by trimesh's import guard.
_LAZY = {"Road": "mincam_sim.scene.road", "Tabletop": "mincam_sim.scene.tabletop"}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'mincam_sim.scene' has no attribute {name!r}")


__all__ = ["Road", "Screen", "Sweep", "Tabletop", "grid_sweep", "line_sweep"]
