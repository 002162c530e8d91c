"""The paper's mincam designs in a :class:`~.setup.Setup`: the intrusion pair (band ramps, Fig. 3a), the
tracking cross (ramps x, 1 - x, y, 1 - y, Eq. 5) and the speed mixel (a sinusoid, Eq. 9), and the same mincam
turned towards the calibration screen."""

from __future__ import annotations

import numpy as np

from mincam_sim import masks
from mincam_sim.experiments.setup import Setup
from mincam_sim.masks import Mask
from mincam_sim.masks.profiles import Band, Ramp
from mincam_sim.model.geometry import Pose
from mincam_sim.model.optics import Mincam, Mixel, cross_layout, layout


def band_ramp(setup: Setup, kind: str, boundary_x_m: float, band_m: float) -> Mask:
    """The 1D intrusion mask (paper Fig. 3a): a ramp along the boundary ``x = boundary_x_m``, ``kind`` "y" or
    "1-y", transparent only in a band ``band_m`` wide around the boundary's image on the mask."""
    if kind not in ("y", "1-y"):
        raise ValueError(f"band ramp kind must be 'y' or '1-y', got {kind!r}")
    u0 = setup.scene_to_mask(boundary_x_m)
    half = band_m * setup.d_f_m / setup.depth_m / setup.mask_size_m / 2
    size = setup.mask_size_m
    profile = Band(Ramp(kind, size, size), (u0 - half - 0.5) * size, (u0 + half - 0.5) * size)
    return masks.from_profile(profile, f"band_ramp_{kind}", setup.mask_resolution, size,
                              kind="band_ramp", ramp=kind, boundary_x_m=boundary_x_m, band_m=band_m)


def intrusion_mincam(setup: Setup, boundary_x_m: float, band_m: float) -> Mincam:
    """Two mixels ``spacing_m`` apart along the boundary, masks y and 1 - y restricted to the boundary band."""
    s = setup.spacing_m
    return layout(
        [band_ramp(setup, "y", boundary_x_m, band_m), band_ramp(setup, "1-y", boundary_x_m, band_m)],
        [(0.0, s / 2), (0.0, -s / 2)],
        ["y", "1-y"],
        center=setup.center,
        d_f_m=setup.d_f_m,
        detector_size_m=setup.detector_size_m,
    )


def tracking_mincam(setup: Setup) -> Mincam:
    """Four mixels (x, 1 - x, y, 1 - y) ``spacing_m`` from the centre camera (paper Eq. 5, Fig. 2)."""
    return cross_layout(setup.spacing_m, setup.mask_resolution, setup.mask_size_m, center=setup.center,
                        d_f_m=setup.d_f_m, detector_size_m=setup.detector_size_m)


def sinusoid_mixel(setup: Setup, period_m: float, pose: Pose, name: str = "sin") -> Mixel:
    """One mixel with the speed mask ``0.5 + 0.5 cos(2 pi x / period_m)`` (paper Eq. 9)."""
    mask = masks.sinusoid(2 * np.pi / period_m, 0.5, 0.5, resolution=setup.mask_resolution,
                          width_m=setup.mask_size_m)
    return Mixel(mask, setup.d_f_m, setup.detector_size_m, pose, name)


def mincam_on_screen(mincam: Mincam, setup: Setup) -> Mincam:
    """The same mincam turned to face the calibration screen (looking along -z from the origin)."""
    mixels = []
    for m in mincam:
        local = setup.center.to_local(np.asarray(m.pose.position_m))
        world = Pose().to_world(local)
        mixels.append(m.with_pose(Pose(tuple(world), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0))))
    return Mincam(tuple(mixels), allow_overlap=mincam.allow_overlap)
