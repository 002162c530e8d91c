"""A textured road under an overcast sky, moving under a mixel (pure description, metres and seconds)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mincam_sim.model.geometry import Pose


@dataclass
class Road:
    """A flat textured road in the plane ``z = 0`` (long axis along world x) under a uniform sky.

    Attributes
    ----------
    texture : (H, W) ndarray
        Albedo in [0, 1] (row 0 at +y).
    length_m, width_m : float
        Extent along x and y [m].
    sky_radiance_w_m2_sr : float
        Radiance of the uniform sky [W m^-2 sr^-1].
    """

    texture: np.ndarray
    length_m: float
    width_m: float
    sky_radiance_w_m2_sr: float = 1.0

    def matrix_at(self, center_x_m: float) -> np.ndarray:
        """4 x 4 placement of the road rectangle (local [-1, 1]^2 scaled to its size) centred at ``x``."""
        pose = Pose((float(center_x_m), 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0))
        return pose.matrix() @ np.diag([self.length_m / 2, self.width_m / 2, 1.0, 1.0])
