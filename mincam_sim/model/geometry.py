"""Poses and frames (pure numpy), with the same conventions as Mitsuba's ``look_at``.

World units are metres. A pose places a local frame whose +z axis is the viewing (or facing) direction and
whose +y axis is "up"; local +x is ``cross(up, forward)``, i.e. the viewer's *left*, exactly as Mitsuba's
``Transform4f.look_at``. The default scene puts the mincam at the origin looking along world -z with world +y
up, so world +x is the viewer's right.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from mincam_sim.errors import InputError

Vec3 = tuple[float, float, float]


def _as_vec3(value, name: str) -> np.ndarray:
    """``value`` as a float64 (3,) array; anything else (strings, NaN, two components) is one InputError."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        arr = np.empty(0)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise InputError(f"{name} must be three finite numbers [m], got {value!r}")
    return arr


@dataclass(frozen=True)
class Pose:
    """Position and orientation of a local frame.

    Parameters
    ----------
    position_m : (3,) float
        Origin of the local frame in world coordinates [m].
    forward : (3,) float
        Direction of local +z (viewing or facing direction); any non-zero length.
    up : (3,) float
        Approximate direction of local +y; must not be parallel to ``forward``.
    """

    position_m: Vec3 = (0.0, 0.0, 0.0)
    forward: Vec3 = (0.0, 0.0, -1.0)
    up: Vec3 = (0.0, 1.0, 0.0)

    def __post_init__(self) -> None:
        pos = _as_vec3(self.position_m, "position_m")
        fwd = _as_vec3(self.forward, "forward")
        up = _as_vec3(self.up, "up")
        if np.linalg.norm(fwd) == 0:
            raise InputError("forward must be a non-zero direction")
        if np.linalg.norm(np.cross(fwd, up)) < 1e-9 * np.linalg.norm(fwd) * max(np.linalg.norm(up), 1e-300):
            raise InputError(f"up {[float(v) for v in up]} must not be parallel to forward {[float(v) for v in fwd]}")
        object.__setattr__(self, "position_m", tuple(float(v) for v in pos))
        object.__setattr__(self, "forward", tuple(float(v) for v in fwd))
        object.__setattr__(self, "up", tuple(float(v) for v in up))

    def axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit vectors (left, up, forward) of the local x, y, z axes in world coordinates."""
        fwd = np.asarray(self.forward) / np.linalg.norm(self.forward)
        left = np.cross(self.up, fwd)
        left /= np.linalg.norm(left)
        up = np.cross(fwd, left)
        return left, up, fwd

    def matrix(self) -> np.ndarray:
        """4x4 local-to-world matrix (columns: left, up, forward, position)."""
        return self._matrix.copy()

    @functools.cached_property
    def _matrix(self) -> np.ndarray:  # a frozen pose: computed once (per-frame region bounds map points with it)
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2] = self.axes()
        m[:3, 3] = self.position_m
        m.setflags(write=False)
        return m

    def to_world(self, points_local: np.ndarray) -> np.ndarray:
        """Map local points (..., 3) [m] to world coordinates [m]."""
        m = self._matrix
        return np.asarray(points_local) @ m[:3, :3].T + m[:3, 3]

    def to_local(self, points_world: np.ndarray) -> np.ndarray:
        """Map world points (..., 3) [m] to local coordinates [m]."""
        m = self._matrix
        return (np.asarray(points_world) - m[:3, 3]) @ m[:3, :3]

    def translated(self, offset_m: Vec3) -> Pose:
        """The same orientation, moved by ``offset_m`` in world coordinates [m]."""
        return Pose(tuple(np.add(self.position_m, offset_m)), self.forward, self.up)


def look_at(position_m: Vec3, target_m: Vec3, up: Vec3 = (0.0, 1.0, 0.0)) -> Pose:
    """Pose at ``position_m`` looking at ``target_m`` [m]."""
    fwd = np.subtract(target_m, position_m)
    if np.linalg.norm(fwd) == 0:
        raise InputError("look_at: target coincides with position")
    return Pose(tuple(position_m), tuple(fwd), tuple(up))


def clip_polygon_halfspace(polygon: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
    """Part of the convex polygon ``polygon`` (k, d) where ``normal . p + offset >= 0`` (Sutherland-Hodgman).

    Any dimension ``d`` (a half-plane in 2D, a half-space in 3D); an empty (0, d) array when nothing is left.
    """
    polygon = np.asarray(polygon, dtype=np.float64)
    if len(polygon) == 0:
        return polygon
    side = polygon @ np.asarray(normal, dtype=np.float64) + offset
    out = []
    for j in range(len(polygon)):
        k = (j + 1) % len(polygon)
        if side[j] >= 0:
            out.append(polygon[j])
        if (side[j] >= 0) != (side[k] >= 0):
            t = side[j] / (side[j] - side[k])
            out.append(polygon[j] + t * (polygon[k] - polygon[j]))
    return np.array(out) if out else np.zeros((0, polygon.shape[1]))
