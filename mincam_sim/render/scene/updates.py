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


SPECK_M = 1e-6  # a shape taken out by its to_world is shrunk to this size [m]: no area, no view, never singular


def removal_updates(params, name: str, is_shape: bool) -> dict:
    """Updates (world coordinates) that take shape or light ``name`` out of a scene whose parameters ``params``
    (``name.parameter -> value``) hold: a mesh's vertices all at its bounding-box centre; a ``to_world`` shape
    shrunk uniformly about its origin to ``SPECK_M`` (an invertible transform), its emitted radiance set to 0;
    a light's intensity (or radiance, irradiance) set to 0."""
    out: dict = {}
    vkey, tkey = f"{name}.vertex_positions", f"{name}.to_world"
    if is_shape and vkey in params:
        v0 = np.asarray(params[vkey], dtype=np.float64).reshape(-1, 3)
        centre = 0.5 * (v0.min(axis=0) + v0.max(axis=0))
        out[vkey] = np.repeat(centre[None], len(v0), axis=0).ravel()
    elif is_shape and tkey in params:
        m = np.array(params[tkey], dtype=np.float64)
        m[:3, :3] *= SPECK_M / max(float(np.linalg.svd(m[:3, :3], compute_uv=False).max()), 1e-300)
        out[tkey] = m
    for part in ("emitter.radiance", "intensity", "radiance", "irradiance"):
        key = f"{name}.{part}.value"
        if key in params:
            value = np.asarray(params[key], dtype=np.float64)
            out[key] = np.zeros_like(value)
    return out


__all__ = ["removal_updates", "transform_update", "vertex_update"]
