"""The ground-truth camera's change of a frame from its background, rendered where it can be.

:meth:`mincam_sim.render.simulation.Simulation.camera_changes` renders the frame and the background over the
windows of the camera's film where the moving shapes and their shadows can be seen
(``kernels.camera_window.change_windows``), with the same seed lane by lane, and
optionally whole films with fewer samples for what reaches the rest of the film by inter-reflection.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mincam_sim.render.kernels.camera_window import Window


@dataclass(frozen=True)
class CameraChange:
    """The camera's view of one frame over ``windows`` [px] (each: first row, first column, rows, columns; none
    where nothing the camera sees can change): the frame's and the background's pixels in each [W m^-2 sr^-1],
    from the same random numbers; and, where whole films were rendered too, their difference outside the
    windows."""

    windows: tuple[Window, ...]
    frame: tuple[np.ndarray, ...]
    background: tuple[np.ndarray, ...]
    elsewhere: np.ndarray | None = None  # the whole film's difference outside the windows (0 inside), or None

    def change_image(self, shape: tuple[int, int], elsewhere: bool = False) -> np.ndarray:
        """The frame minus the background over the whole film of ``shape`` (rows, columns): the windows', and
        outside them 0 or, with ``elsewhere``, the whole-film renders' difference there (if they were made)."""
        out = np.zeros(shape) if not (elsewhere and self.elsewhere is not None) else self.elsewhere.copy()
        for (row, col, rows, cols), frame, background in zip(self.windows, self.frame, self.background, strict=True):
            out[row:row + rows, col:col + cols] = frame - background
        return out

    def inside(self, shape: tuple[int, int]) -> np.ndarray:
        """Boolean image of ``shape``: True in the windows."""
        out = np.zeros(shape, dtype=bool)
        for row, col, rows, cols in self.windows:
            out[row:row + rows, col:col + cols] = True
        return out


def outside(image: np.ndarray, windows: tuple[Window, ...]) -> np.ndarray:
    """``image`` with the pixels of ``windows`` (each: first row, first column, rows, columns) set to 0."""
    out = np.array(image, dtype=float)
    for row, col, rows, cols in windows:
        out[row:row + rows, col:col + cols] = 0.0
    return out
