"""The standard mask library (four ramps, open aperture, a sinusoid, a circular ramp) and its files."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from mincam_sim.masks.curves import circular_ramp
from mincam_sim.masks.files import save_exr
from mincam_sim.masks.mask import DEFAULT_MASK_SIZE_M, DEFAULT_RESOLUTION, Mask, constant, ramp, sinusoid
from mincam_sim.storage import imageio
from mincam_sim.storage.atomic import atomic_path

LIBRARY_SINUSOID_PERIOD_M = 0.5e-3  # [m] period of the library sinusoid (omega = 2 pi / 0.5 mm)


def standard_library(resolution: int = DEFAULT_RESOLUTION, size_m: float = DEFAULT_MASK_SIZE_M) -> list[Mask]:
    """The standard masks: four ramps, open aperture, a sinusoid (period 0.5 mm) and a circular ramp."""
    masks = [ramp(k, resolution, size_m) for k in ("x", "1-x", "y", "1-y")]
    masks.append(constant(1.0, resolution, size_m))
    sin = sinusoid(2 * np.pi / LIBRARY_SINUSOID_PERIOD_M, 0.5, 0.5, resolution=resolution, width_m=size_m)
    masks.append(replace(sin, name=f"sinusoid_period{LIBRARY_SINUSOID_PERIOD_M * 1e3:g}mm"))
    masks.append(circular_ramp(resolution=resolution, width_m=size_m))
    return masks


def generate_library(
    out_dir: str | Path, resolution: int = DEFAULT_RESOLUTION, size_m: float = DEFAULT_MASK_SIZE_M
) -> list[Path]:
    """Write :func:`standard_library` as OpenEXR files plus an 8-bit grayscale PNG preview of each.

    Files are ``<name>.exr`` and ``<name>.png`` in ``out_dir`` (created if needed): ``ramp_x``, ``ramp_1-x``,
    ``ramp_y``, ``ramp_1-y``, ``constant_1``, ``sinusoid_period0.5mm``, ``circular_ramp``. Output is
    deterministic (byte-identical for equal arguments) and every file is written atomically.

    Parameters
    ----------
    out_dir : str or Path
        Output directory.
    resolution : int
        Texels per side.
    size_m : float
        Side of the square masks [m].

    Returns
    -------
    list of Path
        Written files, EXR and PNG alternating, in library order.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths: list[Path] = []
    for m in standard_library(resolution, size_m):
        paths.append(save_exr(m, out / f"{m.name}.exr"))
        png = out / f"{m.name}.png"
        with atomic_path(png) as tmp:
            imageio.write_png(tmp, m.transmission, bit_depth=8)
        paths.append(png)
    return paths
