"""A moving shape that closes round the mincam in the middle of a run: the mixel sees the back of its one-sided
faces (black) and reads 0, a change dP = -P. Only the world as built was checked; every run now watches the shapes
its frames move and says the first such frame once, naming the shape, the frame and the mixel."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh

import mincam_sim as ms
from mincam_sim import Pose
from mincam_sim.render import backend
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.world_checks import EngulfedWarning

pytestmark = pytest.mark.skipif(not backend.is_jit(), reason="needs a JIT variant (LLVM or CUDA)")

BOX = trimesh.creation.box((0.3, 0.3, 0.3))
PARKED = np.asarray(BOX.vertices) + (1.0, 0.0, 0.5)  # beside the mixel, which sits at (0, 0, 0.5)
BUDGET = ms.Budget(spp=1 << 10, replicates=4)


def _world() -> ms.Simulation:
    cam = ms.single(pose=Pose((0.0, 0.0, 0.5), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)))
    lamp = sd.area_light(0.4, 0.4, Pose((0.0, 0.0, 1.0), (0.0, 0.0, -1.0)).matrix(), 5.0)
    floor = sd.textured_plane(np.full((4, 4), 0.5), 1.0, 1.0, Pose((0, 0, 0), (0, 0, 1)).matrix())
    box = sd.mesh_object("box", PARKED, np.asarray(BOX.faces), 0.5)
    return ms.Simulation(cam, world={"box": box, "lamp": lamp, "floor": floor})


def _at(dx_m: float) -> dict:
    return {"box.vertex_positions": (PARKED + (dx_m, 0.0, 0.0)).astype(np.float32).ravel()}


def _said(run) -> tuple[object, list[str]]:
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        result = run()
    return result, [str(w.message) for w in said if issubclass(w.category, EngulfedWarning)]


RUNS = {
    "aperture": lambda sim, frames, bg: sim.measure(frames, ms.Aperture(), BUDGET),
    "plain": lambda sim, frames, bg: sim.measure_changes(frames, bg, ms.PlainChange(), BUDGET),
    "stratified": lambda sim, frames, bg: sim.measure_changes(frames, bg, ms.StratifiedChange(), BUDGET),
    "stratified_split": lambda sim, frames, bg: sim.measure_changes(frames, bg, ms.StratifiedChange(), BUDGET),
}


@pytest.mark.parametrize("solver", sorted(RUNS))
def test_a_mover_that_closes_round_the_mincam_is_said_once(solver):
    """The box passes over the mixel in frame 2 (of 4; again in frame 3 at the edge): the mixel reads 0 there,
    and one EngulfedWarning names the box, frame 2 and the mixel (the split run checks the movers' copies). The
    same box passing beside the mixel in the next run says nothing."""
    sim = _world()
    if solver == "stratified_split":
        sim.split_static, sim.freeze_launches = True, False  # the split; no recordings for 4 frames
    result, told = _said(lambda: RUNS[solver](sim, [_at(dx) for dx in (0.0, -0.5, -1.0, -0.95)], _at(0.0)))
    p = result if solver == "aperture" else result.p
    assert abs(p.irradiance_w_m2[2, 0]) < 0.01 * p.irradiance_w_m2[0, 0]
    assert told == ["the moving shape 'box' closes round mixel(s) m0 in frame 2 (the first place of this run where a "
                    "moved shape does; later frames are not checked): they see only the back of its one-sided faces, "
                    "which are black, so they read about 0 there (a change measured there is off by the whole P), "
                    "though the scene did not go dark; move the shape's path clear of the mincam, or give the shape "
                    "a two-sided material"]
    if solver == "stratified_split":
        assert "split" in result.dp.meta["static_geometry"]
    _, told = _said(lambda: RUNS[solver](sim, [_at(dx) for dx in (0.0, -0.5, -0.8)], _at(0.0)))
    assert told == []


def test_a_background_that_closes_round_the_mincam_is_said():
    """A change run whose background holds the box round the mixel: said as 'the background'."""
    _, told = _said(lambda: _world().measure_changes([_at(0.0)], _at(-1.0), ms.PlainChange(), BUDGET))
    assert len(told) == 1 and "closes round mixel(s) m0 in the background" in told[0]


def test_a_world_aperture_run_that_reaches_nothing_lit_says_so():
    """The world ``Aperture`` solver returned 0 +/- 0 without a word where the mixel saw nothing lit (the display
    solvers and the change solvers warned): one UnseenWarning, as theirs."""
    from mincam_sim.render.kernels.monte_carlo import UnseenWarning

    cam = ms.single(pose=Pose((0.0, 0.0, 0.5), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)))  # looking down at no floor
    lamp = sd.area_light(0.4, 0.4, Pose((0.0, 0.0, 1.0), (0.0, 0.0, -1.0)).matrix(), 5.0)
    sim = ms.Simulation(cam, world={"lamp": lamp})
    with pytest.warns(UnseenWarning, match="no sample of mixel"):
        m = sim.measure([{}], ms.Aperture(), BUDGET)
    assert m.irradiance_w_m2[0, 0] == 0 and m.stderr_w_m2[0, 0] == 0


def _instanced_world(tmp_path, placed_m) -> ms.Simulation:
    """The world of ``_world`` with the box drawn by an instance of a shape group (placed at ``placed_m``)."""
    BOX.export(tmp_path / "box.ply")
    group = {"type": "shapegroup", "b": {"type": "ply", "filename": str(tmp_path / "box.ply"),
                                         "bsdf": {"type": "diffuse"}}}
    cam = ms.single(pose=Pose((0.0, 0.0, 0.5), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)))
    lamp = sd.area_light(0.4, 0.4, Pose((0.0, 0.0, 1.0), (0.0, 0.0, -1.0)).matrix(), 5.0)
    floor = sd.textured_plane(np.full((4, 4), 0.5), 1.0, 1.0, Pose((0, 0, 0), (0, 0, 1)).matrix())
    box = {"type": "instance", "group": {"type": "ref", "id": "grp"}, "to_world": sd._transform(_placed(placed_m))}
    return ms.Simulation(cam, world={"grp": group, "box": box, "lamp": lamp, "floor": floor})


def _placed(centre_m) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, 3] = centre_m
    return matrix


@pytest.mark.parametrize("solver", ["aperture", "stratified"])
def test_an_instance_that_closes_round_the_mincam_is_said(tmp_path, solver):
    """The box drawn through an ``instance`` passes over the mixel in frame 1: the mixel read 0 there (0.0 +- 0
    from the aperture solver, -0.0002 from the stratified one) without a word, the instance's own stand-in BSDF
    and the group's shapes, met through it, being missed. Now one EngulfedWarning names the instance."""
    sim = _instanced_world(tmp_path, (1.0, 0.0, 0.5))
    frames = [{"box.to_world": _placed(centre)} for centre in ((1.0, 0.0, 0.5), (0.0, 0.0, 0.5))]
    result, told = _said(lambda: RUNS[solver](sim, frames, {}))
    p = result if solver == "aperture" else result.p
    assert abs(p.irradiance_w_m2[1, 0]) < 0.01 * p.irradiance_w_m2[0, 0]
    assert len(told) == 1 and "the moving shape 'box' closes round mixel(s) m0 in frame 1 " in told[0]


def test_a_mincam_built_inside_an_instance_is_said(tmp_path):
    """The world as built with the mixel inside the instanced box: said as for a mesh (it was silent)."""
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        _instanced_world(tmp_path, (0.0, 0.0, 0.5))
    told = [str(w.message) for w in said]
    assert any("the mincam is inside a shape (m0 inside 'box')" in message for message in told), told


# a 1 cm block through one corner of the mask (the mask spans +-1 mm at z = 0.498 m, the detector at z = 0.5 m),
# a block round the detector whose face lies 0.5 mm in front of it, between it and the mask, and a card there
PARTS = {"mask corner": ((0.0055, 0.0055, 0.495), "closes round mixel(s) m0 (1 of its 4 mask corners, its housing, "
                         "between detector and mask)", "they read too little"),
         "detector": ((0.0, 0.0, 0.5035), "cuts through mixel(s) m0 (its housing, between detector and mask)",
                      "reads as if it were not there"),
         "card": ((0.0, 0.0, 0.4995), "cuts through mixel(s) m0 (its housing, between detector and mask)",
                  "reads as if it were not there")}


@pytest.mark.parametrize("part", sorted(PARTS))
def test_a_mover_that_closes_round_part_of_a_mixel_is_said(part):
    """A block that closes round a corner of the mask (and so reaches into the housing behind it; part of the
    aperture sees its black back: P 6-7 % low), or
    round the detector, or a 1 mm card inside the housing (a real mixel would be blind; the renderer starts its
    rays at the mask and reads P as without them, within 0.3 %) while the mask centre stays outside them: the
    watch, which looked at the mask centre only, said nothing. Now one EngulfedWarning names the part and what it
    does."""
    centre, named, effect = PARTS[part]
    block = trimesh.creation.box((0.01, 0.01, 0.01) if part != "card" else (0.01, 0.01, 0.0))
    parked = np.asarray(block.vertices) + (1.0, 0.0, 0.5)
    cam = ms.single(pose=Pose((0.0, 0.0, 0.5), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)))
    lamp = sd.area_light(0.4, 0.4, Pose((0.0, 0.0, 1.0), (0.0, 0.0, -1.0)).matrix(), 5.0)
    floor = sd.textured_plane(np.full((4, 4), 0.5), 1.0, 1.0, Pose((0, 0, 0), (0, 0, 1)).matrix())
    sim = ms.Simulation(cam, world={"block": sd.mesh_object("block", parked, np.asarray(block.faces), 0.5),
                                    "lamp": lamp, "floor": floor})
    frames = [{"block.vertex_positions": (np.asarray(block.vertices) + at).astype(np.float32).ravel()}
              for at in ((1.0, 0.0, 0.5), centre)]
    m, told = _said(lambda: sim.measure(frames, ms.Aperture(), BUDGET))
    drop = 1.0 - m.irradiance_w_m2[1, 0] / m.irradiance_w_m2[0, 0]
    assert (drop < 0.01) if part != "mask corner" else (drop > 0.05), drop
    assert len(told) == 1 and f"the moving shape 'block' {named} in frame 1 " in told[0], told
    assert effect in told[0]


def test_a_card_through_the_housing_as_built_is_said():
    """A mixel looking up at a lamp through a two-sided card that crosses its housing 1 mm in front of the
    detector: it read the lamp unhindered (0.758 W/m^2) without a word; now one WorldWarning names mixel and card.
    The card 2 mm beyond the mask (in its view, where the renderer sees it) says nothing of housings."""
    lamp = sd.area_light(0.4, 0.4, Pose((0.0, 0.0, 1.0), (0.0, 0.0, -1.0)).matrix(), 5.0)
    for card_z_m, crossing in ((0.001, True), (0.004, False)):
        card = {"type": "rectangle", "to_world": sd._transform(
            Pose((0.0, 0.0, card_z_m), (0, 0, -1.0), (0, 1.0, 0)).matrix() @ np.diag([0.05, 0.05, 1, 1.0])),
            "bsdf": {"type": "twosided", "bsdf": {"type": "diffuse"}}}
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            ms.Simulation(ms.single(pose=Pose((0.0, 0.0, 0.0), (0, 0, 1.0), (0, 1.0, 0))),
                          world={"lamp": lamp, "card": card})
        told = [str(w.message) for w in said if "housing" in str(w.message)]
        assert told == (["a shape crosses a mixel's housing, between its detector and its mask (m0 by 'card'): a "
                         "mixel would be blind to what it hides there, and the renderer, which starts the rays at "
                         "the mask, reads as if it were not there; move the mincam or the shape apart"]
                        if crossing else [])
