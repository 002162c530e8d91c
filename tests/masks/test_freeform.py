"""Freeform masks: any 2D array (Python, ``.npy``, PNG at any resolution, TOML) as a mixel's mask, and a random
freeform mask rendered against the quadrature oracle."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from conftest import assert_close_mc

import mincam_sim as ms
from mincam_sim import masks
from mincam_sim.configuration.config import load_config, parse_mask
from mincam_sim.errors import ConfigError
from mincam_sim.masks.profiles import MaskProfile
from mincam_sim.oracles.quadrature import mixel_irradiance_polygon
from mincam_sim.render import backend
from mincam_sim.storage import imageio


def _learned(shape=(128, 128), seed=1) -> np.ndarray:
    return np.random.default_rng(seed).random(shape)


def test_from_array_keeps_the_array_and_its_size():
    arr = _learned()
    m = masks.from_array(arr, 0.002, name="learned")
    assert m.shape == (128, 128) and m.profile is None and m.width_m == m.height_m == 0.002
    np.testing.assert_array_equal(m.transmission, arr)
    assert m.meta["kind"] == "freeform"
    wide = masks.from_array(np.ones((64, 128)), 0.004)
    assert wide.height_m == pytest.approx(0.002)  # square texels by default


@pytest.mark.parametrize("array, match", [
    (np.full((8, 8), 200, dtype=np.uint8), "divide 8-bit values by 255"),
    (np.ones((2, 8, 8)), "2D array"),
    (np.full((8, 8), 1.5), r"\[0, 1\]"),
])
def test_from_array_refuses_what_is_not_a_transmission(array, match):
    with pytest.raises(ValueError, match=match):
        masks.from_array(array, 0.002)


def test_npy_files_load_from_python_and_from_toml(tmp_path):
    arr = _learned((128, 128))
    np.save(tmp_path / "m.npy", arr)
    m = masks.load(tmp_path / "m.npy", width_m=0.002)
    np.testing.assert_array_equal(m.transmission, arr)
    assert m.meta["format"] == "npy" and m.name == "m"
    with pytest.raises(ValueError, match="give width_m"):
        masks.load(tmp_path / "m.npy")
    np.testing.assert_allclose(masks.load(tmp_path / "m.npy", 0.002, invert=True).transmission, 1 - arr)

    from_toml = parse_mask("file:m.npy", 0.002, 256, "[[mixel]] #1", base_dir=tmp_path)
    np.testing.assert_array_equal(from_toml.transmission, arr)
    np.save(tmp_path / "wide.npy", np.ones((64, 128)))
    with pytest.raises(ConfigError, match=r"mask_size_m = \[0.002, 0.001\]"):
        parse_mask("file:wide.npy", 0.002, 256, "[[mixel]] #1", base_dir=tmp_path)
    np.save(tmp_path / "bad.npy", np.full((8, 8), 3.0))
    with pytest.raises(ConfigError, match=r"\[\[mixel\]\] #1.*\[0, 1\]"):
        parse_mask("file:bad.npy", 0.002, 256, "[[mixel]] #1", base_dir=tmp_path)


def test_a_custom_mincam_takes_freeform_files_in_its_toml(tmp_path):
    arr = _learned((128, 128), seed=4)
    np.save(tmp_path / "learned.npy", arr)
    imageio.write_png(tmp_path / "learned.png", np.round(arr * 255) / 255, bit_depth=8)
    (tmp_path / "c.toml").write_text(
        '[mincam]\nlayout = "custom"\n'
        '[[mixel]]\nname = "a"\nmask = "file:learned.npy"\nmask_size_m = 0.002\n'
        '[[mixel]]\nname = "b"\nmask = "file:learned.png"\nmask_size_m = 0.002\nposition_m = [0.01, 0.0, 0.0]\n')
    cfg = load_config(tmp_path / "c.toml")
    a, b = cfg.mincam
    np.testing.assert_array_equal(a.mask.transmission, arr)
    np.testing.assert_allclose(b.mask.transmission, arr, atol=0.5 / 255 + 1e-12)
    assert a.mask.width_m == b.mask.width_m == 0.002


def test_transmission_at_reads_between_texels_like_a_clamped_bitmap():
    m = masks.from_array(np.array([[0.0, 1.0], [0.5, 0.25]]), 0.002)
    w = 0.002
    # texel centres are exact; halfway between the top two centres: the mean; the clamped edge: the edge texel
    np.testing.assert_allclose(masks.transmission_at(m, [-w / 4, w / 4, 0.0, -w / 2], [w / 4, w / 4, w / 4, -w / 4]),
                               [0.0, 1.0, 0.5, 0.5])
    assert masks.transmission_at(m, w, 0.0) == 0.0  # outside the aperture
    nearest = masks.from_array(np.array([[0.0, 1.0], [0.5, 0.25]]), 0.002, interpolation="nearest")
    np.testing.assert_allclose(masks.transmission_at(nearest, [-1e-5, 1e-5, 1e-5], [1e-5, 1e-5, -1e-5]),
                               [0.0, 1.0, 0.25])


@dataclass(frozen=True)
class _RasterProfile(MaskProfile):
    """The oracle's view of a raster mask: its array read in numpy (the quadrature reads masks by profile)."""

    mask: masks.Mask

    def evaluate(self, x_m, y_m, ops=None):
        return masks.transmission_at(self.mask, x_m, y_m)


@pytest.mark.skipif(not backend.is_jit(), reason="needs a JIT variant (LLVM or CUDA)")
def test_a_random_freeform_mask_renders_as_the_quadrature_oracle_integrates_it():
    rng = np.random.default_rng(7)
    freeform = masks.from_array(rng.random((12, 12)), 0.002, name="random")
    mixel = ms.Mixel(freeform, pose=ms.Pose((0.0, 0.0, 0.0), (0.1, -0.05, -1.0)), name="free")
    screen = ms.Screen(1.2, 1.2, (8, 8))
    radiance, quadrant = 2.0, (-0.6, 0.0, 0.0, 0.6)  # the top-left quarter of the screen lit: part of the mask
    frame = np.zeros(screen.shape)
    frame[:4, :4] = radiance
    oracle_mixel = ms.Mixel(masks.Mask(freeform.transmission, 0.002, 0.002, "oracle",
                                       profile=_RasterProfile(freeform)), pose=mixel.pose)
    expected = mixel_irradiance_polygon(oracle_mixel, screen, quadrant, radiance, n_detector=4, n_triangle=10,
                                        subdivisions=3)
    m = ms.Simulation(ms.Mincam((mixel,)), screen=screen).measure(
        [frame], ms.Aperture(), ms.Budget(spp=1 << 20, replicates=16, seed=5))
    assert_close_mc(m.irradiance_w_m2[0, 0], expected, m.stderr_w_m2[0, 0], what="freeform mask vs quadrature")
    assert m.stderr_w_m2[0, 0] < 3e-3 * expected
    # a test that can fail: the mask's mean transmission instead of its structure is many sigma off
    uniform = mixel_irradiance_polygon(ms.Mixel(masks.constant(float(freeform.transmission.mean())),
                                                pose=mixel.pose), screen, quadrant, radiance, n_detector=4)
    assert abs(uniform - expected) > 10 * m.stderr_w_m2[0, 0]
