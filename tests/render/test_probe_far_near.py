"""A mincam far from the coordinates' origin with a surface millimetres from its masks: Mitsuba's 32-bit floats
misplace that surface by a share of its distance, which the warning for far scenes (from a 0.25 mm grid, 4 km)
did not see: at 1.2 km a small lamp 1 mm beyond a mask read 2.8 % low (17 sigma against the polygon quadrature)
without a word."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from conftest import assert_close_mc

import mincam_sim as ms
from mincam_sim import Pose, masks
from mincam_sim.model.optics import Mincam, Mixel
from mincam_sim.oracles.quadrature import mixel_irradiance_polygon
from mincam_sim.render import backend
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.world_input import WorldWarning
from mincam_sim.scene.display import Screen

pytestmark = pytest.mark.skipif(not backend.is_jit(), reason="needs a JIT variant (LLVM or CUDA)")
RADIANCE = 2.0


def _chip(shift_m) -> tuple[ms.Simulation, float, list[str]]:
    """A ramp mixel at ``shift_m`` looking down -z, a 2 x 2 mm lamp 1 mm beyond its mask and 1.1 mm to the side:
    the simulation, the quadrature's irradiance [W/m^2] and the float32 warnings said."""
    shift = np.asarray(shift_m, dtype=float)
    mixel = Mixel(masks.ramp("x"), pose=Pose(tuple(shift), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)), name="m")
    lamp = Pose(tuple(shift + [0.0011, 0.0, -(mixel.d_f_m + 1e-3)]), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0))
    oracle = mixel_irradiance_polygon(mixel, Screen(0.002, 0.002, (2, 2), lamp), radiance=RADIANCE)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        sim = ms.Simulation(Mincam((mixel,)), world={"chip": sd.area_light(0.002, 0.002, lamp.matrix(), RADIANCE)},
                            max_depth=2)
    told = [str(w.message) for w in said if issubclass(w.category, WorldWarning) and "32-bit" in str(w.message)]
    return sim, oracle, told


def test_a_surface_mm_from_the_masks_of_a_far_mincam_is_warned():
    """1.2 km out: one warning names the grid, the distance of the surface and how far to bring the origin."""
    _, _, told = _chip((1200.3, -350.7, 40.1))
    assert len(told) == 1, told
    assert ("0.12 mm grid, and a surface its masks see lies 1.04 mm from one: it may be misplaced by up to 12 % of "
            "that distance" in told[0]), told[0]
    assert "move the scene's origin within 16 m of the mincam" in told[0]


def test_the_same_lamp_near_the_origin_reads_the_quadrature_without_a_word():
    sim, oracle, told = _chip((0.0, 0.0, 0.0))
    assert told == []
    m = sim.measure([{}], ms.Aperture(), ms.Budget(spp=1 << 18, replicates=16, seed=3))
    assert_close_mc(m.irradiance_w_m2[0, 0], oracle, m.stderr_w_m2[0, 0], what="lamp 1 mm beyond the mask")


def test_a_lamp_mm_across_before_one_mixel_is_not_a_unit_mistake():
    """A 2 mm lamp 1 mm beyond one 2 mm mask: the scene (2.8 mm across) was compared with the 1 cm device a
    single mixel is taken to sit in and warned as 'less than the mincam (0.01 m)', a unit mistake it is not;
    the small-scene check now takes the rig's own size (its mask). A scene smaller than the mask is still said."""
    def size_warnings(lamp_m: float) -> list[str]:
        mixel = Mixel(masks.ramp("x"), pose=Pose((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)), name="m")
        lamp = Pose((0.0, 0.0, -(mixel.d_f_m + 1e-3)), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0))
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            ms.Simulation(Mincam((mixel,)), world={"chip": sd.area_light(lamp_m, lamp_m, lamp.matrix(), RADIANCE)},
                          max_depth=2)
        return [str(w.message) for w in said if "less than the mincam" in str(w.message)]

    assert size_warnings(0.002) == []
    told = size_warnings(0.0005)
    assert len(told) == 1 and "less than the mincam (0.002 m)" in told[0], told
