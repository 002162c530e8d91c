"""Bounces guided through moving glass: the lights and their images in a glass block's faces guide the bounces,
and smooth glass draws reflection and refraction with even odds (``render/kernels/guided_path.py``). Checked
against an independent closed form (Fresnel's transmittance of a slab), against the plain estimator, and per
run on the glass block of ``tests/rare_paths.py`` (see also ``tests/render/test_world_trust.py``)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh
from conftest import Z, assert_close_mc
from rare_paths import _glass_mesh, rare_scene

import mincam_sim as ms
from mincam_sim import Pose
from mincam_sim.model.optics import cross_layout
from mincam_sim.render.kernels.change_geometry import delta_light_point_sets, face_planes
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.updates import vertex_update
from mincam_sim.render.solvers.change import FallbackWarning

IOR = 1.5


def fresnel_reflectance(cos_i: np.ndarray, eta: float = IOR) -> np.ndarray:
    """Unpolarised Fresnel reflectance of a smooth dielectric interface (from air into ``eta``), by the two
    polarisations' amplitude coefficients."""
    cos_i = np.asarray(cos_i, float)
    sin_t = np.sqrt(1.0 - cos_i ** 2) / eta
    cos_t = np.sqrt(1.0 - sin_t ** 2)
    r_s = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    r_p = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return 0.5 * (r_s ** 2 + r_p ** 2)


def test_face_planes_of_a_block_are_its_six_planes_and_lights_are_mirrored_in_them():
    world, frames, background = rare_scene("glass")
    world.update({**background, **frames[0]})
    planes = face_planes(world.shapes_by_id["lens"])
    assert len(planes) == 6
    normals = np.abs(np.array([n for n, _ in planes]))
    assert np.allclose(np.sort(normals.sum(0)), [2.0, 2.0, 2.0])  # two planes per axis
    lights, images = delta_light_point_sets(world.scene, {"lens"})
    assert len(lights) == 1 and len(images) == 6  # the light and its image in each face plane
    for (n, c), image in zip(planes, images, strict=True):  # mirrored: the midpoints lie on the plane
        np.testing.assert_allclose((0.5 * (lights[0] + image)) @ n, c, atol=1e-6)
    assert delta_light_point_sets(world.scene, {"table"}) == ([], [])  # not a delta shape: nothing
    world.update(background)


def _slab_world():
    """4 mixels 0.4 m over a 1 x 1 m grey table (nothing beyond: the mixels see far) lit by a 0.6 m lamp 2 m
    up; a 1.2 x 1.2 m glass slab 1 mm thick, 0.6 m up, covers every path from the lamp to the table (frame), or
    is parked aside (background)."""
    cam = cross_layout(center=Pose((0.0, 0.0, 0.4), (0, 0, -1), (0, 1, 0)))
    elements = {
        "table": {"type": "rectangle", "to_world": sd._transform(np.diag([0.5, 0.5, 1.0, 1.0])),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "spectrum", "value": 0.5}}},
        "lamp": sd.area_light(0.6, 0.6, Pose((0.0, 0.0, 2.0), (0.0, 0.0, -1.0)).matrix(), 5.0),
    }
    box = trimesh.creation.box((1.2, 1.2, 0.001))  # thin: the shift of a ray through it (~0.05 mm) changes nothing
    placed = box.vertices + [0.0, 0.0, 0.6]
    parked = box.vertices + [8.0, 8.0, 0.6]
    elements["slab"] = _glass_mesh("slab", parked, box.faces)
    world = ms.Simulation(cam, world=elements, max_depth=4)
    return world, [vertex_update("slab", placed)], vertex_update("slab", parked)


def _slab_transmittance_range() -> tuple[float, float]:
    """(least, most) of the slab's transmittance (1 - F)^2 (no inner reflection reaches the lamp within 4
    segments; the two faces are parallel, so both see the same angle) over the angles from the table (0.5 m
    half-width) to the lamp (0.3 m half-width, 2 m up)."""
    tan_max = (0.5 * np.sqrt(2) + 0.3 * np.sqrt(2)) / 2.0
    cos = np.linspace(1.0 / np.sqrt(1.0 + tan_max ** 2), 1.0, 200)
    t = (1.0 - fresnel_reflectance(cos)) ** 2
    return float(t.min()), float(t.max())


def _slab_ratio(solver, spp: int, seed: int):
    world, frames, background = _slab_world()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FallbackWarning)
        ch = world.measure_changes(frames, background, solver, ms.Budget(spp=spp, seed=seed, replicates=8))
    dp, dp_e = ch.dp.irradiance_w_m2[0], ch.dp.stderr_w_m2[0]
    bg = np.asarray(ch.dp.meta["background_w_m2"])
    bg_e = np.asarray(ch.dp.meta["background_stderr_w_m2"])
    ratio = 1.0 + dp / bg
    sigma = np.hypot(dp_e / bg, dp * bg_e / bg ** 2)
    return ratio, sigma, ch


@pytest.mark.parametrize("solver", [ms.StratifiedChange(), ms.PlainChange()], ids=["guided", "plain"])
def test_a_glass_slab_transmits_fresnels_two_surface_share(solver):
    """The table under a glass slab, lit only through it: P(frame) / P(background) is the slab's
    transmittance (1 - F)^2, F from Fresnel's equations at n = 1.5 (0.9216 near normal incidence), to the
    estimator's standard error. Guided: the lamp is found by bounces aimed at it (a slab with parallel faces
    keeps its direction), the glass's reflection and refraction drawn with even odds; plain: Mitsuba's own
    path, which checks the set-up."""
    lo, hi = _slab_transmittance_range()
    assert 0.917 < lo <= hi < 0.9217
    ratio, sigma, ch = _slab_ratio(solver, 1 << 18, 3)
    if isinstance(solver, ms.StratifiedChange):
        assert ch.info.guided_frames == 1 and not ch.info.fallbacks
    expected = np.clip(ratio, lo, hi)  # anywhere in the closed form's range
    assert_close_mc(ratio, expected, sigma, what="slab transmittance P(frame) / P(background), per mixel")
    weights = sigma ** -2.0  # the mixels' rays are independent: their inverse-variance mean
    pooled, pooled_sigma = (weights * ratio).sum() / weights.sum(), weights.sum() ** -0.5
    assert pooled_sigma < 0.005, f"the test needs the ratio to 0.5 %: {pooled} +/- {pooled_sigma}"
    assert_close_mc(pooled, np.clip(pooled, lo, hi), pooled_sigma, what="slab transmittance, the mixels pooled")
    assert abs(pooled - 1.0) > 10 * pooled_sigma, "the Fresnel loss must be resolved"


@pytest.mark.slow
def test_glass_block_guided_agrees_with_plain_at_a_large_budget():
    """The glass block of tests/rare_paths.py: the mean of 16 guided runs against the plain estimator at 2^24
    rays per mixel (|z| <= 4.5 with both standard errors)."""
    from rare_paths import plain_reference, tail_counts

    _, _, _, values, _ = tail_counts("glass", range(16), 1 << 14)
    mean, mean_e = values.mean(0)[0], values.std(0, ddof=1)[0] / np.sqrt(len(values))
    plain, plain_e = plain_reference("glass", 1 << 24)
    assert_close_mc(mean, plain[0], np.hypot(mean_e, plain_e[0]), z=Z, what="guided glass vs plain")


def test_a_moving_glass_block_is_guided_and_a_curved_one_is_said():
    world, frames, background = rare_scene("glass")
    with warnings.catch_warnings():
        warnings.simplefilter("error", FallbackWarning)
        ch = world.measure_changes(frames, background, ms.StratifiedChange(),
                                   ms.Budget(spp=1 << 12, seed=1, replicates=8))
    assert not ch.info.fallbacks and ch.info.guided_frames == 1
    assert ch.dp.meta["guide_spheres_per_frame"] == [4]  # the block, the light, its images (sides; top, bottom)
    cam = cross_layout(center=Pose((0.0, 0.0, 0.4), (0, 0, -1), (0, 1, 0)))
    ball = np.diag([0.02, 0.02, 0.02, 1.0])
    elements = {"table": {"type": "rectangle", "bsdf": {"type": "diffuse"}},
                "lamp": sd.area_light(0.3, 0.3, Pose((0.0, 0.0, 1.0), (0, 0, -1)).matrix(), 5.0),
                "ball": {"type": "sphere", "to_world": sd._transform(ball),
                         "bsdf": {"type": "dielectric"}}}
    moved = ball.copy()
    moved[:3, 3] = [0.03, 0.0, 0.02]
    curved = ms.Simulation(cam, world=elements, max_depth=3)
    with pytest.warns(FallbackWarning, match="'ball' is glass or a mirror"):
        ch = curved.measure_changes([{"ball.to_world": moved}], {}, ms.StratifiedChange(),
                                    ms.Budget(spp=1 << 12, seed=1, replicates=8))
    assert any("ball" in f for f in ch.info.fallbacks)


def test_a_moving_instance_of_a_glass_block_is_guided_as_the_block_itself():
    """An instance draws its group's shapes but carries no BSDF of its own (Mitsuba gives it a diffuse one): its
    group's glass is found through it, its face planes are the group's under its ``to_world``, and the glass in the
    scene draws reflection and refraction with even odds. The block as an instance then measures what the block as
    a mesh measures, to float32 rounding, at the same seed (unguided, 48 seeds of it showed 4 of 192 values beyond
    4.5 sigma, max |z| 11.3; guided, none, max |z| 4.1, as the mesh). An instance of a curved glass group is said;
    an instance of a diffuse group says nothing."""
    out = {}
    for case in ("glass", "glass_instance"):
        world, frames, background = rare_scene(case)
        with warnings.catch_warnings():
            warnings.simplefilter("error", FallbackWarning)
            out[case] = world.measure_changes(frames, background, ms.StratifiedChange(),
                                              ms.Budget(spp=1 << 12, seed=1, replicates=8))
    mesh, instance = out["glass"], out["glass_instance"]
    assert not instance.info.fallbacks and instance.dp.meta["guide_spheres_per_frame"] == [4]
    np.testing.assert_allclose(instance.dp.irradiance_w_m2, mesh.dp.irradiance_w_m2, rtol=1e-5, atol=0)
    np.testing.assert_allclose(instance.dp.stderr_w_m2, mesh.dp.stderr_w_m2, rtol=1e-4, atol=0)
    cam = cross_layout(center=Pose((0.0, 0.0, 0.4), (0, 0, -1), (0, 1, 0)))
    placed, moved = np.eye(4), np.eye(4)
    placed[:3, 3], moved[:3, 3] = [0.5, 0.5, 0.015], [0.05, 0.03, 0.015]
    for part, said in (({"type": "sphere", "radius": 0.02, "bsdf": {"type": "dielectric"}}, True),
                       ({"type": "cube", "bsdf": {"type": "diffuse"}}, False)):
        elements = {"table": {"type": "rectangle", "bsdf": {"type": "diffuse"}},
                    "lamp": sd.area_light(0.3, 0.3, Pose((0.0, 0.0, 1.0), (0, 0, -1)).matrix(), 5.0),
                    "group": {"type": "shapegroup", "part": part},
                    "lens": {"type": "instance", "group": {"type": "ref", "id": "group"},
                             "to_world": sd._transform(placed)}}
        world = ms.Simulation(cam, world=elements, max_depth=3)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            ch = world.measure_changes([{"lens.to_world": moved}], {"lens.to_world": placed}, ms.StratifiedChange(),
                                       ms.Budget(spp=1 << 10, seed=1, replicates=8))
        named = [str(w.message) for w in caught if issubclass(w.category, FallbackWarning)
                 and "'lens' is glass or a mirror" in str(w.message)]
        assert bool(named) == said and any("lens" in f for f in ch.info.fallbacks) == said, (part, named)
