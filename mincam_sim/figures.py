"""Figures of the README: mixel geometry, masks, response maps (``mincam-sim figures``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import masks
from .optics import Mixel, pair_layout
from .plots import _save, plot_mask, plot_mixel_geometry, plot_response_maps, plt
from .screen import Screen


def make_figures(out_dir: str | Path) -> list[Path]:
    """Write the README's figures into ``out_dir``."""
    from .render.screen_engine import response_maps

    out_dir = Path(out_dir)
    paths = [plot_mixel_geometry(Mixel(masks.ramp("x")), 0.5, out_dir / "mixel_geometry.png")]
    library = [masks.ramp("x"), masks.sinusoid(2 * np.pi / 0.4e-3), masks.circular_ramp()]
    fig, axes = plt.subplots(1, len(library), figsize=(4.2 * len(library), 3.4))
    for ax, mask in zip(axes, library, strict=True):
        plot_mask(mask, ax=ax, title=mask.name)
    paths.append(_save(fig, out_dir / "masks.png"))
    screen = Screen()
    maps = response_maps(pair_layout(), screen, samples_per_texel=64, seed=0)
    paths.append(plot_response_maps(maps, screen, out_dir / "response_maps.png"))
    return paths
