"""Bitmap textures from numpy arrays (raw, linear, clamped): masks, frames, printed backgrounds."""

from __future__ import annotations

import numpy as np

from mincam_sim.render import backend


def texture_tensor(array: np.ndarray):
    """A (H, W) array as a one-channel ``mi.TensorXf`` (float32) for ``bitmap`` textures."""
    mi = backend.mitsuba()
    return mi.TensorXf(np.ascontiguousarray(np.asarray(array, dtype=np.float32)[..., None]))


def bitmap_dict(array: np.ndarray, filter_type: str = "bilinear") -> dict:
    """A raw (linear, no sRGB conversion), clamped bitmap texture of ``array`` (H, W)."""
    return {
        "type": "bitmap",
        "data": texture_tensor(array),
        "raw": True,
        "filter_type": filter_type,
        "wrap_mode": "clamp",
    }
