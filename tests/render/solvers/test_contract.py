"""The solver contract: every public solver crossed with every scene it solves (as Mitsuba's
``test_ad_integrators.py`` crosses its scene configs with its integrators).

Each (solver, scene) pair must

* agree with the scene's independent oracle (:mod:`mincam_sim.oracles.closed_forms`,
:mod:`mincam_sim.oracles.quadrature`:
  float64 quadrature sharing no code with the renderer) within the Monte Carlo error (``assert_close_mc``,
  Z = 4.5 estimated standard errors);
* give the same numbers for the same seed (and the scene be left as it was found);
* resume through a :class:`mincam_sim.Run` store: a run killed after its first row, run again, gives the
  in-memory numbers bit for bit;
* return typed results: ``Measurements`` (``m.maps`` the maps of a response-map run, None otherwise) or
  ``Changes`` with a typed :class:`~mincam_sim.RunInfo`;

and every solver refuses a scene kind it does not solve (and the wrong measurement) with an ``InputError``.

A deterministic solver (:class:`~mincam_sim.render.solvers.DotProduct`, its quadrature's error estimate as its
standard error) carries its own oracle in its
entry: the idealised model computed independently (on the screen, through the projection's Jacobian, where the
solver integrates on the mask plane), or, with every physical effect switched on, the scene's physics without the
other mixels' bodies; it must agree to a relative tolerance.

Adding a solver: one module in ``mincam_sim/render/solvers/`` and one :data:`ENTRIES` row here.
"""

from __future__ import annotations

import dataclasses
import functools
import typing
import warnings

import numpy as np
import pytest
from conftest import assert_close_mc

import mincam_sim as ms
from mincam_sim import masks
from mincam_sim.errors import InputError
from mincam_sim.model.geometry import look_at
from mincam_sim.model.optics import Mincam, Mixel
from mincam_sim.oracles.closed_forms import open_aperture_irradiance, point_to_parallel_rect
from mincam_sim.oracles.quadrature import mixel_irradiance_gl, open_aperture_view_factor_irradiance
from mincam_sim.render import backend
from mincam_sim.render import simulation as simulation_module
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.solvers import SOLVERS, ResponseMaps, Solver
from mincam_sim.scene.display import coverage

pytestmark = pytest.mark.skipif(not backend.is_jit(), reason="needs a JIT variant (LLVM or CUDA)")


# ------------------------------------------------------------------------------------------------ scenes
@dataclasses.dataclass
class Scene:
    """A scene config: how to build its Simulation, its frames and the oracle of each frame.

    ``frames`` / ``expected`` are absolute measurements (``P`` per frame and mixel); ``changes`` /
    ``expected_dp`` frames measured against the scene as built (world scenes). ``plane`` names a textured
    rectangle that is the scene's only reflecting surface (``PlaneReplay``), and ``plane_frames`` move it within
    its plane."""

    name: str
    kind: str
    build: typing.Callable[[], ms.Simulation]
    frames: list
    expected: np.ndarray
    changes: list | None = None
    expected_dp: np.ndarray | None = None
    plane: str | None = None
    plane_frames: list | None = None


def _rotation(axis, deg: float) -> np.ndarray:
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    t = np.radians(deg)
    return np.eye(3) + np.sin(t) * k + (1 - np.cos(t)) * k @ k


def _moved(pose: ms.Pose, rot: np.ndarray, shift_m) -> ms.Pose:
    return ms.Pose(tuple(rot @ np.asarray(pose.position_m) + shift_m), tuple(rot @ np.asarray(pose.forward)),
                   tuple(rot @ np.asarray(pose.up)))


def _display_tilted() -> Scene:
    """A tilted off-axis sinusoid mixel before a rotated screen showing an off-centre square (the coupled geometry
    a fixed strata pairing got wrong): the float64 Gauss-Legendre oracle."""
    screen = ms.Screen(width_m=0.4, height_m=0.3, resolution=(80, 60),
                       pose=ms.Pose((0.0, 0.0, -0.6), (np.sin(np.radians(25)), 0.0, np.cos(np.radians(25))),
                                    (0, 1, 0)))
    square = (0.04, 0.07, 0.02, 0.05)
    mask = masks.sinusoid(2 * np.pi / 0.4e-3, 0.5, 0.5, phase_rad=0.7, direction_deg=30.0)
    mixel = Mixel(mask, pose=look_at((0.05, -0.02, 0.0), tuple(screen.to_world(0.055, 0.035)), (0, 1, 0)),
                  name="tilted")
    cam = Mincam((mixel,))
    frame = 2.0 * coverage(screen, *square)
    one = mixel_irradiance_gl(mixel, screen, square, 2.0, n_detector=8, n_screen=24)
    return Scene("display", "display", lambda: ms.Simulation(cam, screen=screen), [frame, 0.5 * frame],
                 np.array([[one], [0.5 * one]]))


def _display_shadowing() -> Scene:
    """A mixel 10 mm in front of another hides 27 % of its view of a uniform screen: the polygon view-factor
    oracle with the front body's shadow."""
    back = Mixel(masks.constant(1.0), pose=ms.Pose((0.0, 0.0, 0.0), (0, 0, -1)), name="back")
    front = Mixel(masks.constant(1.0, width_m=6e-3), d_f_m=3e-3, pose=ms.Pose((0.004, 0.0, -0.010), (0, 0, -1)),
                  name="front")
    screen, radiance = ms.Screen(), 2.0
    shadowed = open_aperture_view_factor_irradiance(back, screen, radiance, [front.body_corners_m()])
    alone = open_aperture_view_factor_irradiance(front, screen, radiance)
    assert shadowed < 0.8 * open_aperture_view_factor_irradiance(back, screen, radiance)
    frame = np.full(screen.shape, radiance)
    cam = Mincam((back, front))
    return Scene("shadowing_mixels", "display", lambda: ms.Simulation(cam, screen=screen), [frame, 0.5 * frame],
                 np.array([[shadowed, alone], [0.5 * shadowed, 0.5 * alone]]))


HEIGHT = 0.5


def _world_plane() -> Scene:
    """An open mixel 0.5 m over a grey plane (albedo 0.5) under a uniform sky (2 W m^-2 sr^-1): the closed-form
    view factor. Taken away (shrunk to a speck, or moved 100 m), the mixel sees the sky itself: dP is the
    closed form at the sky's radiance minus the plane's."""
    cam = ms.single(masks.constant(1.0), pose=ms.Pose((0, 0, HEIGHT), (0, 0, -1), (0, 1, 0)))
    placed = ms.Pose((0, 0, 0), (0, 0, 1)).matrix()

    def elements():
        return {"table": sd.textured_plane(np.full((4, 4), 0.5), 1.0, 1.0, placed), "sky": sd.sky(2.0)}

    def view(radiance: float) -> float:
        return open_aperture_irradiance(radiance, 1e-4, 2e-3, 2e-3, 2e-3, (-0.5, 0.5, -0.5, 0.5), HEIGHT)

    table = view(0.5 * 2.0)
    matrix = placed @ np.diag([0.5, 0.5, 1.0, 1.0])  # the rectangle's to_world (the dict's scale)
    speck, far = matrix.copy(), matrix.copy()
    speck[:3, :2] *= 1e-6
    far[0, 3] += 100.0
    slid = matrix.copy()
    slid[0, 3] += 0.01  # 1 cm within its plane: still under the whole field of view
    changes = [{"table.to_world": speck}, {"table.to_world": far}]
    return Scene("world", "world", lambda: ms.Simulation(cam, world=elements()), [{}, {"table.to_world": slid}],
                 np.array([[table], [table]]), changes, np.full((2, 1), view(2.0) - table), "table",
                 [{}, {"table.to_world": slid}])


def _world_far_tilted() -> Scene:
    """The shadowing pair before an emitting panel (a world element), the whole rig turned 75 degrees and moved
    1.2 km from the origin: the view-factor oracle. The panel taken away (a speck, or 50 m aside): dP = -P."""
    rot, shift = _rotation((0.3, -1, 0.2), 75.0), np.array([1200.0, -350.0, 40.0])
    back = Mixel(masks.constant(1.0), pose=_moved(ms.Pose((0.0, 0.0, 0.0), (0, 0, -1)), rot, shift), name="back")
    front = Mixel(masks.constant(1.0, width_m=6e-3), d_f_m=3e-3,
                  pose=_moved(ms.Pose((0.004, 0.0, -0.010), (0, 0, -1)), rot, shift), name="front")
    base = ms.Screen()
    screen = ms.Screen(base.width_m, base.height_m, base.resolution, _moved(base.pose, rot, shift))
    radiance = 2.0
    expected = np.array([open_aperture_view_factor_irradiance(back, screen, radiance, [front.body_corners_m()]),
                         open_aperture_view_factor_irradiance(front, screen, radiance)])
    cam = Mincam((back, front))

    def elements():
        return {"panel": sd.area_light(screen.width_m, screen.height_m, screen.pose.matrix(), radiance)}
    matrix = screen.pose.matrix() @ np.diag([screen.width_m / 2, screen.height_m / 2, 1.0, 1.0])
    speck, aside = matrix.copy(), matrix.copy()
    speck[:3, :2] *= 1e-6
    aside[:3, 3] += rot @ np.array([50.0, 0.0, 0.0])
    changes = [{"panel.to_world": speck}, {"panel.to_world": aside}]
    return Scene("world_far_tilted", "world", lambda: ms.Simulation(cam, world=elements(), max_depth=2),
                 [{}, {}], np.array([expected, expected]), changes, -np.array([expected, expected]))


SCENES = {s.name: s for s in (_display_tilted(), _display_shadowing(), _world_plane(), _world_far_tilted())}


# ------------------------------------------------------------------------------ oracles of the idealised model
def _ideal_square(mixel: Mixel, screen: ms.Screen, pinhole_m: np.ndarray, region_m, radiance: float,
                  n: int = 48) -> float:
    """The bare dot-product model of one mixel for a uniform rectangle of the screen, integrated on the *screen*:
    ``(pi F / A_mask) int T(x_m(s)) dA_m/dA_s dA_s`` with the central projection's Jacobian
    ``dA_m / dA_s = d_f^2 cos(t_s) / (r^2 cos^3(t))`` (t about the mixel's axis, t_s at the screen), Gauss-Legendre
    over the rectangle (which must lie inside the aperture's view); pi F from the closed form."""
    rot = mixel.pose.matrix()[:3, :3]
    x0, x1, y0, y1 = region_m
    gx, wx = np.polynomial.legendre.leggauss(n)
    xs, ys = 0.5 * (x1 - x0) * (gx + 1) + x0, 0.5 * (y1 - y0) * (gx + 1) + y0
    w = np.outer(wx, wx) * (x1 - x0) * (y1 - y0) / 4
    sx, sy = np.meshgrid(xs, ys, indexing="ij")
    delta = screen.to_world(sx, sy) - pinhole_m
    r = np.linalg.norm(delta, axis=-1)
    local = delta @ rot
    cos_t, cos_s = local[..., 2] / r, -(delta @ screen.pose.axes()[2]) / r
    x_m, y_m = -local[..., 0] * mixel.d_f_m / local[..., 2], local[..., 1] * mixel.d_f_m / local[..., 2]
    assert (np.abs(x_m) < mixel.mask.width_m / 2).all() and (np.abs(y_m) < mixel.mask.height_m / 2).all()
    t = mixel.mask.profile.evaluate(x_m, y_m)
    jac = mixel.d_f_m**2 * cos_s / (r * r * cos_t**3)
    pi_f = np.pi * point_to_parallel_rect(-mixel.mask.width_m / 2, mixel.mask.width_m / 2, -mixel.mask.height_m / 2,
                                          mixel.mask.height_m / 2, mixel.d_f_m)
    return float(radiance * pi_f / mixel.mask.area_m2 * np.sum(w * t * jac))


def _ideal_facing(mixel: Mixel, screen: ms.Screen, pinhole_m: np.ndarray, radiance: float) -> float:
    """The bare model of an open mixel facing a parallel uniform screen: the screen's image on the mask plane is the
    screen scaled by ``d_f / depth`` about the pinhole; ``pi F L`` times the share of the aperture it covers."""
    depth = float(pinhole_m[2] - screen.pose.position_m[2])
    k = mixel.d_f_m / depth
    cx, cy = -(screen.pose.position_m[0] - pinhole_m[0]) * k, (screen.pose.position_m[1] - pinhole_m[1]) * k
    hw, hh = mixel.mask.width_m / 2, mixel.mask.height_m / 2
    sw, sh = screen.width_m * k / 2, screen.height_m * k / 2
    covered = max(0.0, min(hw, cx + sw) - max(-hw, cx - sw)) * max(0.0, min(hh, cy + sh) - max(-hh, cy - sh))
    pi_f = np.pi * point_to_parallel_rect(-hw, hw, -hh, hh, mixel.d_f_m)
    return float(radiance * pi_f * covered / mixel.mask.area_m2)


def _bare_model(scene: str) -> np.ndarray:
    """The bare DotProduct model of each display scene, computed independently of the solver."""
    sim, s = _sim(scene), SCENES[scene]
    centre = sim.mincam.centre_m
    if scene == "display":
        one = _ideal_square(sim.mincam[0], sim.screen, centre, (0.04, 0.07, 0.02, 0.05), 2.0)
        return np.array([[one], [0.5 * one]])
    one = np.array([_ideal_facing(m, sim.screen, centre, 1.0) for m in sim.mincam])
    radiance = np.array([f.max() for f in s.frames])
    return radiance[:, None] * one[None, :]


def _physics_without_bodies(scene: str) -> np.ndarray:
    """Every effect on: the scene's physics, the other mixels' bodies left out (the model has none)."""
    sim, s = _sim(scene), SCENES[scene]
    if scene == "display":
        return s.expected
    alone = np.array([open_aperture_view_factor_irradiance(m, sim.screen, 1.0) for m in sim.mincam])
    return np.array([f.max() for f in s.frames])[:, None] * alone[None, :]


@functools.cache
def _sim(scene: str) -> ms.Simulation:
    """The scene's simulation, shared by every solver that solves it (each leaves the scene as it found it)."""
    return SCENES[scene].build()


# ----------------------------------------------------------------------------------------------- solvers
@dataclasses.dataclass
class Entry:
    """A solver under contract and the budget it is tested with (``slow``: its pairs run only with -m slow)."""

    solver: Solver
    budget: ms.Budget
    slow: bool = False
    oracle: typing.Callable[[str], np.ndarray] | None = None  # exact solvers: their own expectation per scene
    rtol: float = 0.0
    label: str = ""


ENTRIES = [
    Entry(ms.Reference(), ms.Budget(spp=1 << 15, replicates=16, seed=3)),
    Entry(ms.Aperture(), ms.Budget(spp=1 << 16, replicates=16, seed=3)),
    Entry(ms.ResponseMap(), ms.Budget(samples_per_texel=64, replicates=4, seed=3)),
    Entry(ms.PlainChange(), ms.Budget(spp=1 << 14, replicates=8, seed=3)),
    Entry(ms.StratifiedChange(), ms.Budget(spp=1 << 14, replicates=8, seed=3)),
    Entry(ms.PlaneReplay("table"), ms.Budget(spp=1 << 16, replicates=8, seed=3)),
    Entry(ms.DotProduct(), ms.Budget(seed=3), oracle=_bare_model, rtol=1e-9, label="bare"),
    Entry(ms.DotProduct(parallax=True, vignetting=True, detector_blur=True), ms.Budget(seed=3),
          oracle=_physics_without_bodies, rtol=1e-6, label="physics"),
]


def _solves(entry: Entry, scene: Scene) -> bool:
    solver = entry.solver
    if scene.kind not in solver.scenes:
        return False
    if isinstance(solver, ms.PlaneReplay):
        return scene.plane == solver.plane
    return scene.changes is not None if solver.changes else True


def _id(entry: Entry) -> str:
    return entry.solver.name + (f"_{entry.label}" if entry.label else "")


PAIRS = [pytest.param(entry, scene.name, id=f"{_id(entry)}-{scene.name}",
                      marks=[pytest.mark.slow] if entry.slow else [])
         for entry in ENTRIES for scene in SCENES.values() if _solves(entry, scene)]


def _frames(entry: Entry, scene: Scene) -> list:
    if isinstance(entry.solver, ms.PlaneReplay):
        return scene.plane_frames
    return scene.changes if entry.solver.changes else scene.frames


def _measure(entry: Entry, scene: str, sink=None):
    """The solver's result in the scene (a change solver's fallbacks and retries are the scene's business)."""
    sim, s = _sim(scene), SCENES[scene]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if entry.solver.changes:
            return sim.measure_changes(_frames(entry, s), None, entry.solver, entry.budget, sink=sink)
        return sim.measure(_frames(entry, s), entry.solver, entry.budget, sink=sink)


@functools.cache
def _result(entry_index: int, scene: str):
    return _measure(ENTRIES[entry_index], scene)


def _cached(entry: Entry, scene: str):
    return _result(ENTRIES.index(entry), scene)


def _arrays(result) -> list[np.ndarray]:
    if isinstance(result, ms.Changes):
        return [result.dp.irradiance_w_m2, result.dp.stderr_w_m2, result.p.irradiance_w_m2, result.p.stderr_w_m2]
    return [result.irradiance_w_m2, result.stderr_w_m2]


def test_every_public_solver_is_under_contract():
    assert {type(e.solver) for e in ENTRIES} == set(SOLVERS)
    assert {name for name in ms.__all__ if name in {c.__name__ for c in SOLVERS}} == {c.__name__ for c in SOLVERS}
    for entry in ENTRIES:
        assert any(_solves(entry, scene) for scene in SCENES.values()), entry.solver.name


@pytest.mark.parametrize("entry, scene", PAIRS)
def test_agrees_with_the_oracle(entry, scene):
    result, s = _cached(entry, scene), SCENES[scene]
    if entry.oracle is not None:  # a deterministic quadrature: its error estimate, its own oracle
        expected = entry.oracle(scene)
        np.testing.assert_allclose(result.irradiance_w_m2, expected, rtol=entry.rtol, atol=0,
                                   err_msg=f"{_id(entry)} in {scene}")
        # the error estimate covers the error (beyond the oracle's own, within rtol)
        assert np.all(np.abs(result.irradiance_w_m2 - expected) <= result.stderr_w_m2 + entry.rtol * np.abs(expected))
    elif entry.solver.changes:
        assert_close_mc(result.dp.irradiance_w_m2, s.expected_dp, result.dp.stderr_w_m2,
                        what=f"{entry.solver.name} dP in {scene}")
        p_expected = s.expected + s.expected_dp  # P(frame) = P(background) + dP
        lit = p_expected > 1e-3 * np.abs(s.expected).max()
        assert_close_mc(result.p.irradiance_w_m2[lit], p_expected[lit], result.p.stderr_w_m2[lit],
                        what=f"{entry.solver.name} P in {scene}")
    else:
        assert_close_mc(result.irradiance_w_m2, s.expected, result.stderr_w_m2,
                        what=f"{entry.solver.name} in {scene}")


@pytest.mark.parametrize("entry, scene", PAIRS)
def test_same_seed_same_numbers_and_the_scene_left_as_found(entry, scene):
    sim = _sim(scene)
    before = {k: np.array(sim.params[k]) for k in sim.params} if sim.kind == "world" else None
    again = _measure(entry, scene)
    for a, b in zip(_arrays(_cached(entry, scene)), _arrays(again), strict=True):
        np.testing.assert_array_equal(a, b)
    if before is not None:
        for key, value in before.items():
            np.testing.assert_array_equal(np.array(sim.params[key]), value, err_msg=key)


@pytest.mark.parametrize("entry, scene", PAIRS)
def test_results_are_typed(entry, scene):
    result = _cached(entry, scene)
    n = len(_frames(entry, SCENES[scene]))
    if entry.solver.changes:
        assert isinstance(result, ms.Changes) and isinstance(result.info, ms.RunInfo)
        info = result.info
        assert info.solver == entry.solver.name and info.seed == entry.budget.seed
        assert info.replicates == entry.budget.replicates and info.spp_per_mixel_per_frame == entry.budget.spp
        assert isinstance(info.rays_per_mixel_per_frame, int) and info.rays_per_mixel_per_frame > 0
        assert isinstance(info.retried_frames, tuple) and isinstance(info.fallbacks, tuple)
        shape = (n, len(_sim(scene).mincam))
        assert result.dp.irradiance_w_m2.shape == result.p.irradiance_w_m2.shape == shape
    else:
        assert isinstance(result, ms.Measurements)
        assert result.irradiance_w_m2.shape == (n, len(_sim(scene).mincam))
        assert result.meta["solver"] == entry.solver.name
        if isinstance(entry.solver, (ms.ResponseMap, ms.DotProduct)):
            assert isinstance(result.maps, ResponseMaps)
        else:
            assert result.maps is None


@pytest.mark.parametrize("entry, scene", PAIRS)
def test_a_killed_run_resumes_through_run_with_the_same_numbers(entry, scene, tmp_path, monkeypatch):
    original = simulation_module.collect

    def killed_after_the_first_row(rows, table):
        def first_only():
            yield next(iter(rows))
            raise KeyboardInterrupt

        return original(first_only(), table)

    s, sim = SCENES[scene], _sim(scene)
    call = "measure_changes" if entry.solver.changes else "measure"
    args = (None,) if entry.solver.changes else ()
    monkeypatch.setattr(simulation_module, "collect", killed_after_the_first_row)
    with pytest.raises(KeyboardInterrupt), ms.Run(tmp_path) as run, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        getattr(run, call)(sim, _frames(entry, s), *args, entry.solver, entry.budget)
    done = np.load(tmp_path / "measurements" / "done.npy")
    chunked = isinstance(entry.solver, (ms.ResponseMap, ms.DotProduct))  # maps: a chunk of frames per row
    assert done[0] and (done.all() if chunked else not done[1])
    monkeypatch.setattr(simulation_module, "collect", original)
    with ms.Run(tmp_path) as run, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        resumed = getattr(run, call)(sim, _frames(entry, s), *args, entry.solver, entry.budget)
    for a, b in zip(_arrays(_cached(entry, scene)), _arrays(resumed), strict=True):
        np.testing.assert_array_equal(a, b)
    if entry.solver.changes:
        assert resumed.info == _cached(entry, scene).info


@pytest.mark.parametrize("entry", ENTRIES, ids=[_id(e) for e in ENTRIES])
def test_a_wrong_scene_kind_is_refused(entry):
    solver = entry.solver
    for scene in SCENES.values():
        sim = _sim(scene.name)
        if scene.kind not in solver.scenes:
            with pytest.raises(InputError, match=f"does not solve {scene.kind} scenes"):
                _measure(entry, scene.name)
        elif solver.changes:
            with pytest.raises(InputError, match="measures changes against a background"):
                sim.measure(scene.changes, solver, entry.budget)
        else:
            with pytest.raises(InputError, match="needs a change solver"):
                sim.measure_changes(scene.frames, None, solver, entry.budget)
