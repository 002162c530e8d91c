"""Scenes with rare light paths for the per-run honesty of the stratified estimator's standard error: two movers
far apart and out of view (all of their change is light they throw onto the table), a mover seen only in a
mirror, a glass block, a small moving emitter (a lamp carried through the view), and a torus read from an OBJ
file moving over a floor textured by a PNG file (the scene as a user writes it). Shared by
tests/render/test_world_trust.py and the per-run tail measurement (``python tests/rare_paths.py``)."""

from __future__ import annotations

import numpy as np
import trimesh

import mincam_sim as ms
from mincam_sim import Pose
from mincam_sim.model.optics import cross_layout
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.updates import vertex_update

HEIGHT_M = 0.4  # mixels above the table; their view reaches ~0.2 m from the centre on the table
PARK_M = np.array([5.0, 5.0, 0.0])  # where movers wait out of the scene


def _ball(at_m) -> np.ndarray:
    """to_world of a 2 cm ball centred at ``at_m`` (Mitsuba's sphere has radius 1 at the origin)."""
    m = np.diag([0.01, 0.01, 0.01, 1.0])
    m[:3, 3] = at_m
    return m


def _box(size_m, at_m):
    box = trimesh.creation.box(size_m)
    box.apply_translation((0.0, 0.0, size_m[2] / 2))
    return box.vertices + np.asarray(at_m, float), box.faces


def _glass_mesh(name: str, vertices, faces):
    from mincam_sim.render import backend

    mi = backend.mitsuba()
    props = mi.Properties()
    props["bsdf"] = mi.load_dict({"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0})
    mesh = mi.Mesh(name, len(vertices), len(faces), props=props)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(np.asarray(vertices, dtype=np.float32).ravel())
    params["faces"] = mi.UInt32(np.asarray(faces, dtype=np.uint32).ravel())
    params.update()
    return mesh


def _user_files() -> tuple[str, str]:
    """A torus (OBJ, 3 cm across) and a floor texture (PNG, 64 x 64 random gray tiles), written once per
    machine into a temporary folder: paths of files, as a user's scene names them."""
    import tempfile
    from pathlib import Path

    from mincam_sim.storage.imageio import write_png

    folder = Path(tempfile.gettempdir()) / "mincam_rare_paths"
    folder.mkdir(exist_ok=True)
    obj, png = folder / "torus.obj", folder / "floor.png"
    if not obj.exists():
        torus = trimesh.creation.torus(major_radius=0.012, minor_radius=0.004, major_sections=24, minor_sections=12)
        torus.export(obj.with_suffix(".tmp.obj"))
        obj.with_suffix(".tmp.obj").replace(obj)
    if not png.exists():
        tiles = np.random.default_rng(5).uniform(0.1, 0.9, (16, 16))
        write_png(png.with_suffix(".tmp.png"), np.kron(tiles, np.ones((4, 4))))
        png.with_suffix(".tmp.png").replace(png)
    return str(obj), str(png)


def _mirror() -> dict:
    """A vertical perfect mirror at x = 0.22 m facing -x, 40 x 30 cm, its centre 15 cm up."""
    return {"type": "rectangle",
            "to_world": sd._transform(Pose((0.22, 0.0, 0.15), (-1.0, 0.0, 0.0)).matrix()
                                      @ np.diag([0.2, 0.15, 1.0, 1.0])),
            "bsdf": {"type": "conductor", "material": "none"}}


def rare_scene(case: str):
    """(world, frames, background) for ``case`` in {"far_movers", "mirror", "mirror_instance", "glass",
    "glass_instance", "emitter", "textured"}."""
    cam = cross_layout(center=Pose((0.0, 0.0, HEIGHT_M), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)))
    elements = {
        "table": {"type": "rectangle", "to_world": sd._transform(np.diag([0.8, 0.8, 1.0, 1.0])),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "spectrum", "value": 0.4}}},
        "light": sd.area_light(0.3, 0.3, Pose((0.0, 0.0, 1.2), (0.0, 0.0, -1.0)).matrix(), 10.0),
    }
    if case == "far_movers":
        # small bright boxes 0.55 m either side: out of view, their shadows too; one sphere around both holds
        # everything the mixels see
        places = {"left": (-0.55, 0.0, 0.0), "right": (0.55, 0.05, 0.0)}
        sizes = {"left": (0.04, 0.04, 0.05), "right": (0.04, 0.04, 0.05)}
    elif case == "mirror":
        # a vertical perfect mirror at x = 0.22 (facing -x) throws the light onto the table at x = 0.13 .. 0.22,
        # in view; a small mover there blocks part of that light (a shadow of the light's image, found only by
        # bounces that meet the mirror and then the light) and is seen in the mirror
        elements["light"] = sd.area_light(0.1, 0.1, Pose((0.0, 0.0, 1.0), (0.0, 0.0, -1.0)).matrix(), 90.0)
        elements["mirror"] = _mirror()
        places = {"mover": (0.18, 0.03, 0.0)}
        sizes = {"mover": (0.02, 0.02, 0.03)}
    elif case == "mirror_instance":
        # the same mirror drawn by an instance of a shape group
        elements["light"] = sd.area_light(0.1, 0.1, Pose((0.0, 0.0, 1.0), (0.0, 0.0, -1.0)).matrix(), 90.0)
        elements["group"] = {"type": "shapegroup", "sheet": _mirror()}
        elements["mirror"] = {"type": "instance", "group": {"type": "ref", "id": "group"}}
        places = {"mover": (0.18, 0.03, 0.0)}
        sizes = {"mover": (0.02, 0.02, 0.03)}
    elif case == "glass":
        # a glass block (a dielectric mesh) in view: its caustic on the table and what it refracts are found only
        # through delta bounces, which are never guided
        places = {"lens": (0.05, 0.03, 0.0)}
        sizes = {"lens": (0.04, 0.04, 0.03)}
    elif case == "glass_instance":
        # the same block as an instance of a shape group, moved by its to_world
        v, f = _box((0.04, 0.04, 0.03), (0.0, 0.0, 0.0))
        elements["group"] = {"type": "shapegroup", "block": _glass_mesh("block", v, f)}
        parked, placed = np.eye(4), np.eye(4)
        parked[:3, 3], placed[:3, 3] = PARK_M, (0.05, 0.03, 0.0)
        elements["lens"] = {"type": "instance", "group": {"type": "ref", "id": "group"},
                            "to_world": sd._transform(parked)}
        world = ms.Simulation(cam, world=elements, max_depth=3)
        return world, [{"lens.to_world": placed}], {"lens.to_world": parked}
    elif case == "emitter":
        # a 2 cm glowing ball carried through the view at 5 cm height: seen directly, and lighting the table
        elements["glow"] = {"type": "sphere", "to_world": sd._transform(_ball(PARK_M)),
                            "emitter": {"type": "area", "radiance": {"type": "spectrum", "value": 40.0}}}
        world = ms.Simulation(cam, world=elements, max_depth=3)
        return world, [{"glow.to_world": _ball([0.04, -0.02, 0.05])}], {"glow.to_world": _ball(PARK_M)}
    elif case == "textured":
        obj, png = _user_files()
        elements["table"]["bsdf"] = {"type": "diffuse", "reflectance": {"type": "bitmap", "filename": png}}
        elements["torus"] = {"type": "obj", "filename": obj,
                             "bsdf": {"type": "diffuse", "reflectance": {"type": "spectrum", "value": 0.8}}}
        world = ms.Simulation(cam, world=elements, max_depth=3)
        v0 = np.asarray(world.params["torus.vertex_positions"], dtype=np.float64).reshape(-1, 3)
        lift = np.array([0.0, 0.0, 0.004 - v0[:, 2].min()])  # resting on the table
        return (world, [vertex_update("torus", v0 + lift + [0.06, 0.02, 0.0])],
                vertex_update("torus", v0 + lift + PARK_M))
    else:
        raise KeyError(case)
    parked, placed = {}, {}
    for k, (name, at) in enumerate(places.items()):
        v, f = _box(sizes[name], PARK_M + np.array([0.0, 0.3 * k, 0.0]))
        elements[name] = (sd.mesh_object(name, v, f, 0.9) if case != "glass" else _glass_mesh(name, v, f))
        parked.update(vertex_update(name, v))
        foot = v.min(axis=0) * [1, 1, 0] + np.array(sizes[name]) * [0.5, 0.5, 0]  # the box's foot centre
        placed.update(vertex_update(name, v - foot + np.asarray(at)))
    world = ms.Simulation(cam, world=elements, max_depth=3)
    return world, [placed], parked


def tail_counts(case: str, seeds, spp: int, replicates: int = 8):
    """Over independent seeds: each run's dP against the mean of all other runs (z with both standard errors:
    the run's reported sigma and the spread of the others' mean), how many values lie beyond 4.5 sigma, how
    many are 0 +/- 0, the z values and the runs' values and sigmas (runs, frames, mixels)."""
    import warnings

    world, frames, background = rare_scene(case)
    values, sigmas = [], []
    for seed in seeds:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            dp = world.measure_changes(frames, background, ms.StratifiedChange(),
                                       ms.Budget(spp=spp, seed=int(seed), replicates=replicates)).dp
        values.append(dp.irradiance_w_m2)
        sigmas.append(dp.stderr_w_m2)
    v, s = np.array(values), np.array(sigmas)
    n = len(v)
    others = (v.sum(0) - v) / (n - 1)
    spread = np.array([np.delete(v, i, axis=0).std(0, ddof=1) / np.sqrt(n - 1) for i in range(n)])
    z = (v - others) / np.hypot(s, spread)
    zero = int(np.sum((v == 0) & (s == 0)))
    return int(np.sum(np.abs(z) > 4.5)), zero, z, v, s


def plain_reference(case: str, spp: int, seed: int = 12345, replicates: int = 16):
    world, frames, background = rare_scene(case)
    dp = world.measure_changes(frames, background, ms.PlainChange(), ms.Budget(spp=spp, seed=seed,
                                                                               replicates=replicates)).dp
    return dp.irradiance_w_m2, dp.stderr_w_m2


if __name__ == "__main__":
    import sys
    import time

    case = sys.argv[1]
    n_seeds = int(sys.argv[2]) if len(sys.argv) > 2 else 64
    spp = int(sys.argv[3]) if len(sys.argv) > 3 else 1 << 14
    t0 = time.time()
    beyond, zero, z, v, s = tail_counts(case, range(n_seeds), spp)
    print(f"{case}: {beyond} of {z.size} beyond 4.5 sigma, {zero} values 0 +/- 0, max |z| {np.abs(z).max():.1f}, "
          f"mean dP {v.mean(0).ravel()} +/- {(v.std(0, ddof=1) / np.sqrt(len(v))).ravel()}, "
          f"sigma spread/reported {(v.std(0, ddof=1) / np.sqrt((s ** 2).mean(0))).ravel()} ({time.time() - t0:.0f} s)")
    if "--plain" in sys.argv:
        ref = plain_reference(case, 1 << 22)
        print(case, "plain reference dP", ref[0].ravel(), "+/-", ref[1].ravel(), f"({time.time() - t0:.0f} s)")
