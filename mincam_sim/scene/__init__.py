"""Pure scene descriptions (no renderer): displays and sweeps, tabletops, roads.

The render layer (:mod:`mincam_sim.render`) turns them into Mitsuba elements; nothing here imports Mitsuba.
"""

from .display import Screen, Sweep, grid_sweep, line_sweep
from .road import Road
from .tabletop import Tabletop

__all__ = ["Road", "Screen", "Sweep", "Tabletop", "grid_sweep", "line_sweep"]
