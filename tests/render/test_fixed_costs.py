"""Per-frame shortcuts of the stratified change solver that must not change its numbers: kept traversals for the
frozen launches' buffer key (never a stale key), the guide-sphere merge computed over all pairs at once (the same
spheres as one pair at a time), parked background watch boxes merged into one, and an allocated run leaving the
scene at its background."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from test_moving import _world

import mincam_sim as ms
from mincam_sim.render import backend
from mincam_sim.render.kernels.change_geometry import merge_parked
from mincam_sim.render.kernels.guided_path import guide_sphere, guide_spheres
from mincam_sim.render.kernels.stratified import buffers_key
from mincam_sim.render.scene import scene_dicts as sd

pytestmark = pytest.mark.skipif(not backend.is_jit(), reason="needs a JIT variant (LLVM or CUDA)")


def _merge_one_pair_at_a_time(point_sets, merge_ratio=8.0, max_spheres=4):
    """The guide-sphere merge written out pair by pair (each merged sphere from the two groups' points joined)."""
    groups = [np.asarray(p, dtype=float).reshape(-1, 3) for p in point_sets if p is not None and np.size(p)]
    spheres = [guide_sphere(g) for g in groups]
    while len(groups) > 1:
        best, best_ratio = None, np.inf
        for a in range(len(groups)):
            for b in range(a + 1, len(groups)):
                merged = guide_sphere(np.concatenate([groups[a], groups[b]]))
                ratio = merged[1] ** 3 / (spheres[a][1] ** 3 + spheres[b][1] ** 3)
                if ratio < best_ratio:
                    best, best_ratio = (a, b, merged), ratio
        if best_ratio > merge_ratio and len(groups) <= max_spheres:
            break
        a, b, merged = best
        groups[a] = np.concatenate([groups[a], groups[b]])
        spheres[a] = merged
        del groups[b], spheres[b]
    return spheres


def test_guide_sphere_merge_equals_one_pair_at_a_time():
    """Bit for bit the spheres of the pair-by-pair merge, on random clusters (ties and empty sets included)."""
    rng = np.random.default_rng(5)
    for _ in range(300):
        sets = []
        for _ in range(int(rng.integers(1, 10))):
            centre = rng.normal(0.0, rng.choice([0.01, 0.1, 1.0]), 3)
            sets.append(centre + rng.normal(0.0, rng.choice([1e-3, 1e-2, 0.05]), (int(rng.integers(1, 40)), 3)))
            if rng.random() < 0.1:
                sets.append(sets[-1].copy())  # two movers at one place: equal ratios, the first pair wins
            if rng.random() < 0.1:
                sets.append(None)
        ratio, most = float(rng.choice([1.0, 4.0, 8.0, 50.0])), int(rng.integers(1, 6))
        want = _merge_one_pair_at_a_time(sets, ratio, most)
        got = guide_spheres(sets, ratio, most)
        assert len(got) == len(want)
        for (c_got, r_got), (c_want, r_want) in zip(got, want, strict=True):
            assert np.array_equal(c_got, c_want) and r_got == r_want


def _mesh_scene():
    mi = backend.mitsuba()
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    return mi.load_dict({"type": "scene", "toy": sd.mesh_object("toy", box.vertices, box.faces, 0.5)},
                        optimize=False)


def test_kept_traversals_never_give_a_stale_key():
    """With traversals kept between calls, the key after a parameter changes (new buffers, a new albedo) is the
    key a fresh traversal gives, and differs from the one before (a key cached per object would not)."""
    mi = backend.mitsuba()
    import drjit as dr

    scene = _mesh_scene()
    mesh = next(s for s in scene.shapes() if s.id() == "toy")
    kept: dict = {}
    before = buffers_key([mesh], kept)
    assert before == buffers_key([mesh])
    params = mi.traverse(mesh)
    moved = np.asarray(params["vertex_positions"]) + 0.25
    params["vertex_positions"] = mi.Float(np.ascontiguousarray(moved, dtype=np.float32))  # a new buffer
    params.update()
    after = buffers_key([mesh], kept)
    assert after == buffers_key([mesh])
    address = {k[0]: k[1] for k in after if len(k) == 3}
    assert address["vertex_positions"] == int(np.from_dlpack(params["vertex_positions"])
                                              .__array_interface__["data"][0])
    assert after != before
    key = next(k for k in params.keys() if "reflectance" in k)
    params[key] = type(params[key])(0.75)
    params.update()
    dr.eval()
    again = buffers_key([mesh], kept)
    assert again == buffers_key([mesh]) and again != after


def test_parked_boxes_merge_only_outside_the_static_box():
    """Boxes wholly outside the static shapes' box become one holding them, unless that one would reach in."""
    clear = (np.array([-1.0, -1.0, -1.0]), np.array([1.0, 1.0, 1.0]))
    inside = (np.array([-0.1, -0.1, 0.0]), np.array([0.1, 0.1, 0.1]))
    parked = [(np.array([5.0 + k, 5.0, 0.0]), np.array([5.1 + k, 5.1, 0.1])) for k in range(3)]
    got = merge_parked([inside, *parked], clear)
    assert len(got) == 2 and got[0] is inside
    np.testing.assert_array_equal(got[1][0], [5.0, 5.0, 0.0])
    np.testing.assert_array_equal(got[1][1], [7.1, 5.1, 0.1])
    across = [(np.array([5.0, 0.0, 0.0]), np.array([5.1, 0.1, 0.1])),
              (np.array([-5.1, 0.0, 0.0]), np.array([-5.0, 0.1, 0.1]))]  # their union holds the static box
    assert merge_parked(across, clear) == across
    assert merge_parked(parked, None) == parked


def test_allocated_run_leaves_the_background_and_repeats():
    """An allocated run (its last frame's extra passes leave the scene at the frame) ends with the scene at the
    background, and a second run with the same seed gives the same numbers."""
    world, frames, background = _world({}, (0.04, 0.02, 0.02))
    frames = frames([(0.03, 0.02, 0.0), (-0.05, 0.0, 0.0)])
    solver, budget = ms.StratifiedChange(), ms.Budget(spp=128 * 16, replicates=16, seed=5, target_rel_stderr=0.02)
    first = world.measure_changes(frames, background, solver, budget)
    after_run = {key: np.array(world.params[key]) for key in background}
    world.update(frames[-1])
    world.update(background)
    for key in background:  # as the background puts them (world coordinates read back through the scene's origin)
        np.testing.assert_array_equal(after_run[key], np.array(world.params[key]))
    assert first.dp.meta["allocation"]["replicates_max"] > 16  # extra passes were traced
    second = world.measure_changes(frames, background, solver, budget)
    np.testing.assert_array_equal(first.dp.irradiance_w_m2, second.dp.irradiance_w_m2)
    np.testing.assert_array_equal(first.dp.stderr_w_m2, second.dp.stderr_w_m2)
