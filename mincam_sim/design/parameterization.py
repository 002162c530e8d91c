"""Mask parameterisation for design: a coarse grid of logits, bilinear onto the printer's dot grid, a sigmoid
onto the printer's grey values, and the film's tone curve onto printable transmissions. Pure numpy.

The optimiser (``mincam_sim.design.optimiser.optimise_masks``) evaluates the same chain in Dr.Jit;
``dots_from_logits`` is its NumPy twin (used for checks and for building the printable mask).
"""

from __future__ import annotations

import numpy as np

from mincam_sim.masks import Mask, PrintedFilm


def bilinear_upsample(grid: int, dots: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Indices (D, 4) into a ``grid x grid`` array and weights (D, 4) of its bilinear value at each dot centre.

    Grid nodes sit at texel centres ``(i + 0.5) / grid`` (clamped at the border), as Mitsuba's bilinear
    ``bitmap`` with ``clamp`` and :func:`mincam_sim.render.gradients.differentiable.lookup`.
    """
    if int(grid) != grid or grid < 1:
        raise ValueError(f"grid must be a positive integer number of nodes per side, got {grid!r}")
    h, w = dots
    v, u = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w, indexing="ij")
    x, y = u.ravel() * grid - 0.5, v.ravel() * grid - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    c0, c1 = np.clip(x0, 0, grid - 1).astype(int), np.clip(x0 + 1, 0, grid - 1).astype(int)
    r0, r1 = np.clip(y0, 0, grid - 1).astype(int), np.clip(y0 + 1, 0, grid - 1).astype(int)
    index = np.stack([r0 * grid + c0, r0 * grid + c1, r1 * grid + c0, r1 * grid + c1], axis=1)
    weight = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], axis=1)
    return index, weight


def logits_of(values: np.ndarray, clip: float = 0.03) -> np.ndarray:
    """Logits of printer grey values (clipped to ``[clip, 1 - clip]`` so that the sigmoid can move)."""
    v = np.clip(np.asarray(values, dtype=np.float64), clip, 1 - clip)
    return np.log(v / (1 - v))


def grid_values(mask: Mask, grid: int) -> np.ndarray:
    """A mask's transmission sampled at the ``grid x grid`` node centres (nearest texel), flat (grid*grid,)."""
    h, w = mask.shape
    rows = np.minimum(((np.arange(grid) + 0.5) / grid * h).astype(int), h - 1)
    cols = np.minimum(((np.arange(grid) + 0.5) / grid * w).astype(int), w - 1)
    return mask.transmission[np.ix_(rows, cols)].ravel()


def dots_from_logits(logits: np.ndarray, index: np.ndarray, weight: np.ndarray, film: PrintedFilm) -> np.ndarray:
    """Printer grey values (D,) in [0, 1] on the dot grid, quantised to the film's levels."""
    z = (np.asarray(logits)[index] * weight).sum(axis=1)
    value = 1.0 / (1.0 + np.exp(-z))
    if film.levels is not None:
        value = np.rint(value * (film.levels - 1)) / (film.levels - 1)
    return value


def printable_mask(grey: np.ndarray, dots: tuple[int, int], width_m: float, name: str, **meta) -> Mask:
    """The designed mask as the printer's input (grey values, one texel per dot, nearest), ready for
    :meth:`PrintedFilm.print` and :func:`mincam_sim.masks.export_print_png`."""
    return Mask(np.asarray(grey, dtype=np.float64).reshape(dots), width_m, width_m, name,
                {"kind": "designed", **meta}, interpolation="nearest")


__all__ = ["bilinear_upsample", "dots_from_logits", "grid_values", "logits_of", "printable_mask"]
