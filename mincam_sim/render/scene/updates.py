"""Parameter updates of a world scene by name (world coordinates), as ``Simulation.update`` and the frames take
them."""

from __future__ import annotations

import numpy as np


def vertex_update(name: str, vertices_m: np.ndarray) -> dict[str, np.ndarray]:
    """Parameter update moving mesh ``name`` to new vertex positions (n, 3) [m]."""
    return {f"{name}.vertex_positions": np.asarray(vertices_m, dtype=np.float32).ravel()}


def transform_update(name: str, matrix: np.ndarray) -> dict[str, np.ndarray]:
    """Parameter update setting shape ``name``'s to_world matrix (4 x 4)."""
    return {f"{name}.to_world": np.asarray(matrix, dtype=np.float64)}


__all__ = ["transform_update", "vertex_update"]
