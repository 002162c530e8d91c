"""The tabletop of the intrusion and tracking experiments: a printed background under an area light, toys
placed per frame, rendered by the render layer's moving-scene renderer with the ground-truth camera."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import trimesh

from .. import objects
from ..optics import Mincam
from ..render.elements import tabletop_elements
from ..render.world import WorldRenderer
from ..scene.tabletop import Tabletop
from .ground_truth import GroundTruthCamera
from .setup import Setup

TABLE_SIDE_M = 1.2


def make_tabletop(setup: Setup, toys: Mapping[str, trimesh.Trimesh], rng: np.random.Generator) -> Tabletop:
    """A ``TABLE_SIDE_M`` square of printed paper with ``toys`` (parked until placed) under the set-up's light."""
    background = objects.printed_background((256, 256), rng, kind="paper")
    return Tabletop(background, TABLE_SIDE_M, dict(toys), setup.table_light_radiance_w_m2_sr)


def tabletop_world(setup: Setup, table: Tabletop, mincam: Mincam, camera: GroundTruthCamera,
                   replicates: int = 8) -> WorldRenderer:
    """The renderer of ``mincam`` over ``table`` with the ground-truth camera."""
    return WorldRenderer(mincam, tabletop_elements(table), replicates=replicates, camera=camera.scene_dict(setup))
