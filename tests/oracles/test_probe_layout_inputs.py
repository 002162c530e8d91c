"""Layouts that cannot be traced: mixels so far from their mincam's centre that float32 loses the mask, and
poses given as text, are one InputError."""

from __future__ import annotations

import numpy as np
import pytest

import mincam_sim as ms
from mincam_sim import masks
from mincam_sim.errors import InputError
from mincam_sim.model.optics import MAX_MINCAM_RADIUS_M


def test_a_mixel_far_from_its_mincam_is_refused():
    """``pair_layout(spacing_m=1e9)`` was accepted: its mixels 5e8 m from the scene's origin, where float32 is
    exact to 32 m and a 2 mm mask at 2 mm cannot be placed."""
    with pytest.raises(InputError, match=r"sits 5e\+08 m from its mincam's centre.*more than 10 m"):
        ms.pair_layout(spacing_m=1e9)
    cam = ms.pair_layout(spacing_m=2 * MAX_MINCAM_RADIUS_M)  # at the limit: 0.6 um in float32
    assert np.isclose(np.linalg.norm(cam.mixels[0].pose.position_m), MAX_MINCAM_RADIUS_M)
    far_centre = ms.layout([ms.masks.ramp("x", 4)] * 2, [(0.01, 0.0), (-0.01, 0.0)], center=ms.Pose((1e7, 0, 0)))
    assert len(far_centre.mixels) == 2  # far from the world origin is fine: the scene is built around the mincam


def test_pose_given_as_text_is_one_input_error():
    """``Pose(("a", 0, 0))`` was numpy's ValueError (could not convert string to float)."""
    with pytest.raises(InputError, match="position_m must be three finite numbers"):
        ms.Pose(("a", 0, 0))


@pytest.mark.parametrize("build", [lambda: ms.pair_layout(d_f_m=1e300),
                                   lambda: ms.single(masks.ramp("x", width_m=1e300)),
                                   lambda: ms.single(masks.ramp("x", height_m=1e300))])
def test_a_huge_mixel_length_is_one_input_error(build):
    """d_f or a mask side of 1e300 m overflowed the mixels' body-overlap test (OverflowError 34): one
    InputError naming the length and the cap (100 m, as in the configuration files)."""
    with pytest.raises(InputError, match="must be at most 100 metres"):
        build()
