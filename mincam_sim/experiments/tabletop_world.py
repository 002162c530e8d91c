"""The tabletop of the intrusion and tracking experiments: a printed background under an area light, toys
placed per frame, in a world :class:`~mincam_sim.render.simulation.Simulation` with the ground-truth camera."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import trimesh

from mincam_sim.experiments.ground_truth import GroundTruthCamera
from mincam_sim.experiments.setup import Setup
from mincam_sim.model.optics import Mincam
from mincam_sim.render.scene.elements import tabletop_elements
from mincam_sim.render.simulation import Simulation
from mincam_sim.scene import objects
from mincam_sim.scene.tabletop import Tabletop

TABLE_SIDE_M = 1.2
#: The tabletop's contrast where the paper is silent (it describes neither its background nor its lamp): a
#: mid-grey printed paper under a 60 cm square light 1.5 m up. The experiments' ``table_albedo`` and
#: ``light_size_m`` parameters change them.
DEFAULT_TABLE_ALBEDO = 0.4
DEFAULT_LIGHT_SIZE_M = 0.6


def check_contrast(table_albedo: float, object_albedos, light_size_m: float, ground_truth: str,
                   albedos_key: str) -> None:
    """``ValueError`` naming the field for a contrast parameter out of range (albedos in [0, 1], light > 0) or
    a ground truth that is neither "object" nor "change"."""
    if not 0 <= table_albedo <= 1:
        raise ValueError(f"table_albedo must be in [0, 1], got {table_albedo!r}")
    if not all(0 <= a <= 1 for a in object_albedos):
        raise ValueError(f"{albedos_key} must each be in [0, 1], got {list(object_albedos)}")
    if not (np.isfinite(light_size_m) and light_size_m > 0):
        raise ValueError(f"light_size_m must be > 0 metres, got {light_size_m!r}")
    if ground_truth not in ("object", "change"):
        raise ValueError(f"ground_truth must be 'object' (the paper's: the object's centroid) or 'change' (the "
                         f"change's centroid, with the shadow), got {ground_truth!r}")


def check_spp_fraction(spp_fraction: float) -> None:
    """``ValueError`` naming ``spp_fraction`` unless it is a share of the set-up's tabletop budget, in (0, 1]."""
    number = isinstance(spp_fraction, int | float) and not isinstance(spp_fraction, bool)
    if not (number and np.isfinite(spp_fraction) and 0 < spp_fraction <= 1):
        raise ValueError(f"spp_fraction must be in (0, 1] (the share of Setup.spp this experiment's dP spends), "
                         f"got {spp_fraction!r}")


def make_tabletop(setup: Setup, toys: Mapping[str, trimesh.Trimesh], rng: np.random.Generator,
                  table_albedo: float = DEFAULT_TABLE_ALBEDO,
                  light_size_m: float = DEFAULT_LIGHT_SIZE_M) -> Tabletop:
    """A ``TABLE_SIDE_M`` square of printed paper of mean albedo ``table_albedo`` with ``toys`` (parked until
    placed) under the set-up's light, a square ``light_size_m`` on a side [m]."""
    background = objects.printed_background((256, 256), rng, kind="paper", mean=table_albedo)
    return Tabletop(background, TABLE_SIDE_M, dict(toys), setup.table_light_radiance_w_m2_sr,
                    light_size_m=light_size_m)


def with_height_scale(mesh: trimesh.Trimesh, height_scale: float) -> trimesh.Trimesh:
    """A copy of ``mesh`` (resting on z = 0) with its heights scaled by ``height_scale`` (1: unchanged; small:
    a flat print of the toy's footprint, which casts almost no shadow and shows no parallax)."""
    if not (np.isfinite(height_scale) and height_scale > 0):
        raise ValueError(f"height_scale must be > 0, got {height_scale!r}")
    out = mesh.copy()
    out.apply_scale((1.0, 1.0, float(height_scale)))
    out.metadata = dict(mesh.metadata)
    return out


def placed_meshes(table: Tabletop, placements: Mapping) -> list[tuple[np.ndarray, np.ndarray]]:
    """(world vertices [m], faces) of every toy that ``placements`` puts on the table (for the object ground
    truth); parked toys are left out."""
    vertices = table.toy_vertices(placements)
    return [(vertices[name], np.asarray(table.toys[name].faces)) for name, where in placements.items()
            if where is not None]


def tabletop_world(setup: Setup, table: Tabletop, mincam: Mincam, camera: GroundTruthCamera) -> Simulation:
    """The world simulation of ``mincam`` over ``table`` with the ground-truth camera (the replicates of its
    measurements are the budget's: :class:`mincam_sim.budget.Budget`)."""
    return Simulation(mincam, world=tabletop_elements(table), camera=camera.scene_dict(setup))
