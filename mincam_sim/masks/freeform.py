"""Freeform masks: any 2D array of transmissions (a learned 128 x 128 mask, a picture) with its physical size.

A freeform mask is a raster :class:`~.mask.Mask` (no analytic profile): the array *is* the mask, read between its
texels with the mask's ``interpolation`` exactly as the renderer reads it (a Mitsuba ``bitmap``, raw and clamped).

* :func:`from_array`: a mask from an array in Python (``Mask(array, width_m, ...)`` with the checks named for an
  array that is not yet a transmission: 8-bit values, a channel axis).
* :func:`load_npy`: a mask from a NumPy ``.npy`` file; :func:`mincam_sim.masks.load` reads ``.npy`` files too, so a
  TOML ``mask = "file:m.npy"`` with ``mask_size_m`` works like a PNG or an OpenEXR.
* :func:`transmission_at`: the mask's transmission at physical mask points, in numpy, with the renderer's
  reconstruction of raster masks (bilinear between texel centres with clamped edges, or nearest texel), or the
  exact profile of an analytic mask; 0 outside the aperture. Used by the idealised dot-product model and by
  checks that need the mask away from the renderer.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mincam_sim.errors import InputError
from mincam_sim.masks.mask import Mask
from mincam_sim.masks.profiles import NUMPY_OPS

NPY_MAGIC = b"\x93NUMPY"


def from_array(array, width_m: float, height_m: float | None = None, name: str = "freeform",
               interpolation: str = "bilinear", **meta) -> Mask:
    """A freeform mask from a 2D array of transmissions in [0, 1] (row 0 at the top, as seen from the detector
    looking out), ``width_m`` x ``height_m`` [m] (default: square texels, ``width_m * rows / cols``).

    Raises
    ------
    InputError
        An array that is not 2D (or 2D with one channel), an integer array (8-bit images: divide by 255 first),
        values outside [0, 1], NaN, or a size that is not a positive number of metres.
    """
    arr = np.asarray(array)
    if arr.dtype.kind in "iub":
        raise InputError(f"mask {name!r}: the array holds integers ({arr.dtype}); transmission is a float in "
                         "[0, 1]: divide 8-bit values by 255 (or 16-bit by 65535) first")
    if arr.dtype.kind not in "f":
        raise InputError(f"mask {name!r}: the array must hold float transmissions in [0, 1], got dtype {arr.dtype}")
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if arr.ndim != 2:
        raise InputError(f"mask {name!r}: a freeform mask is a 2D array (rows, cols), got shape {arr.shape}")
    if isinstance(width_m, bool) or not isinstance(width_m, (int, float, np.floating)):
        raise InputError(f"mask {name!r}: width_m must be the mask's width in metres (e.g. 0.002), got {width_m!r}")
    height = float(width_m) * arr.shape[0] / arr.shape[1] if height_m is None else height_m
    return Mask(arr, float(width_m), height, name, {"kind": "freeform", **meta}, None, interpolation)


def load_npy(path: str | Path, width_m: float, height_m: float | None = None, name: str | None = None,
             interpolation: str = "bilinear") -> Mask:
    """A freeform mask from a ``.npy`` file holding a 2D float array of transmissions in [0, 1].

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    InputError
        A file that is not a plain NumPy array (pickled objects are refused), or an array :func:`from_array`
        refuses.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"mask file {str(p)!r} does not exist")
    try:
        arr = np.load(p, allow_pickle=False)
    except ValueError as err:
        raise InputError(f"mask file {str(p)!r} is not a plain NumPy array file: {err}") from None
    if not isinstance(arr, np.ndarray):
        raise InputError(f"mask file {str(p)!r} holds several arrays (.npz); save one 2D array with np.save")
    mask = from_array(arr, width_m, height_m, name if name is not None else p.stem, interpolation,
                      source=str(p), format="npy")
    return mask


def is_npy(path: str | Path) -> bool:
    """True when the file starts with the NumPy ``.npy`` magic bytes."""
    try:
        with Path(path).open("rb") as fh:
            return fh.read(len(NPY_MAGIC)) == NPY_MAGIC
    except OSError:
        return False


def transmission_at(mask: Mask, x_m, y_m) -> np.ndarray:
    """Transmission at physical mask points ``(x_m, y_m)`` [m] (centred, +x right, +y up as seen from the detector),
    float64, 0 outside the aperture.

    A mask with a profile is evaluated exactly; a raster mask as the renderer's Mitsuba ``bitmap`` reads it:
    texture coordinates ``u = 0.5 + x_m / width``, ``v = 0.5 - y_m / height``; ``bilinear`` between texel centres
    (pixel coordinate ``u W - 0.5``, indices clamped to the array), ``nearest`` the texel that contains the point.
    """
    x_m, y_m = np.broadcast_arrays(np.asarray(x_m, dtype=np.float64), np.asarray(y_m, dtype=np.float64))
    inside = (np.abs(x_m) <= mask.width_m / 2) & (np.abs(y_m) <= mask.height_m / 2)
    if mask.profile is not None:
        t = np.asarray(mask.profile.evaluate(x_m, y_m, NUMPY_OPS), dtype=np.float64) * np.ones_like(x_m)
    else:
        t = _raster(mask, 0.5 + x_m / mask.width_m, 0.5 - y_m / mask.height_m)
    return np.where(inside, t, 0.0)


def _raster(mask: Mask, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The mask array at texture coordinates (u across columns, v down rows), with its interpolation, clamped."""
    rows, cols = mask.shape
    data = mask.transmission
    if mask.interpolation == "nearest":
        j = np.clip(np.floor(u * cols).astype(np.int64), 0, cols - 1)
        i = np.clip(np.floor(v * rows).astype(np.int64), 0, rows - 1)
        return data[i, j]
    px, py = u * cols - 0.5, v * rows - 0.5
    j0, i0 = np.floor(px), np.floor(py)
    fx, fy = px - j0, py - i0
    j0, i0 = j0.astype(np.int64), i0.astype(np.int64)
    j1, i1 = np.clip(j0 + 1, 0, cols - 1), np.clip(i0 + 1, 0, rows - 1)
    j0, i0 = np.clip(j0, 0, cols - 1), np.clip(i0, 0, rows - 1)
    top = data[i0, j0] * (1 - fx) + data[i0, j1] * fx
    bottom = data[i1, j0] * (1 - fx) + data[i1, j1] * fx
    return top * (1 - fy) + bottom * fy


__all__ = ["from_array", "is_npy", "load_npy", "transmission_at"]
