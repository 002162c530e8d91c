"""Pure scene descriptions (:mod:`mincam_sim.scene`) turned into Mitsuba elements and parameter updates."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from mincam_sim.model.geometry import Pose
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.updates import transform_update, vertex_update
from mincam_sim.scene.road import Road
from mincam_sim.scene.tabletop import Placement, Tabletop


def tabletop_elements(table: Tabletop) -> dict:
    """Table (textured plane), area light and toys (parked) of a :class:`~mincam_sim.scene.Tabletop`."""
    elements = {
        "table": sd.textured_plane(table.background, table.size_m, table.size_m,
                                   Pose((0.0, 0.0, 0.0), (0.0, 0.0, 1.0)).matrix()),
        "light": sd.area_light(table.light_size_m, table.light_size_m,
                               Pose((0.0, 0.0, table.light_height_m), (0.0, 0.0, -1.0)).matrix(),
                               table.light_radiance_w_m2_sr),
    }
    for name, vertices in table.toy_vertices({}).items():
        mesh = table.toys[name]
        elements[name] = sd.mesh_object(name, vertices, mesh.faces, float(mesh.metadata.get("albedo", 0.8)))
    return elements


def toy_updates(table: Tabletop, placements: Mapping[str, Placement]) -> dict[str, np.ndarray]:
    """Parameter updates moving every toy to its placement (or its parking spot)."""
    updates: dict[str, np.ndarray] = {}
    for name, vertices in table.toy_vertices(placements).items():
        updates.update(vertex_update(name, vertices))
    return updates


def road_elements(road: Road, center_x_m: float = 0.0) -> dict:
    """The road (textured plane, key ``"road"``) and its sky."""
    plane = sd.textured_plane(road.texture, 2.0, 2.0, road.matrix_at(center_x_m))  # matrix carries the size
    return {"road": plane, "sky": sd.sky(road.sky_radiance_w_m2_sr)}


def road_update(road: Road, center_x_m: float) -> dict[str, np.ndarray]:
    """Parameter update moving the road so that its centre is at ``center_x_m`` [m]."""
    return transform_update("road", road.matrix_at(center_x_m))


__all__ = ["road_elements", "road_update", "tabletop_elements", "toy_updates", "transform_update", "vertex_update"]
