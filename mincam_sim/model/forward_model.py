"""The paper's ideal forward model (pure numpy): what a mixel measures when the mask is thin, the detector a
point, and every mixel shares the pinhole view of the mincam's centre. The renderer does not use it (rays
give the real measurement); the estimators are derived from it and tested against it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike


def ideal_measurement(mask: ArrayLike, images: ArrayLike, pixel_area: float = 1.0) -> np.ndarray:
    """Paper Eq. 1: ``P(t) = sum_xy M(x, y) I_t(x, y) dA``, the scene image weighted by the mask.

    Parameters
    ----------
    mask : (H, W) array_like
        Transmission M in [0, 1] sampled on the image's pixel grid (the mask as it overlays the scene).
    images : (H, W) or (frames, H, W) array_like
        Scene radiance I_t as a pinhole camera at the mixel would see it (any unit).
    pixel_area : float
        Area ``dA`` of one pixel in the integral's measure (1 = a plain sum).

    Returns
    -------
    numpy.ndarray
        One value per frame (a 0-d array for a single image), in the unit of ``images`` times ``pixel_area``.
    """
    m = np.asarray(mask, dtype=np.float64)
    i = np.asarray(images, dtype=np.float64)
    if m.ndim != 2 or i.shape[-2:] != m.shape:
        raise ValueError(f"mask (H, W) and images (..., H, W) must share H, W; got {m.shape} and {i.shape}")
    return np.tensordot(i, m, axes=([-2, -1], [0, 1])) * pixel_area


def speed_signal(time_s: ArrayLike, speed_m_s: float, omega_d_rad_per_m: float, a0: float, a1: float,
                 phase_rad: float = 0.0) -> np.ndarray:
    """Paper Eq. 13: ``P(t) = A0' + A1' cos(omega_d v t + phi')``, the signal of a sinusoid mixel over a scene
    moving at ``speed_m_s`` whose content at the mask's scene frequency ``omega_d`` (Eq. 10) has amplitude
    ``a1``; its temporal frequency is ``omega_p = omega_d v`` (Eq. 14 inverts it)."""
    t = np.asarray(time_s, dtype=np.float64)
    return a0 + a1 * np.cos(omega_d_rad_per_m * speed_m_s * t + phase_rad)
