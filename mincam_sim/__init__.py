"""mincam_sim: physically-based optical simulator for minimalist cameras (mixels), rendered with Mitsuba 3.

Units are SI throughout: metres, radians, W/m^2 (irradiance), W m^-2 sr^-1 (radiance), seconds.
Only ``mincam_sim.render`` imports mitsuba / drjit; everything else is pure numpy.
"""

from .geometry import Pose, look_at
from .masks import Mask
from .optics import Mincam, Mixel, cross_layout, layout, pair_layout, single
from .scene.display import Screen, grid_sweep, line_sweep, white_square

__all__ = [
    "Mask",
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
__version__ = "0.1.0"
