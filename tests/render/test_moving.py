"""Moving scenes at video rate: the stratified dP estimator against the plain one on scenes built to break its
region bounds, its standard error against the spread over independent seeds, and its region bounds."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from conftest import Z, assert_close_mc
from front import changes, estimates

import mincam_sim as ms
from mincam_sim import Pose
from mincam_sim.model.optics import cross_layout
from mincam_sim.render import backend
from mincam_sim.render.kernels.change_region import ApertureRegions, change_points, mixel_regions, mixel_regions_each
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.updates import vertex_update

HEIGHT = 0.4  # [m] mixels above the table
PARK = np.array([5.0, 5.0, 0.0])  # [m] where moving objects wait out of view


def _box(size_m, at_m) -> np.ndarray:
    box = trimesh.creation.box(size_m)
    box.apply_translation((0.0, 0.0, size_m[2] / 2))
    return box.vertices + np.asarray(at_m), box.faces


def _world(statics: dict, mover_size_m, light_at_m=(0.0, 0.0, 1.2), light_size_m=0.4):
    """4 mixels at HEIGHT over a 1 m textured table, a square area light facing down-ish towards the origin,
    static boxes ``name -> (size, position, albedo)`` and one moving box ``"mover"`` (parked)."""
    cam = cross_layout(center=Pose((0.0, 0.0, HEIGHT), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)))
    rng = np.random.default_rng(1)
    light_at = np.asarray(light_at_m, float)
    elements = {
        "table": sd.textured_plane(np.clip(0.4 + 0.1 * rng.standard_normal((32, 32)), 0, 1), 1.0, 1.0,
                                   Pose((0, 0, 0), (0, 0, 1)).matrix()),
        "light": sd.area_light(light_size_m, light_size_m,
                               Pose(light_at, -light_at / np.linalg.norm(light_at)).matrix(), 10.0),
    }
    for name, (size, at, albedo) in statics.items():
        v, f = _box(size, at)
        elements[name] = sd.mesh_object(name, v, f, albedo)
    v, f = _box(mover_size_m, PARK)
    elements["mover"] = sd.mesh_object("mover", v, f, 0.9)
    world = ms.Simulation(cam, world=elements)
    frames = lambda positions: [vertex_update("mover", v - PARK + np.asarray(p)) for p in positions]  # noqa: E731
    return world, frames, vertex_update("mover", v)


def _compare(world, frames, background, spp_plain, spp_fast, seed=1, what=""):
    plain, _ = changes(world, frames, background, spp=spp_plain, seed=seed)
    fast, _ = changes(world, frames, background, spp=spp_fast, seed=seed + 1, solver=ms.StratifiedChange())
    sigma = np.hypot(fast.stderr_w_m2, plain.stderr_w_m2)
    assert_close_mc(fast.irradiance_w_m2, plain.irradiance_w_m2, sigma, what=f"stratified vs plain dP, {what}")
    resolution = sigma.max() / np.abs(plain.irradiance_w_m2).max()
    assert resolution < 0.1, f"{what}: the comparison resolves only {resolution:.1%} of the largest change"
    return plain, fast


def test_tall_object():
    """A 25 cm pole reaching 15 cm below the mixels: its top projects far from its foot."""
    world, frames, bg = _world({}, (0.03, 0.03, 0.25))
    _compare(world, frames([(0.05, 0.03, 0.0), (-0.06, -0.02, 0.0)]), bg, 1 << 18, 1 << 15, what="tall object")


def test_object_partly_out_of_view():
    """A box straddling the edge of the mixels' fields of view (half-width ~0.2 m at the table)."""
    world, frames, bg = _world({}, (0.06, 0.06, 0.03))
    _compare(world, frames([(0.19, 0.0, 0.0), (0.0, -0.2, 0.0)]), bg, 1 << 18, 1 << 15, what="partly out of view")


def test_shadow_on_another_object():
    """Light low on one side: the moving box's shadow falls on a tall static box next to it."""
    world, frames, bg = _world({"wall": ((0.03, 0.12, 0.12), (0.06, 0.0, 0.0), 0.8)}, (0.04, 0.04, 0.04),
                               light_at_m=(-0.8, 0.0, 0.5))
    _compare(world, frames([(0.0, 0.0, 0.0), (-0.04, 0.03, 0.0)]), bg, 1 << 20, 1 << 18, what="shadow on object")


def test_light_partly_blocked():
    """A static plate 0.3 m below the light hides part of it: the box's shadow from the light's bounds is wider
    than its real shadow, and the plate's shading of the table changes nothing that moves."""
    world, frames, bg = _world({"plate": ((0.3, 0.6, 0.01), (0.12, 0.0, 0.9), 0.5)}, (0.05, 0.03, 0.03))
    _compare(world, frames([(0.02, 0.0, 0.0), (-0.08, 0.05, 0.0)]), bg, 1 << 18, 1 << 15, what="light blocked")


def test_wrong_region_costs_variance_not_bias():
    """Bounds that miss the object entirely (or are empty) still give an unbiased estimate: the other strata
    cover the whole aperture."""
    from mincam_sim.render.kernels.stratified import stratified_estimates

    world, frames, bg = _world({}, (0.06, 0.06, 0.03))
    world.update({**bg, **frames([(0.05, 0.0, 0.0)])[0]})
    ref = estimates(world, 1 << 16, seed=3)
    wrong = mixel_regions(world.mincam, np.array([[-0.15, -0.15, 0.0], [-0.14, -0.14, 0.01]]))
    for regions in (wrong, ApertureRegions.empty(world.mincam), ApertureRegions.full(world.mincam)):
        est = stratified_estimates(world.scene, world.sensor, world.mincam, regions, 8, [1024, 512, 512], 4,
                                   (1.0, 3.0))
        sigma = np.hypot(est.std(0, ddof=1), ref.std(0, ddof=1)) / np.sqrt(8)
        assert_close_mc(est.mean(0), ref.mean(0), sigma, what="stratified with wrong bounds vs plain P")


def test_reported_sigma_matches_spread_over_seeds():
    """Each seed's reported standard error agrees with the scatter of dP over 10 independent seeds (pooled over
    frames and mixels: chi-square bounds at ~1e-4 false-alarm probability)."""
    world, frames, bg = _world({}, (0.04, 0.02, 0.02))
    fr = frames([(0.03, 0.02, 0.0), (-0.05, 0.0, 0.0)])
    runs = [changes(world, fr, bg, spp=1 << 13, seed=100 + s, solver=ms.StratifiedChange())[0] for s in range(10)]
    values = np.stack([r.irradiance_w_m2 for r in runs])  # (seeds, frames, mixels)
    sigma = np.stack([r.stderr_w_m2 for r in runs])
    spread_var = values.var(axis=0, ddof=1)  # (frames, mixels), 9 degrees of freedom each
    reported_var = np.mean(sigma**2, axis=0)
    ratio = float(np.mean(spread_var / reported_var))  # 8 cells x 9 dof: ~ N(1, 0.17) (plus sigma's own noise)
    assert 0.45 < ratio < 1.7, f"spread / reported variance = {ratio:.2f}"


def test_jittered_background_agrees_with_plain_and_reports_its_spread():
    """The background's whole-aperture value of the stratified runs (aperture points on a jittered grid) is the
    independent estimator's value within sigma, and its reported sigma is the spread over 8 seeds."""
    from mincam_sim.render.kernels.stratified import whole_aperture_estimates

    world, frames, bg = _world({}, (0.04, 0.02, 0.02))
    world.update(bg)
    plain = estimates(world, 1 << 16, seed=3)
    runs = [whole_aperture_estimates(world.scene, world.sensor, world.mincam, 8, 1 << 14, seed=40 + s)
            for s in range(8)]
    means = np.stack([r.mean(0) for r in runs])  # (seeds, mixels)
    sigma = np.stack([r.std(0, ddof=1) / np.sqrt(8) for r in runs])
    plain_sigma = plain.std(0, ddof=1) / np.sqrt(8)
    assert_close_mc(means[0], plain.mean(0), np.hypot(sigma[0], plain_sigma), what="jittered vs plain background")
    ratio = float(np.mean(means.var(axis=0, ddof=1) / np.mean(sigma**2, axis=0)))  # 4 mixels x 7 dof
    assert 0.35 < ratio < 2.0, f"spread / reported variance = {ratio:.2f}"
    equal_rays_plain_sigma = 2.0 * plain_sigma  # the plain estimate had 4x the rays
    assert np.all(sigma[0] < 0.7 * equal_rays_plain_sigma), "the jittered grid should be less noisy at equal rays"


def test_guide_sphere_holds_the_mover_and_its_shadow_in_scene_coordinates():
    """The guide of a frame holds the moved box's corners and the shadow they cast on the table from the light's
    corners (scene coordinates: the world shifted by minus the mincam's centre); unbounded changes have none."""
    from mincam_sim.render.kernels.change_region import box_corners

    world, frames, bg = _world({}, (0.04, 0.02, 0.02))
    world.update({**bg, **frames([(0.05, -0.03, 0.0)])[0]})
    ((centre, radius),) = world.change_guide(["mover"])
    corners = box_corners(np.array([0.03, -0.04, 0.0]), np.array([0.07, -0.02, 0.02]))
    light = np.array([0.0, 0.0, 1.2])
    top = corners[corners[:, 2] > 0.01]
    shadow = light + (top - light) * (light[2] / (light[2] - top[:, 2:3]))  # where the top corners' shadow lands
    for p in np.concatenate([corners, shadow]) - world.scene_origin_m:
        assert np.linalg.norm(p - centre) <= radius + 1e-9, p
    assert radius < 0.2, "the guide should stay near the box"
    assert world.change_guide(["not a shape"]) is None
    world.update(bg)


def test_same_seed_same_numbers():
    world, frames, bg = _world({}, (0.04, 0.02, 0.02))
    fr = frames([(0.03, 0.02, 0.0)])
    a, pa = changes(world, fr, bg, spp=1 << 12, seed=5, solver=ms.StratifiedChange())
    b, pb = changes(world, fr, bg, spp=1 << 12, seed=5, solver=ms.StratifiedChange())
    np.testing.assert_array_equal(a.irradiance_w_m2, b.irradiance_w_m2)
    np.testing.assert_array_equal(pa.stderr_w_m2, pb.stderr_w_m2)
    assert a.meta["solver"] == "stratified_change" and a.meta["rays_per_mixel_per_frame"] > 0
    assert a.meta["guide_bounces"] and a.meta["guided_frames"] == 1


def test_region_bounds_hold_the_object_and_its_shadow():
    """Rays aimed at an object corner, and at a shadow point on the table, land inside the computed bounds."""
    cam = cross_layout(center=Pose((0.0, 0.0, HEIGHT), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)))
    box = (np.array([0.02, -0.01, 0.0]), np.array([0.06, 0.01, 0.02]))
    light = (np.array([-0.2, -0.2, 1.2]), np.array([0.2, 0.2, 1.2]))
    points = change_points([box], [light], (np.array([-0.5, -0.5, 0.0]), np.array([0.5, 0.5, 1.2])))
    regions = mixel_regions(cam, points)
    shadow = np.array([0.06, 0.01, 0.02]) + (np.array([0.06, 0.01, 0.02]) - [-0.2, -0.2, 1.2]) * (0.02 / 1.18)
    for k, mixel in enumerate(cam):
        for target in (box[1], shadow):
            local = mixel.pose.to_local(target)
            s = local[:2] * mixel.d_f_m / local[2] / np.array([mixel.mask.width_m, mixel.mask.height_m]) + 0.5
            assert np.all(s >= regions.base[k, :2] - 1e-9) and np.all(s <= regions.base[k, 2:] + 1e-9)
    assert np.all(regions.area_fraction() < 0.02)


def test_region_bounds_of_many_point_sets_at_once_equal_one_set_at_a_time():
    """``mixel_regions_each`` (every mover's points through each mixel's pose at once) gives, bit for bit, the
    bounds a loop over the sets and mixels gives (written out here), on a tilted rig 30 m from the origin: sets
    in view, one reaching behind a mask plane (the whole aperture), an empty one and None (the whole aperture)."""
    far = np.array([30.0, -12.0, 4.0])
    cam = cross_layout(center=Pose(tuple(far + [0.0, 0.0, HEIGHT]), (0.3, 0.1, -1.0), (0.0, 1.0, 0.0)))
    rng = np.random.default_rng(3)
    sets = [far + rng.uniform(-0.2, 0.2, (n, 3)) * [1, 1, 0.1] for n in (8, 72, 1, 40)]
    sets.insert(2, np.vstack([sets[0], far + [0.0, 0.0, HEIGHT + 0.05]]))  # one point above the mixels
    sets += [np.zeros((0, 3)), None]
    got = mixel_regions_each(cam, sets)
    for points, regions in zip(sets, got, strict=True):
        if points is None:
            assert np.all(np.isinf(regions.base)) and not regions.slope.any()
            continue
        if not len(points):
            assert regions.is_empty().all()
            continue
        for k, mixel in enumerate(cam):
            m = mixel.pose.matrix()
            local = (points - m[:3, 3]) @ m[:3, :3]
            if np.any(local[:, 2] <= mixel.d_f_m * (1 + 1e-9)):
                assert np.all(np.isinf(regions.base[k])) and not regions.slope[k].any()
                continue
            scale = mixel.d_f_m / local[:, 2]
            sx = local[:, 0] * scale / mixel.mask.width_m + 0.5
            sy = local[:, 1] * scale / mixel.mask.height_m + 0.5
            a = 1.0 - scale
            assert np.array_equal(regions.base[k], [sx.min(), sy.min(), sx.max(), sy.max()])
            assert np.array_equal(regions.slope[k], [a.min() / mixel.mask.width_m, a.max() / mixel.mask.width_m,
                                                     a.min() / mixel.mask.height_m, a.max() / mixel.mask.height_m])
    assert np.all(np.isinf(got[2].base))
    assert np.array_equal(mixel_regions(cam, sets[1]).base, got[1].base)


def test_bad_strata_are_clear_errors():
    world, frames, bg = _world({}, (0.04, 0.02, 0.02))
    with pytest.raises(ValueError, match="needs a change solver"):
        changes(world, frames([(0, 0, 0)]), bg, spp=64, solver=ms.Aperture())
    with pytest.raises(ValueError, match="strata_shares"):
        changes(world, frames([(0, 0, 0)]), bg, spp=64, solver=ms.StratifiedChange(strata_shares=(1.0, -1.0)))
    with pytest.raises(ValueError, match="expansions"):
        changes(world, frames([(0, 0, 0)]), bg, spp=64,
                solver=ms.StratifiedChange(strata_shares=(1.0, 1.0), strata_expansions=(2.0,)))
    assert Z == 4.5


@pytest.mark.slow
def test_small_box_high_precision_and_what_the_region_leaves_out():
    """The benchmark's kind of scene (a 4 x 2 x 2 cm box): stratified vs plain resolving 1 % of the largest
    change, and the part of dP outside the region bounds (light the box reflects onto the table) is many sigma
    from zero: an estimator of the region alone would be biased; the rings and the rest keep it unbiased."""
    from mincam_sim.render.kernels.stratified import stratified_estimates
    from mincam_sim.render.solvers.change import STRATA_EXPANSIONS

    world, frames, bg = _world({}, (0.04, 0.02, 0.02))
    fr = frames([(0.03, 0.02, 0.0), (-0.06, -0.01, 0.0)])
    plain, fast = _compare(world, fr, bg, 1 << 23, 1 << 18, seed=7, what="small box, high precision")
    resolution = np.hypot(plain.stderr_w_m2, fast.stderr_w_m2).max() / np.abs(plain.irradiance_w_m2).max()
    assert resolution < 0.01
    world.update(bg)
    regions = world.change_regions(["mover"])
    world.update({**bg, **fr[0]})
    regions = regions.union(world.change_regions(["mover"]))
    counts = [1 << 13] * (len(STRATA_EXPANSIONS) + 1)
    parts = stratified_estimates(world.scene, world.sensor, world.mincam, regions, 8, counts, 11, STRATA_EXPANSIONS,
                                 by_stratum=True)
    world.update(bg)
    parts = parts - stratified_estimates(world.scene, world.sensor, world.mincam, regions, 8, counts, 11,
                                         STRATA_EXPANSIONS, by_stratum=True)
    outside = parts[..., 1:].sum(axis=2)  # (replicates, mixels): dP outside the region
    z_outside = outside.mean(0) / (outside.std(0, ddof=1) / np.sqrt(len(outside)))
    assert np.all(np.abs(z_outside) > 5), f"outside-region dP only {z_outside} sigma"


def test_only_shapes_that_differ_from_the_background_bound_the_region():
    """Updates that re-set a parked shape to its background value do not move it (tracking frames re-park every
    toy but the active one): only the active shape's bounds enter the region."""
    from mincam_sim.render.kernels.change_geometry import changed_shapes

    bg = {"a.vertex_positions": np.zeros(6, np.float32), "b.vertex_positions": np.ones(6, np.float32)}
    frame = {"a.vertex_positions": np.full(6, 2.0, np.float32), "b.vertex_positions": np.ones(6, np.float32),
             "c.to_world": np.eye(4)}
    assert changed_shapes(frame, bg) == {"a", "c"}
    assert changed_shapes(bg, bg) == set()


# --- tilted, rotated mincams and every kind of light: the bounds checked against the sensor's own rays --------

TILTED_MOVER = ((0.04, 0.03, 0.03), (0.01, 0.02, 0.0))  # (size, foot position) [m]
LIGHTS = {
    "area": lambda: sd.area_light(0.3, 0.3, Pose((-0.3, 0.2, 0.9), (0.3, -0.2, -0.9)).matrix(), 10.0),
    "point": lambda: {"type": "point", "position": [0.2, -0.3, 0.8], "intensity": {"type": "spectrum", "value": 2.0}},
    "spot": lambda: {"type": "spot", "intensity": {"type": "spectrum", "value": 2.0}, "cutoff_angle": 40.0,
                     "to_world": sd._transform(Pose((0.2, -0.3, 0.8), (-0.2, 0.3, -0.8)).matrix())},
    "directional": lambda: {"type": "directional", "direction": [0.4, -0.3, -1.0],
                            "irradiance": {"type": "spectrum", "value": 3.0}},
}


def _tilted_mincam():
    """Two mixels at ~0.3 m looking obliquely down at the table, rolled, with different d_f, non-square masks
    (2 x 3 mm), an off-axis sinusoid and a 0.2 mm detector."""
    from mincam_sim import masks
    from mincam_sim.model.geometry import look_at
    from mincam_sim.model.optics import Mincam, Mixel

    first = look_at((0.12, -0.08, 0.3), (-0.03, 0.04, 0.0), up=(0.5, 1.0, 0.2))
    left, _, _ = first.axes()
    second = look_at(tuple(np.add(first.position_m, 0.033 * left)), (0.02, 0.0, 0.0), up=(-0.3, 1.0, 0.0))
    return Mincam((
        Mixel(masks.ramp("x", 64, 0.002, 0.003), d_f_m=0.002, detector_size_m=0.0002, pose=first, name="a"),
        Mixel(masks.sinusoid(4000.0, direction_deg=30.0, width_m=0.002, height_m=0.003), d_f_m=0.0035,
              detector_size_m=0.0002, pose=second, name="b"),
    ))


def _tilted_world(light: str):
    rng = np.random.default_rng(2)
    elements = {
        "table": sd.textured_plane(np.clip(0.4 + 0.1 * rng.standard_normal((32, 32)), 0, 1), 1.0, 1.0,
                                   Pose((0, 0, 0), (0, 0, 1)).matrix()),
        "light": LIGHTS[light](),
    }
    size, at = TILTED_MOVER
    v, f = _box(size, PARK)
    elements["mover"] = sd.mesh_object("mover", v, f, 0.9)
    world = ms.Simulation(_tilted_mincam(), world=elements)
    frame = vertex_update("mover", v - PARK + np.asarray(at))
    return world, frame, vertex_update("mover", v)


def _light_points(light: str) -> np.ndarray:
    """Points a shadow ray can aim at [m] (a 5 x 5 grid over the area light); a directional light's rays come from
    far along minus its direction."""
    if light == "area":
        pose = Pose((-0.3, 0.2, 0.9), (0.3, -0.2, -0.9))
        g = np.linspace(-0.15, 0.15, 5)
        return pose.to_world(np.array([(x, y, 0.0) for x in g for y in g]))
    if light == "directional":
        d = np.array([0.4, -0.3, -1.0])
        return -1e3 * d[None] / np.linalg.norm(d)  # an offset from the shaded point, see _region_violations
    return np.array([[0.2, -0.3, 0.8]])


def _segment_hits_box(o: np.ndarray, d: np.ndarray, lo, hi, t_max) -> np.ndarray:
    """(n,) whether the segments ``o + t d``, ``0 < t < t_max``, meet the box [lo, hi] (slab test)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (np.asarray(lo) - o) / d, (np.asarray(hi) - o) / d
    near = np.nanmax(np.where(d != 0, np.minimum(t1, t2), -np.inf), axis=1)
    far = np.nanmin(np.where(d != 0, np.maximum(t1, t2), np.inf), axis=1)
    inside_slabs = np.all((d != 0) | ((o >= lo) & (o <= hi)), axis=1)
    return inside_slabs & (far >= np.maximum(near, 1e-9)) & (near < t_max)


def _region_violations(world, light: str, base_override=None, n: int = 40_000, seed: int = 0):
    """Rays of the fast sensor drawn uniformly over (detector, aperture), split by the change region of the
    mover: (rays outside that meet the mover or land in its shadow, rays inside that do)."""
    mi = backend.mitsuba()
    regions = world.change_regions(["mover"])
    base = regions.base if base_override is None else base_override
    mover = {s.id(): s for s in world.scene.shapes()}["mover"].bbox()
    lo_box, hi_box = np.array(mover.min, float), np.array(mover.max, float)
    lights = _light_points(light)
    if light != "directional":  # the renderer works around the mincam: scene = world - scene_origin_m
        lights = lights - world.scene_origin_m
    rng = np.random.default_rng(seed)
    outside_bad = inside_good = 0
    n_mix = len(world.mincam)
    for k, mixel in enumerate(world.mincam):
        u, s = rng.random((n, 2)), rng.random((n, 2))
        x_d = (u - 0.5) * (1 - 2e-6) * mixel.detector_size_m
        a = regions.slope[k]
        lo = base[k, :2] + np.minimum(a[[0, 2]] * x_d, a[[1, 3]] * x_d)
        hi = base[k, 2:] + np.maximum(a[[0, 2]] * x_d, a[[1, 3]] * x_d)
        margin = 1e-4  # float32 rounding of the sensor's sample mapping
        outside = np.any((s < lo - margin) | (s > hi + margin), axis=1)
        inside = np.all((s >= lo) & (s <= hi), axis=1)
        position = mi.Point2f((k + 0.5 + (u[:, 0] - 0.5) * (1 - 2e-6)) / n_mix, u[:, 1])
        ray, _ = world.sensor.sample_ray(0.0, mi.Float(0.5), position, mi.Point2f(s[:, 0], s[:, 1]))
        o, d = np.array(ray.o, float).T, np.array(ray.d, float).T
        hits_mover = _segment_hits_box(o, d, lo_box, hi_box, np.inf)
        si = world.scene.ray_intersect(ray)
        p = np.array(si.p, float).T
        valid = np.array(si.is_valid(), bool) & ~hits_mover
        shadowed = np.zeros(n, bool)
        for target in lights:
            towards = np.broadcast_to(target, p.shape) if light == "directional" else target - p
            shadowed |= valid & _segment_hits_box(p, towards, lo_box, hi_box, 1.0)
        changed = hits_mover | shadowed
        outside_bad += int(np.sum(changed & outside))
        inside_good += int(np.sum(changed & inside))
    return outside_bad, inside_good


@pytest.mark.parametrize("light", sorted(LIGHTS))
def test_tilted_mincam_bounds_hold_every_ray_that_meets_the_mover_or_its_shadow(light):
    """On a tilted, rolled two-mixel mincam (different d_f, non-square masks), no ray of the sensor outside the
    change region meets the moving box or lands in its shadow, for area, point, spot and directional lights;
    rays inside do (the check has something to find), and mirrored bounds fail it (the check can fail)."""
    world, frame, bg = _tilted_world(light)
    world.update({**bg, **frame})
    outside_bad, inside_good = _region_violations(world, light)
    assert outside_bad == 0, f"{light} light: {outside_bad} rays outside the change region meet the change"
    assert inside_good > 50, f"{light} light: only {inside_good} rays inside the region meet the change"
    regions = world.change_regions(["mover"])
    mirrored = regions.base.copy()
    mirrored[:, [0, 2]] = 1.0 - regions.base[:, [2, 0]]
    assert _region_violations(world, light, base_override=mirrored)[0] > 0
    assert np.all(regions.area_fraction() < 0.5), "the bounds should be a small part of the aperture"
    world.update(bg)


@pytest.mark.parametrize("light", ["area", "point"])
def test_tilted_mincam_stratified_agrees_with_plain(light):
    world, frame, bg = _tilted_world(light)
    _compare(world, [frame], bg, 1 << 18, 1 << 15, what=f"tilted mincam, {light} light")


def test_directional_light_shadow_points_and_bad_direction():
    """A directional light's shadow reaches the scene box's floor along its direction; a zero direction is a
    clear error."""
    box = (np.array([0.0, 0.0, 0.1]), np.array([0.02, 0.02, 0.12]))
    scene_box = (np.array([-1.0, -1.0, 0.0]), np.array([1.0, 1.0, 1.0]))
    points = change_points([box], [], scene_box, [np.array([1.0, 0.0, -1.0])])
    floor = np.array([0.12, 0.0, 0.0])  # the box's far bottom corner, 0.1 m up, shifted 0.1 m along +x to z = 0
    hull_lo, hull_hi = points.min(axis=0), points.max(axis=0)
    assert np.all(floor >= hull_lo - 1e-12) and np.all(floor <= hull_hi + 1e-12)
    with pytest.raises(ValueError, match="directions"):
        change_points([box], [], scene_box, [np.zeros(3)])


@pytest.mark.parametrize("solver", [ms.PlainChange(), ms.StratifiedChange()], ids=["plain", "stratified"])
def test_background_that_leaves_out_a_moved_parameter_means_the_scene_as_built(solver):
    """``background={}`` (or one that leaves out a parameter the frames set) restores the scene as built, run after
    run: the same numbers as the explicit background (it once traced the background with the frame's toy in place
    and returned dP = 0, or the previous run's last frame as the background)."""
    world, frames, bg = _world({}, (0.04, 0.02, 0.02))
    fr = frames([(0.03, 0.02, 0.0)])
    explicit, _ = changes(world, fr, bg, spp=1 << 12, seed=5, solver=solver)
    for _ in range(2):
        left_out, _ = changes(world, fr, {}, spp=1 << 12, seed=5, solver=solver)
        np.testing.assert_array_equal(left_out.irradiance_w_m2, explicit.irradiance_w_m2)
    assert np.any(np.abs(explicit.irradiance_w_m2) > 3 * explicit.stderr_w_m2), "the frame should change dP"


def test_stratified_run_killed_midway_resumes_to_the_same_numbers(tmp_path, monkeypatch):
    """A stratified run stopped after two of four frames resumes with them kept and gives the uninterrupted run's
    numbers; the same out dir refuses other strata shares, unguided bounces or the plain estimator."""
    import mincam_sim.render.solvers.change as change_module
    from mincam_sim.errors import StaleResultError

    world, frames, bg = _world({}, (0.04, 0.02, 0.02))
    fr = frames([(0.03, 0.02, 0.0), (-0.05, 0.0, 0.0), (0.0, -0.04, 0.0), (0.06, 0.05, 0.0)])
    whole, _ = changes(world, fr, bg, spp=1 << 12, seed=7, solver=ms.StratifiedChange())
    real, calls = change_module.stratified_lanes, []
    budget = ms.Budget(spp=1 << 12, seed=7, replicates=8)

    def dies_on_the_fifth_pass(*args, **kwargs):  # two passes per frame: frames 0 and 1 finish
        calls.append(1)
        if len(calls) == 5:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(change_module, "stratified_lanes", dies_on_the_fifth_pass)
    with pytest.raises(KeyboardInterrupt), ms.Run(tmp_path) as run:
        run.measure_changes(world, fr, bg, ms.StratifiedChange(), budget)
    monkeypatch.setattr(change_module, "stratified_lanes", lambda *a, **k: calls.append(1) or real(*a, **k))
    calls.clear()
    with ms.Run(tmp_path) as run:
        resumed = run.measure_changes(world, fr, bg, ms.StratifiedChange(), budget).dp
    assert len(calls) == 4, f"the resumed run traced {len(calls) // 2} frames, not the 2 left"
    np.testing.assert_array_equal(resumed.irradiance_w_m2, whole.irradiance_w_m2)
    np.testing.assert_array_equal(resumed.stderr_w_m2, whole.stderr_w_m2)
    (tmp_path / "measurements.npz").unlink()  # the store alone decides
    for other in (ms.PlainChange(), ms.StratifiedChange(strata_shares=(0.5, 0.1, 0.1, 0.1, 0.2)),
                  ms.StratifiedChange(guide_bounces=False)):
        with ms.Run(tmp_path) as run, pytest.raises(StaleResultError):
            run.measure_changes(world, fr, bg, other, budget)


def _odd_world(case: str):
    """A glass mover over a textured table; a box over a rough-metal table; a small sphere 6 cm under a tilted
    4-mixel mincam (area light, then a point light over rough metal)."""
    import os
    import tempfile

    rng = np.random.default_rng(5)
    metal = {"type": "rectangle", "bsdf": {"type": "roughconductor", "alpha": 0.2},
             "to_world": sd._transform(Pose((0, 0, 0), (0, 0, 1)).matrix() @ np.diag([0.5, 0.5, 1.0, 1.0]))}
    textured = sd.textured_plane(np.clip(0.4 + 0.1 * rng.standard_normal((32, 32)), 0, 1), 1.0, 1.0,
                                 Pose((0, 0, 0), (0, 0, 1)).matrix())
    if case.startswith("close"):
        cam = cross_layout(center=Pose((0.0, 0.0, 0.06), (0.1, 0.0, -1.0), (0.0, 1.0, 0.0)))
        sphere = trimesh.creation.icosphere(subdivisions=2, radius=0.008)
        sphere.apply_translation((0, 0, 0.008))
        v, f, at = sphere.vertices + PARK, sphere.faces, np.array([0.004, 0.0, 0.0])
    else:
        cam = _tilted_mincam()
        v, f = _box((0.03, 0.02, 0.025), PARK)
        at = np.array([0.0, 0.02, 0.0])
    light = "point" if case == "close, point light, metal" else "area"
    elements = {"table": metal if "metal" in case else textured, "light": LIGHTS[light]()}
    if case == "glass mover":
        path = os.path.join(tempfile.mkdtemp(), "mover.ply")
        trimesh.Trimesh(v, f, process=False).export(path)
        elements["mover"] = {"type": "ply", "filename": path, "bsdf": {"type": "dielectric"}}
    else:
        elements["mover"] = sd.mesh_object("mover", v, f, 0.9)
    world = ms.Simulation(cam, world=elements)
    return world, vertex_update("mover", v - PARK + at), vertex_update("mover", v)


@pytest.mark.parametrize("case", ["glass mover", "box over metal", "close, area light", "close, point light, metal"])
def test_stratified_agrees_with_plain_on_glass_metal_and_close_geometry(case):
    """Delta BSDFs on the mover (never guided), a glossy table, and mixels 6 cm above a 16 mm sphere (the change
    region's rings reach past the aperture's edge)."""
    world, frame, bg = _odd_world(case)
    plain, _ = changes(world, [frame], bg, spp=1 << 19, seed=1)
    fast, _ = changes(world, [frame], bg, spp=1 << 16, seed=2, solver=ms.StratifiedChange())
    sigma = np.hypot(fast.stderr_w_m2, plain.stderr_w_m2)
    assert_close_mc(fast.irradiance_w_m2, plain.irradiance_w_m2, sigma, what=f"stratified vs plain dP, {case}")
    assert np.all(sigma < 0.2 * np.abs(plain.irradiance_w_m2)), f"{case}: the comparison should resolve each dP"
