"""One front door: a :class:`Simulation` holds a mincam in a scene; solvers and a budget measure it.

::

    import mincam_sim as ms

    sim = ms.Simulation(ms.pair_layout(spacing_m=0.033), screen=ms.Screen())
    m = sim.measure(frames, solver=ms.ResponseMap(), budget=ms.Budget(target_rel_stderr=1e-3))

    world = ms.Simulation(ms.cross_layout(), world="room.xml")          # or a dict of elements, or an mi.Scene
    ch = world.measure_changes(frames, solver=ms.StratifiedChange(), budget=ms.Budget(spp=1 << 15))
    ch.dp, ch.p, ch.info.rays_per_mixel_per_frame, ch.info.reached_rel_stderr

Display scenes measure frames (radiance images, row 0 at the top); world scenes measure parameter updates
(``"name.parameter" -> value``, positions in world coordinates [m], as :attr:`Simulation.params` reads them),
absolutely (:meth:`Simulation.measure`, the aperture solver) or as changes against a background
(:meth:`Simulation.measure_changes`). Persistence (identity, lock, resume) is the business of
:class:`mincam_sim.run.Run`, which wraps a simulation.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from os import PathLike
from pathlib import Path

import numpy as np

from ..budget import DEFAULT_SAMPLES_PER_TEXEL, Budget
from ..changes import Changes, RunInfo
from ..errors import InputError
from ..frames import FrameSink, resolve_sink
from ..measurements import Measurements
from ..optics import Mincam
from ..scene.display import Screen
from .estimation import replicate_mean_stderr
from .screen_engine import render_frames
from .solvers import Aperture, PlainChange, PlaneReplay, ResponseMap, Solver, StratifiedChange
from .world import WorldRenderer

DEFAULT_WORLD_REPLICATES = 8


class Simulation:
    """A mincam in a display scene or in a world.

    Parameters
    ----------
    mincam : Mincam
        The mixels, with their poses in world coordinates [m].
    screen : Screen, optional
        An emissive display in a dark room (frames are its radiance images).
    world : dict, mitsuba.Scene, or path, optional
        A world: elements ``name -> Mitsuba dict or object`` (in metres), a loaded ``mi.Scene`` (its shapes and
        emitters), or a Mitsuba 3 XML scene file (loaded with every shape kept as built, addressed by its id).
    max_depth : int
        World scenes: longest path, in segments from the mask (2 = direct light only; 3 adds one bounce).
    camera : dict, optional
        World scenes: a ground-truth pinhole camera (``mincam_sim.render.scene_dicts.pinhole_camera``).
    """

    def __init__(self, mincam: Mincam, *, screen: Screen | None = None, world=None, max_depth: int = 3,
                 camera: dict | None = None) -> None:
        if not isinstance(mincam, Mincam):
            raise InputError(f"mincam must be a Mincam (e.g. mincam_sim.cross_layout()), got {type(mincam).__name__}")
        if (screen is None) == (world is None):
            raise InputError("a Simulation holds either screen=Screen(...) or world=..., exactly one of them")
        if screen is not None and not isinstance(screen, Screen):
            raise InputError(f"screen must be a mincam_sim.Screen, got {type(screen).__name__}")
        self.mincam, self.screen = mincam, screen
        self.kind = "display" if screen is not None else "world"
        self._world: WorldRenderer | None = None
        self.source: Path | None = None
        if world is not None:
            if isinstance(world, (str, PathLike)):
                from .scene_files import load_scene_file

                self.source = Path(world)
                world = {"scene": load_scene_file(self.source)}
            self._world = WorldRenderer(mincam, world, replicates=DEFAULT_WORLD_REPLICATES, max_depth=max_depth,
                                        camera=camera)

    # ------------------------------------------------------------------------------------------ world state
    @property
    def renderer(self) -> WorldRenderer:
        """The world's renderer (world scenes only)."""
        if self._world is None:
            raise InputError("this Simulation holds a display; parameters and updates belong to world scenes")
        return self._world

    @property
    def params(self):
        """The world's parameters in world coordinates (read-only mapping; see :class:`.world.WorldParameters`)."""
        return self.renderer.params

    def update(self, updates: Mapping[str, object]) -> None:
        """Set world parameters (positions in world coordinates [m]) without reloading."""
        self.renderer.update(updates)

    def camera_image(self, spp: int = 64, seed: int = 0) -> np.ndarray:
        """The ground-truth camera's image [W m^-2 sr^-1], row 0 at the top."""
        return self.renderer.camera_image(spp, seed)

    def content_fingerprint(self) -> str:
        """Content key of the scene (world: every traversed parameter; display: the screen)."""
        if self._world is not None:
            return self._world.content_fingerprint()
        from ..identity import fingerprint

        return fingerprint(self.screen)

    # ------------------------------------------------------------------------------------------ measuring
    def _solver(self, solver: Solver | None, default: Solver, what: str) -> Solver:
        solver = default if solver is None else solver
        if not isinstance(solver, Solver):
            raise InputError(f"solver must be one of mincam_sim's solvers (e.g. ms.{type(default).__name__}()), got "
                             f"{type(solver).__name__}")
        if self.kind not in solver.scenes:
            raise InputError(f"the {solver.name} solver does not solve {self.kind} scenes ({what}); use one of its "
                             f"kinds: {', '.join(solver.scenes)}")
        return solver

    @staticmethod
    def _budget(budget: Budget | None) -> Budget:
        if budget is None:
            return Budget()
        if not isinstance(budget, Budget):
            raise InputError(f"budget must be a mincam_sim.Budget, got {type(budget).__name__}")
        return budget

    def measure(self, frames, solver: Solver | None = None, budget: Budget | None = None, *,
                sink: FrameSink | None = None, out_dir: str | Path | None = None, overwrite: bool = False,
                show_progress: bool = False) -> Measurements:
        """What each mixel measures in each frame, with its standard error [W/m^2], (n_frames, n_mixels).

        Display scenes: ``frames`` are radiance images (an array (n, rows, cols), a list, or a FrameSource);
        default solver :class:`~.solvers.ResponseMap`. World scenes: ``frames`` are parameter updates, each
        applied to the scene as built; solver :class:`~.solvers.Aperture`, or :class:`~.solvers.PlaneReplay`
        for frames that only move one textured plane within its plane. ``sink`` (displays;
        :class:`mincam_sim.frames.FrameSink`) takes the per-frame rows: :meth:`mincam_sim.run.Run.sink` keeps them
        on disk and resumes. ``out_dir`` (deprecated, one release): a store there, locked while it is written.
        """
        budget = self._budget(budget)
        if self.kind == "display":
            solver = self._solver(solver, ResponseMap(), "measure")
            sink = resolve_sink(sink, out_dir, overwrite, "Simulation.measure")
            m, maps = render_frames(self.mincam, self.screen, frames, solver.form, budget.rays(),
                                    budget.samples_per_texel or DEFAULT_SAMPLES_PER_TEXEL, budget.target_rel_stderr,
                                    budget.seed, budget.replicates, show_progress=show_progress, sink=sink)
            m.meta["solver"] = solver.name
            m.maps = maps  # ResponseMap: the maps it used; other solvers: None
            return m
        solver = self._solver(solver, Aperture(), "measure")
        if out_dir is not None or sink is not None:
            raise InputError("world frames measured absolutely are not stored; use Run.measure_changes(...) or "
                             "measure_changes(..., sink=run.sink(name))")
        return self._measure_world_frames(frames, solver, budget)

    def _measure_world_frames(self, frames, solver: Solver, budget: Budget) -> Measurements:
        world = self.renderer
        if isinstance(frames, Mapping) or not isinstance(frames, Sequence):
            raise InputError("frames must be a list of parameter-update dicts (one per frame)")
        replicates = budget.replicates_or(DEFAULT_WORLD_REPLICATES)
        as_built = world.complete_background(frames, {})
        if isinstance(solver, PlaneReplay):
            estimates = _plane_replay(world, solver.plane, frames, as_built, budget, replicates)
        else:
            estimates = []
            for frame in frames:
                world.update(as_built)
                world.update(frame)
                estimates.append(world.world.fast_estimates(budget.rays(), replicates, budget.seed))
            world.update(as_built)
        pairs = [replicate_mean_stderr(e) for e in estimates]
        values, errors = [mean for mean, _ in pairs], [err for _, err in pairs]
        meta = {"solver": solver.name, "form": "fast_world", "seed": budget.seed, "replicates": replicates,
                "spp_per_mixel_per_frame": budget.rays()}
        return Measurements(np.array(values).reshape(len(frames), -1), np.array(errors).reshape(len(frames), -1),
                            self.mincam.names, meta)

    def response_maps(self, budget: Budget | None = None, show_progress: bool = False):
        """Each mixel's response map over the screen (display scenes), at the budget's samples per texel."""
        from .response_map import response_maps

        if self.kind != "display":
            raise InputError("response maps are maps over a screen's texels: display scenes only")
        budget = self._budget(budget)
        return response_maps(self.mincam, self.screen, budget.samples_per_texel or DEFAULT_SAMPLES_PER_TEXEL,
                             budget.seed, show_progress=show_progress, replicates=budget.replicates_or(4))

    def measure_changes(self, frames, background: Mapping | None = None, solver: Solver | None = None,
                        budget: Budget | None = None, *, sink: FrameSink | None = None,
                        out_dir: str | Path | None = None, overwrite: bool = False,
                        show_progress: bool = False) -> Changes:
        """Each frame's change from the background, ``dP = P(frame) - P(background)``, and ``P`` (world scenes).

        Parameters
        ----------
        frames : list of dict
            Parameter updates of each frame (on top of ``background``).
        background : dict, optional
            Updates that make the background; a parameter the frames set that it leaves out takes its value in
            the scene as built (default ``{}``: the scene as built).
        solver : StratifiedChange (default) or PlainChange
        budget : Budget
            ``spp`` rays per mixel per frame and pass (or a target), replicates (default 8), seed.
        sink : FrameSink, optional
            Takes the per-frame rows (:meth:`mincam_sim.run.Run.sink`: on disk; a rerun of the same run resumes,
            another one is refused). Default: in memory.
        out_dir : path, optional
            Deprecated (one release): a store there, locked while it is written; use :class:`mincam_sim.run.Run`.
        """
        solver = self._solver(solver, StratifiedChange(), "measure_changes")
        if not isinstance(solver, (PlainChange, StratifiedChange)):
            raise InputError(f"measure_changes needs a change solver (StratifiedChange or PlainChange), got "
                             f"{solver.name}")
        budget = self._budget(budget)
        sink = resolve_sink(sink, out_dir, overwrite, "Simulation.measure_changes")
        world = self.renderer
        world.replicates = budget.replicates_or(DEFAULT_WORLD_REPLICATES)
        kw = {}
        if isinstance(solver, StratifiedChange):
            kw = {"strata_shares": solver.strata_shares, "strata_expansions": solver.strata_expansions,
                  "guide_bounces": solver.guide_bounces}
        dp, p = world.measure_changes(frames, {} if background is None else background, spp=budget.rays(),
                                      seed=budget.seed, show_progress=show_progress,
                                      target_rel_stderr=budget.target_rel_stderr, estimator=solver.form, sink=sink,
                                      **kw)
        dp.meta["target_rel_stderr"] = budget.target_rel_stderr
        return Changes(dp, p, RunInfo.from_meta(dp.meta))


def _plane_replay(world: WorldRenderer, plane: str, frames, as_built: Mapping, budget: Budget,
                  replicates: int) -> list[np.ndarray]:
    """Each frame's (replicates, n_mixels) estimates by :class:`.sliding_plane.SlidingPlane`: the frames may set
    only ``plane``'s ``to_world``."""
    from .sliding_plane import SlidingPlane

    key = f"{plane}.to_world"
    if key not in world.params:
        raise InputError(f"PlaneReplay(plane={plane!r}): the scene has no parameter {key!r}; name the textured "
                         "rectangle's element")
    for i, frame in enumerate(frames):
        if not isinstance(frame, Mapping):
            raise InputError(f"frames[{i}] must be a parameter-update dict, got {type(frame).__name__}")
        other = sorted(k for k in frame if k != key)
        if other:
            raise InputError(f"frames[{i}] sets {other}: the PlaneReplay solver replays frames that move only "
                             f"{key!r}; measure other frames with solver=ms.Aperture()")
    unset = as_built[key] if key in as_built else world.params[key]  # a frame that leaves the plane where it is
    placements = [frame.get(key, unset) for frame in frames]
    if not placements:
        return []
    replay = SlidingPlane(world, plane, placements, budget.rays(), budget.seed, replicates=replicates)
    return [replay.estimates(m) for m in placements]
