"""The reference solver: the literal scene per mixel (mask surface, housing, a detector with Mitsuba's
``irradiancemeter``, the ``path`` integrator), in millimetres around each mixel. Slow and obviously right;
displays only."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from mincam_sim.render.solvers.base import DisplayRaySolver


@dataclass(frozen=True)
class Reference(DisplayRaySolver):
    """The literal scene per mixel, in millimetres around it (slow, obviously right); displays only."""

    name: ClassVar[str] = "reference"
    scenes: ClassVar[tuple[str, ...]] = ("display",)
    form: ClassVar[str] = "reference"
    estimator: ClassVar[str] = "irradiancemeter_path"

    def prepare(self, scene) -> None:
        scene.reference_scenes()

    def estimates(self, scene, spp: int, replicates: int, seed: int) -> np.ndarray:
        return scene.reference_estimates(spp, replicates, seed)

    def meta(self) -> dict:
        return {"scene_units": "millimetres around each mixel (ray offsets ~0.3 um)"}


__all__ = ["Reference"]
