"""The guided path (bounces drawn partly toward a sphere) against Mitsuba's own ``path`` integrator.

Both trace the same camera rays with independent seeds; the image is averaged in 4 x 4 blocks and each block's
mean is compared within its Monte Carlo standard error (16 replicates). The scene mixes what the mixture must
get right: a textured diffuse floor, a rough conductor, a glass sphere (delta BSDF: never guided), a plastic
cube (a delta lobe beside a diffuse one), a two-sided diffuse card, and area, point, spot, directional and
environment lights; guides around an object, far off, around the camera (shading points inside the sphere) and
too small to trust."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_close_mc

from mincam_sim.render import backend
from mincam_sim.render.kernels.guided_path import MAX_GUIDED_DEPTH, guide_sphere, guided_radiance, supports

BLOCKS = 4
REPLICATES = 16
RAYS = 1 << 15  # per replicate


def _scene(mi):
    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 8},
        "sensor": {"type": "perspective", "fov": 50,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0.0, -1.6, 0.9], target=[0, 0, 0.1],
                                                              up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": 16, "height": 16}},
        "floor": {"type": "rectangle", "to_world": mi.ScalarTransform4f().scale([1.0, 1.0, 1.0]),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "checkerboard", "color0": 0.2,
                                                              "color1": 0.7, "to_uv": mi.ScalarTransform4f().scale(
                                                                  [6, 6, 1])}}},
        "mover": {"type": "cube", "to_world": mi.ScalarTransform4f().translate([0.05, 0.0, 0.06]).scale(0.06),
                  "bsdf": {"type": "diffuse", "reflectance": 0.9}},
        "metal": {"type": "cube", "to_world": mi.ScalarTransform4f().translate([-0.35, 0.2, 0.1]).scale(0.1),
                  "bsdf": {"type": "roughconductor", "alpha": 0.3}},
        "glass": {"type": "sphere", "center": [0.3, 0.25, 0.12], "radius": 0.12,
                  "bsdf": {"type": "dielectric"}},
        "plastic": {"type": "cube", "to_world": mi.ScalarTransform4f().translate([0.35, -0.25, 0.07]).scale(0.07),
                    "bsdf": {"type": "plastic", "diffuse_reflectance": 0.5}},
        "card": {"type": "rectangle",
                 "to_world": mi.ScalarTransform4f().translate([-0.2, -0.3, 0.15]).rotate([1, 0, 0], 80).scale(0.1),
                 "bsdf": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": 0.6}}},
        "area": {"type": "rectangle",
                 "to_world": mi.ScalarTransform4f().translate([0.0, 0.0, 1.2]).rotate([1, 0, 0], 180).scale(0.3),
                 "emitter": {"type": "area", "radiance": 6.0}},
        "point": {"type": "point", "position": [0.6, -0.5, 0.6], "intensity": 0.6},
        "spot": {"type": "spot", "to_world": mi.ScalarTransform4f().look_at(origin=[-0.6, -0.6, 0.8],
                                                                            target=[0, 0, 0], up=[0, 0, 1]),
                 "intensity": 1.5, "cutoff_angle": 30},
        "sun": {"type": "directional", "direction": [0.3, 0.5, -1.0], "irradiance": 0.4},
        "sky": {"type": "constant", "radiance": 0.05},
    })


def _block_means(scene, max_depth: int, guide, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(BLOCKS^2,) mean radiance per image block and its standard error, over REPLICATES launches."""
    mi = backend.mitsuba()
    sensor = scene.sensors()[0]
    reference = mi.load_dict({"type": "path", "max_depth": max_depth})
    values = np.zeros((REPLICATES, BLOCKS * BLOCKS))
    for rep in range(REPLICATES):
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(seed * 1000 + rep, RAYS)
        position = sampler.next_2d()
        ray, weight = sensor.sample_ray(0.0, sampler.next_1d(), position, sampler.next_2d())
        if guide == "path":
            radiance, _, _ = reference.sample(scene, sampler, ray, None, True)
        else:
            radiance = guided_radiance(scene, sampler, ray, max_depth, guide)
        value = np.asarray(weight * radiance, dtype=np.float64).ravel()
        px, py = (np.asarray(c, dtype=float) for c in (position.x, position.y))
        block = np.minimum((px * BLOCKS).astype(int), BLOCKS - 1) * BLOCKS + np.minimum((py * BLOCKS).astype(int),
                                                                                         BLOCKS - 1)
        values[rep] = np.bincount(block, weights=value, minlength=BLOCKS * BLOCKS) / RAYS * BLOCKS * BLOCKS
    return values.mean(0), values.std(0, ddof=1) / np.sqrt(REPLICATES)


GUIDES = {
    "around the mover": (np.array([0.05, 0.0, 0.06]), 0.11),
    "far off": (np.array([3.0, 2.0, 0.5]), 0.2),
    "around the camera": (np.array([0.0, -1.0, 0.5]), 1.2),  # many shading points inside: not guided there
    "too small to trust": (np.array([0.05, 0.0, 0.06]), 1e-5),
}


@pytest.mark.parametrize("name", ["around the mover", "far off", "around the camera", "too small to trust"])
def test_guided_path_equals_mitsuba_path(name):
    scene = _scene(backend.mitsuba())
    expected, e_err = _block_means(scene, 3, "path", seed=1)
    value, v_err = _block_means(scene, 3, GUIDES[name], seed=2)
    assert_close_mc(value, expected, np.hypot(e_err, v_err), what=f"guided path ({name}) vs path, max_depth 3")
    assert np.hypot(e_err, v_err).max() < 0.05 * expected.max(), "the comparison should resolve 5 % of the image"


@pytest.mark.slow
@pytest.mark.parametrize("max_depth", [2, 4, 5])
def test_guided_path_equals_mitsuba_path_at_other_depths(max_depth):
    scene = _scene(backend.mitsuba())
    expected, e_err = _block_means(scene, max_depth, "path", seed=3)
    value, v_err = _block_means(scene, max_depth, GUIDES["around the mover"], seed=4)
    assert_close_mc(value, expected, np.hypot(e_err, v_err), what=f"guided path vs path, max_depth {max_depth}")


def test_guide_lowers_the_noise_of_light_thrown_by_an_object():
    """A bright card lit by a spot that the camera cannot see: the floor gets its light only through one
    bounce off the card. Guiding toward the card must cut the standard error (16 replicates each, same rays)."""
    mi = backend.mitsuba()
    scene = mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, -0.1, 1.5], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 8, "height": 8}},
        "floor": {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": 0.5}},
        "card": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0.0, 0.0, 0.3]).scale(0.05),
                 "bsdf": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": 0.9}}},
        "spot": {"type": "spot", "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0.01], target=[0, 0, 1],
                                                                            up=[0, 1, 0]),
                 "intensity": 5.0, "cutoff_angle": 9, "beam_width": 8},  # under the floor's plane: lights the card
    })
    plain, plain_err = _block_means(scene, 3, "path", seed=5)
    guided, guided_err = _block_means(scene, 3, guide_sphere(np.array([[-0.05, -0.05, 0.3], [0.05, 0.05, 0.3]])),
                                      seed=6)
    assert_close_mc(guided, plain, np.hypot(plain_err, guided_err), what="guided vs path, light off a card")
    assert np.median(guided_err / plain_err) < 0.5, f"guiding should cut the noise: {guided_err / plain_err}"


def test_guide_sphere_and_depth_support():
    centre, radius = guide_sphere(np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, 1.0, 0.0]]))
    np.testing.assert_allclose(centre, [1.0, 0.5, 0.0])
    assert radius == pytest.approx(np.hypot(1.0, 0.5))
    assert guide_sphere(None) is None and guide_sphere(np.zeros((0, 3))) is None
    assert guide_sphere(np.array([[0.0, 0.0, np.inf]])) is None
    assert supports(3) and supports(MAX_GUIDED_DEPTH) and not supports(-1) and not supports(MAX_GUIDED_DEPTH + 1)
    with pytest.raises(ValueError, match="max_depth"):
        guided_radiance(None, None, None, 0, None)
    with pytest.raises(ValueError, match="share"):
        guided_radiance(None, None, None, 3, None, share=1.0)
