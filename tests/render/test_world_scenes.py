"""Your own scene as Mitsuba users write it: ``<default>`` parameters set from Python and TOML, any shape or light
as a mover, a loaded ``mi.Scene`` as the world, shapes without an id, the file's ``<integrator>`` depth, scenes
modelled in cm (``unit_m``), and the silent answers of a lightless world or a mincam inside a shape.

Physics is checked against the view-factor quadrature of :mod:`mincam_sim.oracles.quadrature` (no renderer code):
a lamp on the floor seen by an open-aperture mixel 50 cm above it, a 10 x 5 cm card between them."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh
from conftest import assert_close_mc

import mincam_sim as ms
from mincam_sim import Pose, masks
from mincam_sim.errors import ConfigError, InputError
from mincam_sim.frames import MemorySink
from mincam_sim.model.optics import Mincam, Mixel
from mincam_sim.oracles.quadrature import open_aperture_view_factor_irradiance
from mincam_sim.render import backend
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.world_input import WorldWarning
from mincam_sim.scene.display import Screen

LAMP_M = (1.1, 0.62)  # the lamp's width and height [m], centred on the origin of the floor, emitting up
CARD_M = (0.10, 0.05)  # the card's width and height [m]
CARD_Z_M = 0.25  # the card's height over the floor [m]
RADIANCE = 3.0  # the lamp's radiance [W m^-2 sr^-1]


def _mixel() -> Mixel:
    return Mixel(masks.constant(1.0), pose=Pose((0.0, 0.0, 0.5), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)), name="open")


CAM = Mincam((_mixel(),))


def _scene_xml(unit_m: float = 0.01, card_x_m: float = 0.0, depth: int | None = 2, sensor: bool = True,
               card_id: str | None = "card", extra: str = "") -> str:
    """The lamp (a white diffuse emitting rectangle on the floor) and a white card facing it, 25 cm up, in units
    of ``unit_m``; the lamp's radiance is the parameter ``lamp``, the card's x the parameter ``card_x``."""
    u = 1.0 / unit_m
    integrator = "" if depth is None else (
        f'<default name="depth" value="{depth}"/>\n'
        '<integrator type="path"><integer name="max_depth" value="$depth"/></integrator>')
    camera = ('<sensor type="perspective"><film type="hdrfilm"><integer name="width" value="4"/>'
              '<integer name="height" value="4"/></film></sensor>') if sensor else ""
    ident = f' id="{card_id}"' if card_id else ""
    return f"""<scene version="3.0.0">
    <default name="lamp" value="{RADIANCE}"/>
    <default name="card_x" value="{card_x_m * u!r}"/>
    <default name="card_z" value="{CARD_Z_M * u!r}"/>
    {integrator}
    {camera}
    <shape type="rectangle" id="lamp">
        <transform name="to_world"><scale x="{LAMP_M[0] / 2 * u!r}" y="{LAMP_M[1] / 2 * u!r}"/></transform>
        <bsdf type="diffuse"><spectrum name="reflectance" value="0.8"/></bsdf>
        <emitter type="area"><spectrum name="radiance" value="$lamp"/></emitter>
    </shape>
    <shape type="rectangle"{ident}>
        <transform name="to_world">
            <scale x="{CARD_M[0] / 2 * u!r}" y="{CARD_M[1] / 2 * u!r}"/>
            <rotate x="1" angle="180"/>
            <translate x="$card_x" z="$card_z"/>
        </transform>
        <bsdf type="diffuse"><spectrum name="reflectance" value="0.8"/></bsdf>
    </shape>
    {extra}
</scene>
"""


def _write(tmp_path, name: str = "box.xml", **kw):
    path = tmp_path / name
    path.write_text(_scene_xml(**kw))
    return path


def _card_corners(x_m: float, z_m: float) -> np.ndarray:
    """The card as a flat box: its 8 corners (two coincident layers) [m]."""
    hw, hh = CARD_M[0] / 2, CARD_M[1] / 2
    return np.array([[x_m + sx * hw, sy * hh, z_m] for sx in (-1, 1) for sy in (-1, 1) for _ in (0, 1)])


def _oracle(card_x_m: float | None, card_z_m: float = CARD_Z_M) -> float:
    """Direct irradiance [W/m^2] of the open mixel from the lamp, the card (if any) in the way."""
    lamp = Screen(LAMP_M[0], LAMP_M[1], (16, 9), Pose((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0)))
    occluders = [] if card_x_m is None else [_card_corners(card_x_m, card_z_m)]
    return open_aperture_view_factor_irradiance(_mixel(), lamp, RADIANCE, occluders, n_detector=16)


def _measure(sim: ms.Simulation, spp: int = 1 << 17, seed: int = 1):
    m = sim.measure([{}], budget=ms.Budget(spp=spp, seed=seed, replicates=16))
    return m.irradiance_w_m2[0, 0], m.stderr_w_m2[0, 0], m


# ---------------------------------------------------------------------------------------------- parameters
def test_parameters_switch_the_lamp_off_and_are_part_of_the_identity(tmp_path):
    """``parameters={"lamp": 0}`` sets the file's ``<default>`` through Mitsuba's loader: the only light is off,
    every ray reads exactly 0. The parameters are in the identity; unknown names and parameters without a file are
    one clear error."""
    path = _write(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", WorldWarning)
        on = ms.Simulation(CAM, world=path)
        off = ms.Simulation(CAM, world=path, parameters={"lamp": 0})
    p_on, s_on, _ = _measure(on, spp=1 << 12)
    p_off, s_off, _ = _measure(off, spp=1 << 12)
    assert p_on > 10 * s_on > 0
    assert p_off == 0.0 and s_off == 0.0
    assert off.identity()["parameters"] == {"lamp": "0"} and "parameters" not in on.identity()
    assert off.identity()["scene"] != on.identity()["scene"]
    with pytest.raises(InputError, match=r"\['lmp'\] are not parameters of box.xml.*card_x, card_z, depth, lamp"):
        ms.Simulation(CAM, world=path, parameters={"lmp": 0})
    with pytest.raises(InputError, match="parameters set a scene file's <default> values"):
        ms.Simulation(CAM, world={"lamp": sd.sky(1.0)}, parameters={"lamp": 0})
    with pytest.raises(InputError, match=r"parameters\['lamp'\]"):
        ms.Simulation(CAM, world=path, parameters={"lamp": object()})


def test_a_mesh_named_through_a_parameter_is_part_of_the_identity(tmp_path):
    """A mesh chosen by ``parameters`` is hashed by content: editing it makes another identity (it was shown again
    as 'this same run')."""
    for name, z in (("a.obj", 0.02), ("b.obj", 0.03)):
        box = trimesh.creation.box((0.04, 0.04, 0.04))
        box.apply_translation((0.3, 0.0, z))
        box.export(tmp_path / name)
    extra = ('<default name="mesh" value="a.obj"/>'
             '<shape type="obj" id="toy"><string name="filename" value="$mesh"/></shape>')
    path = _write(tmp_path, extra=extra)

    def identity(**kw):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", WorldWarning)
            return ms.Simulation(CAM, world=path, **kw).identity()

    a, b = identity(), identity(parameters={"mesh": "b.obj"})
    assert "b.obj" in b["files"] and "b.obj" not in a["files"]
    box = trimesh.creation.box((0.05, 0.04, 0.04))
    box.apply_translation((0.3, 0.0, 0.03))
    box.export(tmp_path / "b.obj")
    edited = identity(parameters={"mesh": "b.obj"})
    assert edited["files"]["b.obj"] != b["files"]["b.obj"] and edited["scene"] != b["scene"]


# ------------------------------------------------------------------------------- units, depth, the file's own
def test_a_cm_file_with_unit_m_matches_the_view_factor_oracle_and_its_metre_twin(tmp_path):
    """The lamp and the card modelled in cm, read with ``unit_m=0.01``, against the quadrature oracle and against
    the same file written in metres. Read as metres it is 100 x too large: one warning says so."""
    cm, metres = _write(tmp_path, "cm.xml", unit_m=0.01), _write(tmp_path, "m.xml", unit_m=1.0)
    expected = _oracle(0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", WorldWarning)
        warnings.filterwarnings("ignore", "the scene's own sensor", WorldWarning)
        in_cm = ms.Simulation(CAM, world=cm, unit_m=0.01)
        in_m = ms.Simulation(CAM, world=metres)
    a, sa, _ = _measure(in_cm, seed=1)
    b, sb, _ = _measure(in_m, seed=2)
    assert sa / a < 3e-3
    assert_close_mc(a, expected, sa, what="cm file with unit_m against the view-factor oracle")
    assert_close_mc(b, expected, sb, what="metre file against the view-factor oracle")
    assert_close_mc(a, b, np.hypot(sa, sb), what="cm file with unit_m against its metre twin")
    in_plane = [0, 1, 3]  # a rectangle's size and place (its local z, the normal, is scaled with the rest)
    np.testing.assert_allclose(in_cm.params["card.to_world"][:, in_plane], in_m.params["card.to_world"][:, in_plane],
                               atol=1e-6)
    assert in_cm.identity()["unit_m"] == 0.01
    with pytest.warns(WorldWarning, match=r"unit_m = 0.01"):
        ms.Simulation(CAM, world=cm)
    with pytest.raises(InputError, match="unit_m"):
        ms.Simulation(CAM, world=cm, unit_m=0.0)


def test_the_files_integrator_depth_is_used_when_none_is_given(tmp_path):
    """The file's ``<integrator>`` says ``max_depth`` 2: direct light only. The lamp is white and a white ceiling
    hangs behind the mincam, so a third segment adds the ceiling's light the lamp reflects: at max_depth 3 P rises
    by many sigma, while the file's depth gives the oracle of direct light (the card moved to 10 cm by a
    parameter), the same numbers as max_depth=2 given, and the meta says where the depth came from. The file's
    camera is ignored with one warning."""
    panel = ('<shape type="rectangle"><transform name="to_world"><scale value="100"/><rotate x="1" angle="180"/>'
             '<translate z="60"/></transform><bsdf type="diffuse"><spectrum name="reflectance" value="0.8"/></bsdf>'
             '</shape>')  # a white ceiling behind the mincam: the lamp reflects the light it sends back
    path = _write(tmp_path, extra=panel)
    low = {"card_z": 10.0}
    with pytest.warns(WorldWarning, match="sensor") as said:
        from_file = ms.Simulation(CAM, world=path, unit_m=0.01, parameters=low)
    assert len([w for w in said if issubclass(w.category, WorldWarning)]) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", WorldWarning)
        given = ms.Simulation(CAM, world=path, unit_m=0.01, max_depth=2, parameters=low)
        deeper = ms.Simulation(CAM, world=path, unit_m=0.01, max_depth=3, parameters=low)
        no_integrator = ms.Simulation(CAM, world=_write(tmp_path, "plain.xml", depth=None), unit_m=0.01)
    assert from_file.max_depth_source == "the <integrator> of box.xml" and given.max_depth_source == "given"
    assert no_integrator.mincam_scene.max_depth == 3 and no_integrator.max_depth_source.startswith("default")
    a, sa, m = _measure(from_file, seed=3)
    b, _, _ = _measure(given, seed=3)
    c, sc, _ = _measure(deeper, seed=4)
    assert a == b
    assert m.meta["max_depth"] == 2 and m.meta["max_depth_from"] == "the <integrator> of box.xml"
    assert_close_mc(a, _oracle(0.0, 0.1), sa, what="the file's max_depth 2 against direct light")
    assert (c - a) > 10 * np.hypot(sa, sc), "a third segment adds the card's reflected light"
    with pytest.raises(InputError, match="max_depth 1"):
        ms.Simulation(CAM, world=path, parameters={"depth": 1})


def test_a_loaded_scene_is_a_world_and_shapes_without_an_id_are_static(tmp_path):
    """``world=mi.Scene`` (documented, refused as 'elements must be a dict'); a card without an id is kept as
    static geometry and shadows the lamp as the oracle says."""
    mi = backend.mitsuba()
    scene = mi.load_file(str(_write(tmp_path, card_id=None, unit_m=1.0, sensor=False)), optimize=False)
    sim = ms.Simulation(CAM, world=scene)
    assert "card.to_world" not in sim.params and "scene_shape1.to_world" in sim.params
    again = mi.load_file(str(tmp_path / "box.xml"), optimize=False)
    assert sim.movable() == ["lamp"] == ms.Simulation(CAM, world=again).movable()  # static, also when loaded again
    # the same loaded scene again: its shapes lie in the first simulation's coordinates (their params read the
    # lamp 0.5 m low, and the next rebuild of either scene placed it there)
    with pytest.raises(InputError, match="element 'lamp' is a Mitsuba object that an earlier Simulation took"):
        ms.Simulation(CAM, world=scene)
    assert sim.max_depth_source == "the integrator of the loaded scene 'scene'"
    p, s, _ = _measure(sim, seed=5)
    assert_close_mc(p, _oracle(0.0), s, what="a card without an id, static")
    with pytest.raises(InputError, match="world must be a dict of elements, a loaded mitsuba Scene or the path"):
        ms.Simulation(CAM, world=3)


# ------------------------------------------------------------------------------------------------- movers
def test_a_moved_card_gives_the_view_factor_difference(tmp_path):
    """A rectangle moved by its ``to_world`` (it was refused as 'the transform is singular'), against a background
    without it (:meth:`Simulation.without`): dP = -(the lamp's light the card hides), from the oracle, at two
    places; the difference of the two dP is the view-factor difference."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", WorldWarning)
        sim = ms.Simulation(CAM, world=_write(tmp_path), unit_m=0.01)
    m0 = sim.params["card.to_world"]
    xs = (0.0, 0.08)
    frames = []
    for x in xs:
        m = m0.copy()
        m[0, 3] = x
        frames.append({"card.to_world": m})
    background = sim.without("card")
    assert set(background) == {"card.to_world"}
    ch = sim.measure_changes(frames, background, budget=ms.Budget(spp=1 << 16, seed=2, replicates=16))
    dp, sigma = ch.dp.irradiance_w_m2[:, 0], ch.dp.stderr_w_m2[:, 0]
    bare = _oracle(None)
    expected = np.array([_oracle(x) - bare for x in xs])
    assert np.all(expected < -0.01 * bare) and np.all(sigma < 0.05 * np.abs(expected))
    assert_close_mc(dp, expected, sigma, what="a moved card's dP against the view factors")
    assert_close_mc(dp[1] - dp[0], expected[1] - expected[0], np.hypot(*sigma), what="dP difference")
    bg = np.asarray(ch.p.meta["background_w_m2"])[0]
    assert_close_mc(bg, bare, float(np.asarray(ch.p.meta["background_stderr_w_m2"])[0]), what="background")


def test_lights_move_and_are_taken_out(tmp_path):
    """The lamp (an emitting rectangle) and a point light taken out by :meth:`Simulation.without` leave the sky
    alone: P as the view-factor oracle of the sky through the aperture, the card in the way. A moved point light
    is a change; the movable names leave out the camera and the environment."""
    sky = 0.1
    extra = ('<emitter type="point" id="bulb"><point name="position" x="0" y="20" z="30"/>'
             '<spectrum name="intensity" value="0.5"/></emitter>'
             f'<emitter type="constant" id="sky"><spectrum name="radiance" value="{sky}"/></emitter>')
    camera = sd.pinhole_camera(Pose((0.0, -1.0, 1.0), (0.0, 1.0, -1.0)).matrix(), 40.0, 8, 6, spp=4)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", WorldWarning)
        sim = ms.Simulation(CAM, world=_write(tmp_path, extra=extra), unit_m=0.01, camera=camera)
    assert sim.movable() == ["bulb", "card", "lamp"]
    out = sim.without("lamp", "bulb")
    assert set(out) == {"lamp.to_world", "lamp.emitter.radiance.value", "bulb.intensity.value"}
    np.testing.assert_allclose(sim.params["bulb.position"], [0.0, 0.2, 0.3], atol=1e-6)
    with pytest.raises(InputError, match="'sky' is not a shape or light of the scene that can move; movable: bulb"):
        sim.without("sky")
    p, s, _ = _measure_after(sim, out)
    ground = Screen(2.0, 2.0, (16, 16), Pose((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0)))
    expected = open_aperture_view_factor_irradiance(_mixel(), ground, sky, [_card_corners(0.0, CARD_Z_M)],
                                                    n_detector=16)
    assert_close_mc(p, expected, s, what="lamp and point light taken out: the sky alone")
    moved = {"bulb.position": np.array([0.05, 0.0, 0.3]), "bulb.intensity.value": sim.params["bulb.intensity.value"]}
    ch = sim.measure_changes([moved], sim.without("bulb"), ms.PlainChange(), ms.Budget(spp=1 << 12, seed=1))
    assert np.all(ch.dp.irradiance_w_m2 > 5 * ch.dp.stderr_w_m2)


class _StopAfterFirstRow(MemorySink):
    """A sink whose table stops the run (as Ctrl-C would) when the first row arrives."""

    def open(self, n_frames, columns):
        table = super().open(n_frames, columns)

        def write(indices, values, stderr):
            raise KeyboardInterrupt

        table.write = write
        return table


def test_a_run_leaves_the_world_as_it_found_it(tmp_path):
    """A change run's background and frames are its own: after a run against a background without the card, or
    without the lamp, and after a run stopped on its first frame, the next run measures the world as the caller
    left it, the same numbers bit for bit (the card stayed taken out, the lamp stayed dark: every later run read
    0 or the scene without the card). What the caller sets with ``update`` stays."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", WorldWarning)
        sim = ms.Simulation(CAM, world=_write(tmp_path), unit_m=0.01)
    budget = ms.Budget(spp=1 << 12, seed=3, replicates=8)
    as_built = sim.measure([{}], budget=budget).irradiance_w_m2
    moved = sim.params["card.to_world"].copy()
    moved[0, 3] += 0.04
    frames = [{"card.to_world": moved}, {"card.to_world": sim.params["card.to_world"]}]
    card = sim.params["card.to_world"]
    dp = sim.measure_changes(frames, sim.without("card"), ms.PlainChange(), budget).dp.irradiance_w_m2
    assert np.all(dp < 0)
    np.testing.assert_array_equal(sim.params["card.to_world"], card)
    np.testing.assert_array_equal(sim.measure([{}], budget=budget).irradiance_w_m2, as_built)
    sim.measure_changes(frames, sim.without("lamp"), ms.PlainChange(), budget)
    np.testing.assert_array_equal(sim.measure([{}], budget=budget).irradiance_w_m2, as_built)
    with pytest.raises(KeyboardInterrupt):
        sim.measure_changes(frames, sim.without("card"), ms.PlainChange(), budget, sink=_StopAfterFirstRow())
    np.testing.assert_array_equal(sim.measure([{}], budget=budget).irradiance_w_m2, as_built)
    sim.update(sim.without("lamp"))  # the caller's own change stays through runs
    sim.measure_changes(frames, {}, ms.PlainChange(), budget)
    assert np.all(sim.measure([{}], budget=budget).irradiance_w_m2 == 0.0)


def _measure_after(sim: ms.Simulation, update: dict):
    m = sim.measure([update], budget=ms.Budget(spp=1 << 17, seed=7, replicates=16))
    return m.irradiance_w_m2[0, 0], m.stderr_w_m2[0, 0], m


def _placed(x_m: float, y_m: float, z_m: float, size_m: float):
    return sd._transform(np.array([[size_m, 0, 0, x_m], [0, size_m, 0, y_m], [0, 0, size_m, z_m], [0, 0, 0, 1.0]]))


SHAPES = {"disk": {"type": "disk", "to_world": _placed(0.05, 0.0, 0.2, 0.04)},
          "sphere": {"type": "sphere", "to_world": _placed(-0.05, 0.02, 0.15, 0.03)},
          "cube": {"type": "cube", "to_world": _placed(0.0, -0.06, 0.1, 0.02)},
          "spot": sd.spot_light(Pose((0.0, 0.1, 0.4), (0.0, 0.0, -1.0)).matrix(), 2.0, 25.0)}


@pytest.mark.parametrize("kind", list(SHAPES))
def test_taking_a_shape_or_light_out_equals_the_scene_without_it(kind):
    """Disks, spheres and cubes shrink to a 1 um speck by their ``to_world`` (accepted: the transform is
    invertible), a spot light's intensity goes to 0: P then equals P of the same scene built without it."""
    grey = {"type": "diffuse", "reflectance": {"type": "spectrum", "value": 0.6}}
    lamp = dict(sd.area_light(LAMP_M[0], LAMP_M[1], np.eye(4), RADIANCE), bsdf=grey)  # the spot lights it too
    element = dict(SHAPES[kind], **({} if kind == "spot" else {"bsdf": grey}))
    with_it = ms.Simulation(CAM, world={"lamp": lamp, kind: element})
    without = ms.Simulation(CAM, world={"lamp": lamp})
    assert with_it.movable() == sorted(["lamp", kind])
    out = with_it.without(kind)
    with_it.update(out)
    a, sa, _ = _measure(with_it, spp=1 << 16, seed=8)
    b, sb, _ = _measure(without, spp=1 << 16, seed=9)
    assert_close_mc(a, b, np.hypot(sa, sb), what=f"{kind} taken out against the scene without it")
    with_it.update({key: with_it.complete_background([out], {})[key] for key in out})  # back as built
    c, sc, _ = _measure(with_it, spp=1 << 16, seed=8)
    assert abs(c - a) > 5 * np.hypot(sa, sc), f"the {kind} changes the view as built"


# ---------------------------------------------------------------------------------------- silent answers
def test_a_world_without_light_is_refused_when_measured():
    """An empty world gave 0 +- 0 without a word (and crashed in Dr.Jit for changes)."""
    sim = ms.Simulation(CAM, world={})
    for measure in (lambda: sim.measure([{}], ms.Aperture()), lambda: sim.measure_changes([{}], {})):
        with pytest.raises(InputError, match="the world holds no light"):
            measure()


def test_a_mincam_inside_a_shape_is_said(tmp_path):
    """A closed box around the rig (one-sided diffuse faces, normals out): the mixel sees only their backs, black.
    One warning names the shape; the same box beside the rig says nothing."""
    box = trimesh.creation.box((0.3, 0.3, 0.3))
    lamp = sd.area_light(0.2, 0.2, Pose((0.0, 0.0, 1.0), (0.0, 0.0, -1.0)).matrix(), 1.0)
    for centre, inside in (((0.0, 0.0, 0.5), True), ((1.0, 0.0, 0.5), False)):
        wall = sd.mesh_object("wall", np.asarray(box.vertices) + centre, np.asarray(box.faces), 0.5)
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            ms.Simulation(CAM, world={"wall": wall, "lamp": lamp})
        told = [str(w.message) for w in said if issubclass(w.category, WorldWarning)]
        assert told == (["the mincam is inside a shape (open inside 'wall'): its mixels see the back of one-sided "
                         "faces, which are black; move the mincam out of the shape (or give the shape a two-sided "
                         "material)"] if inside else [])


def test_a_mesh_without_triangles_is_refused_naming_it(tmp_path):
    """An OBJ with vertices and no faces, loaded with face normals, failed in a Dr.Jit gather (a traceback)."""
    (tmp_path / "empty.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    lamp = sd.area_light(0.2, 0.2, Pose((0.0, 0.0, 1.0), (0.0, 0.0, -1.0)).matrix(), 1.0)
    toy = {"type": "obj", "filename": str(tmp_path / "empty.obj"), "face_normals": True}
    with pytest.raises(InputError, match=r"^shape 'toy': a mesh without a single triangle .* give it faces"):
        ms.Simulation(CAM, world={"toy": toy, "lamp": lamp})


@pytest.mark.parametrize("distance_m, outcome, grid", [
    (1_000.0, "nothing", ""), (5_000.0, "warning", "0.49 mm"), (20_000.0, "refusal", "2 mm"),
    (100_000.0, "refusal", "7.8 mm")])
def test_a_mincam_far_from_the_origin_is_warned_then_refused(distance_m, outcome, grid):
    """Mitsuba loads coordinates as 32-bit floats: a tilted pair 100 km out read 10-13 sigma low, 1000 km 2x, with
    no word. 1.2 km reads what the origin reads (test_far_geometry); beyond 4 km a warning, 16 km a refusal that
    names the distance, the grid and the fix. A sky alone has nothing to misplace and is taken anywhere."""
    shift = np.array([distance_m, -700.0, 0.0])
    cam = ms.pair_layout(center=Pose(tuple(shift + [0.0, 0.0, 0.4]), (0.2, 0.1, -1.0), (0.0, 1.0, 0.3)))
    floor = sd.mesh_object("floor", np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]) + shift,
                           np.array([[0, 1, 2], [0, 2, 3]]), 0.5)
    lamp = sd.area_light(0.2, 0.2, Pose(tuple(shift + [0.0, 0.0, 1.0]), (0.0, 0.0, -1.0)).matrix(), 1.0)
    where = (f"the mincam sits {distance_m:g} m from the scene's origin, where the 32-bit floats Mitsuba loads a "
             f"scene in place its points on a {grid} grid")
    fix = ("move the scene's origin near the mincam (subtract a local origin from the file's or the elements' "
           "coordinates and from the mincam's position; within 4,096 m of it the grid is 0.24 mm or finer)")
    with warnings.catch_warnings(record=True) as told:
        warnings.simplefilter("always")
        if outcome == "refusal":
            with pytest.raises(InputError) as refused:
                ms.Simulation(cam, world={"floor": floor, "lamp": lamp})
            assert str(refused.value) == (f"{where}: the shapes near it are not where they were put and every "
                                          f"reading would be off (at 100 km by 10-15 %); {fix}")
        else:
            ms.Simulation(cam, world={"floor": floor, "lamp": lamp})
        ms.Simulation(cam, world={"sky": sd.sky(1.0)})
    far = [str(w.message) for w in told if "scene's origin" in str(w.message)]
    assert far == ([f"{where}: readings may be off by a little; {fix}"] if outcome == "warning" else [])


def test_toml_parameters_unit_and_movers(tmp_path):
    """``[world.parameters]``, ``[world] unit_m`` (the file's unit; the config's own lights stay in metres) and a
    rectangle and a point light as ``[[world.mover]]``s from a config; the background without movers takes both
    out (and switches the light on again in every frame). The card's dP agrees with the oracle (the bulb, under
    the one-sided lamp and card, lights only their black backs)."""
    from mincam_sim.configuration.world_config import load_world_config
    from mincam_sim.runs.jobs import run_world_config, world_job

    extra = ('<emitter type="point" id="bulb"><point name="position" x="0" y="20" z="-30"/>'
             '<spectrum name="intensity" value="0.5"/></emitter>')
    _write(tmp_path, extra=extra)
    text = """[run]
solver = "plain_change"
spp = 8192
replicates = 8
out_dir = "out"
[mincam]
layout = "custom"
[[mixel]]
name = "open"
mask = "constant:1.0"
position_m = [0.0, 0.0, 0.5]
forward = [0.0, 0.0, -1.0]
[world]
scene = "box.xml"
unit_m = 0.01
[world.parameters]
card_x = 3.0
[[world.light]]
id = "dim"
kind = "point"
position_m = [0.0, 0.2, 0.3]
intensity_w_sr = 0.0
[[world.mover]]
id = "card"
offsets_m = [[-0.03, 0.0, 0.0], [0.05, 0.0, 0.0]]
[[world.mover]]
id = "bulb"
offsets_m = [[0.0, 0.0, 0.0], [0.0, 0.01, 0.0]]
"""
    (tmp_path / "c.toml").write_text(text)
    cfg = load_world_config(tmp_path / "c.toml")
    assert cfg.parameters == {"card_x": "3.0"} and cfg.unit_m == 0.01 and cfg.run.max_depth is None
    mixel, ours = cfg.mincam[0], _mixel()
    np.testing.assert_allclose(mixel.pose.position_m, ours.pose.position_m, atol=1e-12)
    assert (mixel.d_f_m, mixel.detector_size_m, mixel.mask.width_m) == (ours.d_f_m, ours.detector_size_m,
                                                                        ours.mask.width_m)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", WorldWarning)
        job = world_job(cfg)  # the file in cm, the config's light in metres
        np.testing.assert_allclose(job.sim.params["card.to_world"][:3, 3], [0.03, 0.0, 0.25], atol=1e-6)
        np.testing.assert_allclose(job.sim.params["dim.position"], [0.0, 0.2, 0.3], atol=1e-6)
        assert set(job.background) == {"card.to_world", "bulb.intensity.value"}
        np.testing.assert_allclose(job.frames[1]["bulb.position"], [0.0, 0.21, -0.3], atol=1e-6)
        assert all(f["bulb.intensity.value"] == 0.5 for f in job.frames)  # on in the frames, off in the background
        ch = run_world_config(cfg)
    expected = np.array([_oracle(0.0), _oracle(0.08)]) - _oracle(None)
    assert_close_mc(ch.dp.irradiance_w_m2[:, 0], expected, ch.dp.stderr_w_m2[:, 0], what="TOML card mover")
    assert ch.p.meta["max_depth_from"] == "the <integrator> of box.xml"
    np.testing.assert_allclose(ch.frame_columns["card_centre_x_m"], [0.0, 0.08], atol=1e-6)
    bad = text.replace('id = "bulb"', 'id = "sky"')
    (tmp_path / "c.toml").write_text(bad.replace("[world.parameters]", "[world.parameters]\nlmp = 1"))
    with pytest.raises(InputError, match="lmp"):
        run_world_config(load_world_config(tmp_path / "c.toml"), overwrite=True)
    (tmp_path / "c.toml").write_text(bad)
    with pytest.raises(ConfigError, match="'sky' is not a shape or light of the scene that can move; movable: "
                                          "bulb, card, dim, lamp$"):
        run_world_config(load_world_config(tmp_path / "c.toml"), overwrite=True)


def test_an_undefined_change_centroid_is_said():
    """A change below the threshold has no pixel above it and its centroid is NaN: one warning says why and what
    to lower (it was NaN without a word)."""
    from mincam_sim.runs.jobs import _warn_undefined_centroids

    bg = np.zeros((4, 6))
    bg[0, 0] = 100.0
    dim, unchanged = bg.copy(), bg.copy()
    dim[2, 3] += 1.0  # below 0.05 x 100
    with pytest.warns(UserWarning, match=r"undefined \(NaN\) in 1 of 2 frames .*no light in view \(100 W m\^-2 sr"):
        _warn_undefined_centroids([dim, unchanged], bg, np.array([np.nan, np.nan]), 0.05, 100.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _warn_undefined_centroids([dim], bg, np.array([2.0]), 0.05, 100.0)


def test_the_change_centroid_is_defined_with_a_lamp_in_view(tmp_path):
    """A lamp in the camera's view (20 W m^-2 sr^-1, 400 times the lit floor) no longer sets the threshold: the
    pixels whose centre ray meets a light are left out of the brightest pixel, so a card moving over the floor
    has a centroid (it was NaN: every change lay below 0.05 x the lamp), on the card's side of the image."""
    from mincam_sim.configuration.world_config import CameraSpec
    from mincam_sim.render.scene.world_checks import light_pixels
    from mincam_sim.runs.jobs import _camera_dict, _ground_truth

    grey = {"type": "diffuse", "reflectance": {"type": "spectrum", "value": 0.5}}
    card = ms.Pose((0.15, 0.0, 0.3), (0.0, 0.0, 1.0)).matrix() @ np.diag([0.05, 0.05, 1.0, 1.0])
    world = {"floor": {"type": "rectangle", "to_world": sd._transform(np.diag([0.6, 0.6, 1.0, 1.0])), "bsdf": grey},
             "overhead": sd.area_light(0.3, 0.3, ms.Pose((0.0, 0.0, 1.2), (0.0, 0.0, -1.0)).matrix(), 5.0),
             "bulb": sd.area_light(0.1, 0.1, ms.Pose((-0.2, 0.0, 0.001), (0.0, 0.0, 1.0)).matrix(), 20.0),
             "card": {"type": "rectangle", "to_world": sd._transform(card), "bsdf": grey}}
    spec = CameraSpec((0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 60.0, 32, 32, 16, 0.05)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", WorldWarning)
        sim = ms.Simulation(CAM, world=world, camera=_camera_dict(spec))
    lights = light_pixels(sim.scene, sim.camera)
    bulb_col = np.nonzero(lights)[1].mean() - 15.5  # the bulb's side of the image (x = -0.2 m)
    assert 1 <= lights.sum() <= 40 and abs(bulb_col) > 5
    moved = np.array(sim.params["card.to_world"])
    moved[1, 3] += 0.05
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        rows, cols = _ground_truth(sim, spec, [{"card.to_world": moved}], sim.without("card"), tmp_path)
    bg = np.load(tmp_path / "camera.npz")["background"]
    frame = np.load(tmp_path / "camera.npz")["frames"][0]
    assert np.abs(frame - bg).max() < 0.05 * bg.max(), "the old rule (x the lamp) detected nothing"
    assert np.all(np.isfinite(rows)) and np.all(np.isfinite(cols))
    # the card (x = 0.15 m, 0.7 m from the camera) and its shadow (x = 0.2 m on the floor) are ~6 px from the
    # centre, on the other side from the bulb
    assert 3 < -np.sign(bulb_col) * (cols[0] - 15.5) < 9 and abs(rows[0] - 15.5) < 5, (rows, cols)
