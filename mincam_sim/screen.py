"""Displays and sweeps: kept here for existing imports; the descriptions live in :mod:`mincam_sim.scene.display`."""

from .scene.display import (  # noqa: F401
    DEFAULT_DISTANCE_M,
    INCH_M,
    PAPER_SCREEN_SIZE_M,
    Screen,
    Sweep,
    check_visible,
    coverage,
    diagonal_to_size,
    grid_sweep,
    line_sweep,
    vertical_line,
    white_square,
)
