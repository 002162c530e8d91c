"""glTF / GLB files with their materials (written here by trimesh, y-up as glTF is): an emissive node lights the
scene as the view-factor quadrature says, a node moves as a mover, a base colour changes P as its closed form
says, and the base-colour texture lands where the file puts it.

Physics against :mod:`mincam_sim.oracles.quadrature` (no renderer code)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh
from conftest import assert_close_mc
from PIL import Image
from trimesh.visual import TextureVisuals
from trimesh.visual.material import PBRMaterial

import mincam_sim as ms
from mincam_sim import Pose, masks
from mincam_sim.errors import InputError
from mincam_sim.model.optics import Mincam, Mixel
from mincam_sim.oracles.quadrature import open_aperture_view_factor_irradiance
from mincam_sim.render import backend
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.gltf_files import GltfFile
from mincam_sim.render.scene.world_input import WorldWarning
from mincam_sim.scene.display import Screen

LAMP_M = (1.1, 0.62)  # the lamp's width and height [m], on the floor, emitting up
CARD_M = (0.10, 0.05)  # the card's width and height [m], 25 cm up, facing the lamp
CARD_Z_M = 0.25
RADIANCE = 3.0  # the lamp's radiance [W m^-2 sr^-1]
EMISSIVE = (1.0, 0.5, 0.25)  # its emissive factor: luminance 0.2126 + 0.7152 / 2 + 0.0722 / 4 (Rec. 709)
EMISSIVE_Y = 0.212671 + 0.715160 * 0.5 + 0.072169 * 0.25
MIXEL = Mixel(masks.constant(1.0), pose=Pose((0.0, 0.0, 0.5), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)), name="open")
CAM = Mincam((MIXEL,))


def _quad_y_up(width_m: float, depth_m: float, height_m: float, up: bool) -> trimesh.Trimesh:
    """A rectangle in a y-up file: ``width_m`` along x, ``depth_m`` along z, at y = ``height_m``, its front
    facing +y (``up``) or -y, with texture coordinates (0, 0) .. (1, 1) (v grows toward -z: the world's +y)."""
    hw, hd = width_m / 2, depth_m / 2
    vertices = np.array([[-hw, height_m, hd], [hw, height_m, hd], [hw, height_m, -hd], [-hw, height_m, -hd]])
    faces = np.array([[0, 1, 2], [0, 2, 3]]) if up else np.array([[0, 2, 1], [0, 3, 2]])
    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
    assert np.sign(mesh.face_normals[0, 1]) == (1 if up else -1)
    return mesh


def _material_mesh(mesh: trimesh.Trimesh, **material) -> trimesh.Trimesh:
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    mesh.visual = TextureVisuals(uv=uv, material=PBRMaterial(**material))
    return mesh


def _write(path, nodes: dict) -> GltfFile:
    scene = trimesh.Scene()
    for name, mesh in nodes.items():
        scene.add_geometry(mesh, node_name=name, geom_name=f"{name}_mesh")
    scene.export(path)
    return GltfFile(path, emission_w_m2_sr=RADIANCE / EMISSIVE_Y)


def _lamp() -> trimesh.Trimesh:
    return _material_mesh(_quad_y_up(*LAMP_M, 0.0, up=True), baseColorFactor=[0, 0, 0, 255],
                          emissiveFactor=list(EMISSIVE))


def _card() -> trimesh.Trimesh:
    return _material_mesh(_quad_y_up(*CARD_M, CARD_Z_M, up=False), baseColorFactor=[0.8, 0.8, 0.8, 1.0])


def _card_corners(x_m: float) -> np.ndarray:
    hw, hh = CARD_M[0] / 2, CARD_M[1] / 2
    return np.array([[x_m + sx * hw, sy * hh, CARD_Z_M] for sx in (-1, 1) for sy in (-1, 1) for _ in (0, 1)])


def _oracle(card_x_m: float | None) -> float:
    """Direct irradiance [W/m^2] of the open mixel from the lamp, the card (if any) in the way."""
    lamp = Screen(LAMP_M[0], LAMP_M[1], (16, 9), Pose((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0)))
    occluders = [] if card_x_m is None else [_card_corners(card_x_m)]
    return open_aperture_view_factor_irradiance(MIXEL, lamp, RADIANCE, occluders, n_detector=16)


def test_an_emissive_node_lights_the_scene_and_a_node_moves(tmp_path):
    """A GLB of two nodes: the lamp (emissive factor (1, 0.5, 0.25), its luminance times ``emission_w_m2_sr``
    the radiance) and a card named ``card.001`` (``card_001`` here). P as built against the quadrature with the
    card in the way; the card moved by its vertices (a node is a mover) against a background without it gives
    dP = the view-factor difference."""
    gltf = _write(tmp_path / "lamp_card.glb", {"lamp": _lamp(), "card.001": _card()})
    sim = ms.Simulation(CAM, world={"file": gltf}, max_depth=2)
    assert sim.movable() == ["card_001", "lamp"]
    card = sim.params["card_001.vertex_positions"].reshape(-1, 3)
    np.testing.assert_allclose(card[:, 2], CARD_Z_M, atol=1e-6)  # y-up file turned z-up, in metres
    moved = card + [0.08, 0.0, 0.0]
    frames = [{"card_001.vertex_positions": v.ravel()} for v in (card, moved)]
    ch = sim.measure_changes(frames, sim.without("card_001"),
                             budget=ms.Budget(spp=1 << 16, seed=3, replicates=16))
    bare = _oracle(None)
    p, sp = ch.p.irradiance_w_m2[:, 0], ch.p.stderr_w_m2[:, 0]
    assert_close_mc(p[0], _oracle(0.0), sp[0], what="the emissive node lighting the scene, the card in the way")
    expected = np.array([_oracle(0.0) - bare, _oracle(0.08) - bare])
    dp, sigma = ch.dp.irradiance_w_m2[:, 0], ch.dp.stderr_w_m2[:, 0]
    assert np.all(expected < -0.01 * bare) and np.all(sigma < 0.05 * np.abs(expected))
    assert_close_mc(dp, expected, sigma, what="the moved glTF node's dP against the view factors")


def _floor_gltf(path, rgba) -> GltfFile:
    floor = _material_mesh(_quad_y_up(0.8, 0.8, 0.0, up=True), baseColorFactor=list(rgba))
    return _write(path, {"floor": floor})


def test_a_base_colour_changes_p_as_its_closed_form_says(tmp_path):
    """A 0.8 m floor under a uniform sky of radiance L, seen by the open mixel 0.5 m up (direct light only):
    P = L (G_sky - G_floor) + rho L G_floor, with G the aperture's geometric factors of the whole lower
    hemisphere and of the floor (the quadrature), rho the luminance of the base colour: a grey 0.2 and a red
    (1, 0.2, 0.2), whose luminance is 0.2127 + 0.2 (0.7152 + 0.0722)."""
    sky_l = 2.0
    huge = Screen(2e3, 2e3, (8, 8), Pose((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0)))
    floor = Screen(0.8, 0.8, (8, 8), Pose((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0)))
    g_sky = open_aperture_view_factor_irradiance(MIXEL, huge, 1.0, n_detector=16)
    g_floor = open_aperture_view_factor_irradiance(MIXEL, floor, 1.0, n_detector=16)
    for k, (rgba, rho) in enumerate((((0.2, 0.2, 0.2, 1.0), 0.2),
                                     ((1.0, 0.2, 0.2, 1.0), 0.212671 + 0.2 * (0.715160 + 0.072169)))):
        gltf = _floor_gltf(tmp_path / f"floor{k}.gltf", rgba)
        sim = ms.Simulation(CAM, world={"file": gltf, "sky": sd.sky(sky_l)}, max_depth=2)
        m = sim.measure([{}], budget=ms.Budget(spp=1 << 15, seed=k, replicates=16))
        expected = sky_l * (g_sky - g_floor) + rho * sky_l * g_floor
        assert_close_mc(m.irradiance_w_m2[0, 0], expected, m.stderr_w_m2[0, 0], what=f"base colour {rgba}")


def test_the_base_colour_texture_lands_where_the_file_puts_it(tmp_path):
    """A floor whose base-colour texture is white in its top rows (the image's first rows: glTF's v = 0) and
    black below, times a factor 0.6 (153 / 255: trimesh keeps base-colour factors in 8 bits): the reflectance
    Mitsuba evaluates is 0.6 x sRGB-decoded white on the side the texture coordinates put the top rows (world +y
    here) and 0 on the other."""
    image = np.zeros((4, 8, 3), np.uint8)
    image[:2] = 255
    floor = _material_mesh(_quad_y_up(0.8, 0.8, 0.0, up=True), baseColorTexture=Image.fromarray(image),
                           baseColorFactor=[0.6, 0.6, 0.6, 1.0])
    gltf = _write(tmp_path / "poster.glb", {"floor": floor})
    sim = ms.Simulation(CAM, world={"file": gltf, "sky": sd.sky(1.0)}, max_depth=2)
    mi = backend.mitsuba()
    origin = sim.scene_mincam.centre_m - sim.mincam.centre_m  # world -> scene: the scene is built around the rig
    ys = np.array([0.3, 0.1, -0.1, -0.3])
    o = np.stack([np.zeros(4), ys, np.full(4, 0.2)], axis=1) + origin
    ray = mi.Ray3f(mi.Point3f(*[mi.Float(o[:, j]) for j in range(3)]), mi.Vector3f(0.0, 0.0, -1.0))
    si = sim.scene.ray_intersect(ray)
    albedo = np.array(si.bsdf().eval_diffuse_reflectance(si), dtype=float).ravel()
    np.testing.assert_allclose(albedo, [0.6, 0.6, 0.0, 0.0], atol=1e-6)


def test_bad_gltf_inputs_are_one_clear_error(tmp_path):
    (tmp_path / "bad.glb").write_bytes(b"not a glb")
    with pytest.raises(InputError, match="could not be read by trimesh"):
        ms.Simulation(CAM, world={"file": GltfFile(tmp_path / "bad.glb")})
    with pytest.raises(InputError, match="does not exist"):
        ms.Simulation(CAM, world={"file": GltfFile(tmp_path / "missing.glb")})
    with pytest.raises(InputError, match="up must be"):
        GltfFile(tmp_path / "x.glb", up="x")
    with pytest.raises(InputError, match="emission_w_m2_sr"):
        GltfFile(tmp_path / "x.glb", emission_w_m2_sr=-1.0)
    clash = _write(tmp_path / "clash.glb", {"a.b": _card(), "a_b": _lamp()})
    with pytest.raises(InputError, match="rename one of them"):
        ms.Simulation(CAM, world={"file": clash})


def test_dropped_material_parts_are_said_once(tmp_path):
    metal = _material_mesh(_quad_y_up(0.8, 0.8, 0.0, up=True), baseColorFactor=[0.5, 0.5, 0.5, 1.0],
                           metallicFactor=1.0, roughnessFactor=0.3)
    gltf = _write(tmp_path / "metal.glb", {"floor": metal})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ms.Simulation(CAM, world={"file": gltf, "sky": sd.sky(1.0)}, max_depth=2)
    said = [w for w in caught if issubclass(w.category, WorldWarning) and "metallic" in str(w.message)]
    assert len(said) == 1, [str(w.message) for w in caught]


def test_a_gltf_scene_from_a_world_config_and_from_a_path(tmp_path):
    """``[world] scene = "lamp_card.gltf"`` (y-up unless ``up`` is set, ``emission_w_m2_sr`` the emission's scale,
    the buffers it names part of the run's files) with the node ``card_001`` as a mover, against the quadrature;
    ``world="lamp_card.gltf"`` from Python builds the same nodes; parameters are refused for a glTF file."""
    from mincam_sim.configuration.world_config import load_world_config
    from mincam_sim.errors import ConfigError
    from mincam_sim.runs.jobs import run_world_config

    gltf = _write(tmp_path / "lamp_card.gltf", {"lamp": _lamp(), "card.001": _card()})
    text = f"""[run]
spp = 16384
replicates = 16
seed = 4
max_depth = 2
out_dir = "out"
[mincam]
layout = "custom"
[[mixel]]
name = "open"
mask = "constant:1.0"
position_m = [0.0, 0.0, 0.5]
forward = [0.0, 0.0, -1.0]
[world]
scene = "lamp_card.gltf"
emission_w_m2_sr = {gltf.emission_w_m2_sr!r}
[[world.mover]]
id = "card_001"
offsets_m = [[0.0, 0.0, 0.0], [0.08, 0.0, 0.0]]
"""
    (tmp_path / "c.toml").write_text(text)
    cfg = load_world_config(tmp_path / "c.toml")
    assert cfg.up == "y" and any(f.suffix == ".bin" for f in cfg.files)
    ch = run_world_config(cfg)
    expected = np.array([_oracle(0.0), _oracle(0.08)]) - _oracle(None)
    assert_close_mc(ch.dp.irradiance_w_m2[:, 0], expected, ch.dp.stderr_w_m2[:, 0], what="TOML glTF node mover")
    sim = ms.Simulation(CAM, world=tmp_path / "lamp_card.gltf", max_depth=2)
    assert sim.movable() == ["card_001", "lamp"]
    with pytest.raises(InputError, match="glTF, which has no <default> parameters"):
        ms.Simulation(CAM, world=tmp_path / "lamp_card.gltf", parameters={"lamp": 0})
    (tmp_path / "c.toml").write_text(text + "[world.parameters]\nlamp = 0\n")
    with pytest.raises(ConfigError, match="a glTF file has none"):
        load_world_config(tmp_path / "c.toml")


def test_a_mirrored_node_keeps_its_front_side(tmp_path):
    """glTF: a node whose transform mirrors (negative determinant) has its triangles' winding reversed. The lamp
    mirrored in x (the same rectangle) still emits up: P as the quadrature says (0 had its front turned down)."""
    scene = trimesh.Scene()
    scene.add_geometry(_lamp(), node_name="lamp", geom_name="lamp_mesh", transform=np.diag([-1.0, 1.0, 1.0, 1.0]))
    scene.export(tmp_path / "mirrored.glb")
    gltf = GltfFile(tmp_path / "mirrored.glb", emission_w_m2_sr=RADIANCE / EMISSIVE_Y)
    sim = ms.Simulation(CAM, world={"file": gltf}, max_depth=2)
    m = sim.measure([{}], budget=ms.Budget(spp=1 << 14, seed=6, replicates=16))
    assert_close_mc(m.irradiance_w_m2[0, 0], _oracle(None), m.stderr_w_m2[0, 0], what="a mirrored emissive node")
