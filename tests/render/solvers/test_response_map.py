"""What the response-map solver says when a mixel reads 0 +/- 0: a map that sampled per texel and missed the
mixel's view (texels far larger than the part of the screen the mixel sees), a mask that shuts the screen off,
and frames lit only outside the view are three different things, each said as it is."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from conftest import assert_close_mc

import mincam_sim as ms
from mincam_sim import masks
from mincam_sim.render import backend
from mincam_sim.render.kernels.monte_carlo import UnseenWarning
from mincam_sim.scene.display import visible_screen_area_m2

pytestmark = pytest.mark.skipif(not backend.is_jit(), reason="needs a JIT variant (LLVM or CUDA)")

BEYOND_MASK_M = 0.5e-3  # the screen this far beyond a single mixel's mask: its view there is ~2.5 mm across


def _close_screen() -> tuple[ms.Simulation, ms.Screen]:
    cam = ms.single()
    screen = ms.Screen(resolution=(16, 9), pose=ms.Pose((0.0, 0.0, -(cam[0].d_f_m + BEYOND_MASK_M)), (0.0, 0.0, 1.0)))
    return ms.Simulation(cam, screen=screen), screen


def _said(measure) -> tuple[ms.Measurements, list[str]]:
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        result = measure()
    return result, [str(w.message) for w in said if issubclass(w.category, UnseenWarning)]


def test_texels_larger_than_the_view_are_said_not_unseen():
    """A uniform screen 0.5 mm beyond the mask: the aperture solver reads ~0.75 W/m^2, the response map 0 +/- 0
    because 16 samples per 69 mm texel put ~0.02 in the mixel's 6.4 mm^2 view. It said 'no sample reached a lit
    part' (untrue: the whole screen is lit and in view); it says the texels are larger than the view, by how much,
    and points to ms.Aperture() and to the samples per texel that would see it, which then agree with the
    aperture solver."""
    sim, screen = _close_screen()
    frames = [np.ones(screen.shape)]
    half = 0.525 * (sim.mincam[0].d_f_m + BEYOND_MASK_M) - 0.05e-3  # [m] tan(half fov) z - detector / 2
    assert visible_screen_area_m2(screen, sim.mincam[0]) == pytest.approx((2 * half) ** 2, rel=1e-9)
    m, told = _said(lambda: sim.measure(frames, ms.ResponseMap(), ms.Budget(samples_per_texel=16)))
    assert m.irradiance_w_m2[0, 0] == 0 and m.stderr_w_m2[0, 0] == 0
    assert len(told) == 1, told
    assert "reached a lit part" not in told[0]
    for part in ("mixel(s) m0 read 0 +/- 0 W/m^2 in 1 frame(s) (first: 0)", "though the screen is in view",
                 "is 750.7 times the part of the screen m0 sees through its aperture (6.38 mm^2)",
                 "16 samples per texel put about 0.021 sample(s) in that view", "ms.Aperture()",
                 "raise samples_per_texel to at least 753424"):
        assert part in told[0], (part, told[0])
    advised, told = _said(lambda: sim.measure(frames, ms.ResponseMap(), ms.Budget(samples_per_texel=753424)))
    aperture = sim.measure(frames, ms.Aperture(), ms.Budget(spp=1 << 16))
    assert told == []
    assert_close_mc(advised.irradiance_w_m2, aperture.irradiance_w_m2,
                    np.hypot(advised.stderr_w_m2, aperture.stderr_w_m2), what="the advised samples per texel")


def test_an_opaque_mask_is_said_apart_from_frames_lit_elsewhere():
    """An opaque mask (an empty map, the screen in view at 0.5 m) is said as such; a map that saw the screen and
    frames lit only outside the view keep the words 'not seen'."""
    screen = ms.Screen(resolution=(16, 9))
    dark = ms.Simulation(ms.single(masks.constant(0.0)), screen=screen)
    _, told = _said(lambda: dark.measure([np.ones(screen.shape)], ms.ResponseMap(), ms.Budget(samples_per_texel=16)))
    assert len(told) == 1 and "their masks are opaque toward it or the other mixels' bodies hide it" in told[0]
    corner = np.zeros(screen.shape)
    corner[0, 0] = 1.0
    aside = ms.Simulation(ms.single(pose=ms.Pose((0.0, 0.0, 0.0), (0.3, 0.0, -1.0))), screen=screen)
    m, told = _said(lambda: aside.measure([corner], ms.ResponseMap(), ms.Budget(samples_per_texel=16)))
    assert m.irradiance_w_m2[0, 0] == 0 and np.any(m.maps.weights_sr[0])
    assert len(told) == 1 and told[0].startswith("no sample of mixel(s) m0 reached a lit part")
    assert "not seen" in told[0]
