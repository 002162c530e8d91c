"""The ground-truth camera's change of a frame from its background, rendered where it can be.

:meth:`mincam_sim.render.simulation.Simulation.camera_changes` renders the frame and the background over the
window of the camera's film where the moving shapes and their shadows can be seen
(``kernels.camera_window.change_window``), with the same seed lane by lane, and
optionally whole films with fewer samples for what reaches the rest of the film by inter-reflection.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mincam_sim.render.kernels.camera_window import Window


@dataclass(frozen=True)
class CameraChange:
    """The camera's view of one frame over ``window`` [px] (first row, first column, rows, columns; None where
    nothing the camera sees can change): the frame's and the background's pixels there [W m^-2 sr^-1], from
    the same random numbers; and, where whole films were rendered too, their difference outside the window."""

    window: Window | None
    frame: np.ndarray
    background: np.ndarray
    elsewhere: np.ndarray | None = None  # the whole film's difference outside the window (0 inside), or None

    def change_image(self, shape: tuple[int, int], elsewhere: bool = False) -> np.ndarray:
        """The frame minus the background over the whole film of ``shape`` (rows, columns): the window's, and
        outside it 0 or, with ``elsewhere``, the whole-film renders' difference there (if they were made)."""
        out = np.zeros(shape) if not (elsewhere and self.elsewhere is not None) else self.elsewhere.copy()
        if self.window is not None:
            row, col, rows, cols = self.window
            out[row:row + rows, col:col + cols] = self.frame - self.background
        return out


def outside(image: np.ndarray, window: Window | None) -> np.ndarray:
    """``image`` with the pixels of ``window`` (first row, first column, rows, columns) set to 0."""
    out = np.array(image, dtype=float)
    if window is not None:
        row, col, rows, cols = window
        out[row:row + rows, col:col + cols] = 0.0
    return out
