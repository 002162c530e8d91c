"""Analytic mask profiles: the exact transmission of generated masks, evaluated by numpy or by the renderer.

A profile maps physical mask coordinates ``(x_m, y_m)`` [m] (centred on the mask, +x to the right and +y up, as
seen from the detector looking out) to a transmission in [0, 1]. The same expression runs on numpy arrays (to
sample the mask's texel array) and inside the renderer's Dr.Jit kernels (to evaluate the mask *exactly* at every
ray, with no texture discretisation): every profile is written against a tiny array namespace ``ops``
(``NumpyOps`` here; the render layer provides the Dr.Jit one), so this module stays pure numpy.

The namespace needs: ``cos``, ``sqrt``, ``atan2``, ``abs``, ``floor``, ``minimum``, ``maximum`` and
``where(cond, a, b)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np


class ArrayOps(Protocol):
    """The operations a profile may use (numpy's names; the render layer maps them onto Dr.Jit)."""

    def cos(self, a: Any) -> Any: ...
    def sqrt(self, a: Any) -> Any: ...
    def atan2(self, y: Any, x: Any) -> Any: ...
    def abs(self, a: Any) -> Any: ...
    def floor(self, a: Any) -> Any: ...
    def minimum(self, a: Any, b: Any) -> Any: ...
    def maximum(self, a: Any, b: Any) -> Any: ...
    def where(self, cond: Any, a: Any, b: Any) -> Any: ...


class NumpyOps:
    """:class:`ArrayOps` on numpy arrays."""

    cos = staticmethod(np.cos)
    sqrt = staticmethod(np.sqrt)
    atan2 = staticmethod(np.arctan2)
    abs = staticmethod(np.abs)
    floor = staticmethod(np.floor)
    minimum = staticmethod(np.minimum)
    maximum = staticmethod(np.maximum)
    where = staticmethod(np.where)


NUMPY_OPS = NumpyOps()


def _clip01(value, ops: ArrayOps):
    return ops.minimum(ops.maximum(value, 0.0), 1.0)


class MaskProfile:
    """Base class: ``evaluate(x_m, y_m, ops)`` -> transmission in [0, 1]."""

    def evaluate(self, x_m, y_m, ops: ArrayOps = NUMPY_OPS):  # pragma: no cover - abstract
        raise NotImplementedError

    def describe(self) -> dict:
        """JSON-friendly parameters (part of a run's identity)."""
        out: dict = {"profile": type(self).__name__}
        for key, value in vars(self).items():
            out[key] = value.describe() if isinstance(value, MaskProfile) else value
        return out


@dataclass(frozen=True)
class Constant(MaskProfile):
    """Uniform transmission ``value``."""

    value: float

    def evaluate(self, x_m, y_m, ops: ArrayOps = NUMPY_OPS):
        return x_m * 0.0 + self.value


@dataclass(frozen=True)
class Ramp(MaskProfile):
    """Linear ramp across the mask: ``kind`` in x, 1-x, y, 1-y (normalised coordinates, y up)."""

    kind: str
    width_m: float
    height_m: float

    def evaluate(self, x_m, y_m, ops: ArrayOps = NUMPY_OPS):
        x = x_m / self.width_m + 0.5
        y = y_m / self.height_m + 0.5
        value = {"x": x, "1-x": 1.0 - x, "y": y, "1-y": 1.0 - y}[self.kind]
        return _clip01(value, ops)


@dataclass(frozen=True)
class Sinusoid(MaskProfile):
    """``a0 + a1 cos(omega (x cos t + y sin t) + phase)``, clipped to [0, 1] (the paper's Eq. 9)."""

    omega_rad_per_m: float
    a0: float
    a1: float
    phase_rad: float
    direction_deg: float

    def evaluate(self, x_m, y_m, ops: ArrayOps = NUMPY_OPS):
        t = math.radians(self.direction_deg)
        arg = self.omega_rad_per_m * (x_m * math.cos(t) + y_m * math.sin(t)) + self.phase_rad
        return _clip01(self.a0 + self.a1 * ops.cos(arg), ops)


@dataclass(frozen=True)
class CircularArc(MaskProfile):
    """Ramp along a circular arc: the arc-length fraction of the closest arc point (see ``circular_ramp``)."""

    center_x_m: float
    center_y_m: float
    radius_m: float
    start_angle_deg: float
    sweep_deg: float
    v0: float
    v1: float

    def evaluate(self, x_m, y_m, ops: ArrayOps = NUMPY_OPS):
        dx, dy = x_m - self.center_x_m, y_m - self.center_y_m
        sweep = math.radians(abs(self.sweep_deg))
        start = math.radians(self.start_angle_deg)
        sign = 1.0 if self.sweep_deg >= 0 else -1.0
        a = (ops.atan2(dy, dx) - start) * sign
        rel = a - ops.floor(a / (2 * math.pi)) * (2 * math.pi)  # angle along the sweep, in [0, 2 pi)
        frac = rel / sweep
        end = start + math.radians(self.sweep_deg)
        r = self.radius_m
        d_start = (dx - r * math.cos(start)) ** 2 + (dy - r * math.sin(start)) ** 2
        d_end = (dx - r * math.cos(end)) ** 2 + (dy - r * math.sin(end)) ** 2
        frac = ops.where(rel > sweep, ops.where(d_start <= d_end, 0.0 * frac, 0.0 * frac + 1.0), frac)
        frac = ops.where((dx == 0) & (dy == 0), 0.0 * frac, _clip01(frac, ops))
        return _clip01(self.v0 + (self.v1 - self.v0) * frac, ops)


@dataclass(frozen=True)
class Affine(MaskProfile):
    """``offset + scale * inner`` (complements and scaled masks)."""

    inner: MaskProfile
    scale: float
    offset: float

    def evaluate(self, x_m, y_m, ops: ArrayOps = NUMPY_OPS):
        return _clip01(self.offset + self.scale * self.inner.evaluate(x_m, y_m, ops), ops)


@dataclass(frozen=True)
class Band(MaskProfile):
    """``inner`` inside the vertical band ``x0_m <= x <= x1_m``, opaque elsewhere."""

    inner: MaskProfile
    x0_m: float
    x1_m: float

    def evaluate(self, x_m, y_m, ops: ArrayOps = NUMPY_OPS):
        inside = (x_m >= self.x0_m) & (x_m <= self.x1_m)
        value = self.inner.evaluate(x_m, y_m, ops)
        return ops.where(inside, value, 0.0 * value)


def sample(profile: MaskProfile, shape: tuple[int, int], width_m: float, height_m: float) -> np.ndarray:
    """The profile at the texel centres of an (H, W) array (row 0 at the top), as float64."""
    h, w = shape
    x = ((np.arange(w) + 0.5) / w - 0.5) * width_m
    y = (0.5 - (np.arange(h) + 0.5) / h) * height_m
    gx, gy = np.meshgrid(x, y)
    return np.broadcast_to(np.asarray(profile.evaluate(gx, gy, NUMPY_OPS), dtype=np.float64), (h, w)).copy()
