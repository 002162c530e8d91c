"""A tabletop world, described without any renderer: a printed background, an area light, toys that move.

World frame: the table is the plane ``z = 0`` with ``+z`` up; lengths in metres. Toys are ``trimesh`` meshes in
their object frame (resting on ``z = 0``, facing ``+x``); a placement ``(position (2,), heading)`` puts one on the
table (:func:`mincam_sim.scene.objects.mesh_at`), ``None`` parks it far outside every field of view. The render layer
turns a :class:`Tabletop` into Mitsuba elements (``mincam_sim.render.scene.elements.tabletop_elements``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from mincam_sim.scene import objects

Placement = tuple[np.ndarray, float] | None


@dataclass
class Tabletop:
    """A printed background on a table, an area light above it, toys that move (pure description).

    Attributes
    ----------
    background : (H, W) ndarray
        Albedo of the printed background in [0, 1], row 0 at +y.
    size_m : float
        Side of the square table [m], centred on the origin.
    toys : dict
        name -> ``trimesh.Trimesh`` in its object frame (albedo in ``mesh.metadata["albedo"]``).
    light_radiance_w_m2_sr : float
        Radiance of the square area light [W m^-2 sr^-1].
    light_size_m, light_height_m : float
        Side of the light and its height above the table [m].
    park_m : (float, float)
        Where toys wait, far outside every field of view [m].
    """

    background: np.ndarray
    size_m: float
    toys: dict
    light_radiance_w_m2_sr: float
    light_size_m: float = 0.6
    light_height_m: float = 1.5
    park_m: tuple[float, float] = (20.0, 20.0)

    def toy_vertices(self, placements: Mapping[str, Placement]) -> dict[str, np.ndarray]:
        """World vertex positions (n, 3) [m] of every toy: placed where given, parked otherwise."""
        out = {}
        for name, mesh in self.toys.items():
            where = placements.get(name)
            pos, heading = (self.park_m, 0.0) if where is None else where
            out[name] = objects.mesh_at(mesh, pos, heading)
        return out
