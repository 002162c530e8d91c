"""A mincam in a general scene (tabletop, road ...): fast form, per-frame parameter updates, correlated seeds.

Frames change only what moves, through ``mi.traverse`` parameters (no scene reload). All mixels of a frame
are traced in one kernel. A frame and its background are traced with the same seed, replicate by replicate,
so the Monte Carlo noise of the two largely cancels in their difference ``dP`` (what the estimators use); the
standard error of ``dP`` comes from the spread of the per-replicate differences, so it includes that
correlation.

Two estimators of ``dP`` (``measure_changes(estimator=...)``):

* ``"plain"`` (the reference): every frame traced over the whole aperture with the background's seed; the
  background traced once.
* ``"stratified"``: per frame and mixel, the aperture region where the frame can differ from the background
  (``mincam_sim.render.change_region``: the moving shapes' bounds and their shadow volumes from the emitting
  shapes, for both the frame and the background) gets most rays, the rest of the aperture a few, both strata unbiased
  (``mincam_sim.render.stratified``). The frame and the background are traced with the same seed, counts and regions, so
  their rays pair up lane by lane; inter-reflection bounces are guided toward the moving shapes
  (``mincam_sim.render.guided_path``); the background's whole-aperture value (for ``P``) is traced once per run, on a
  jittered aperture grid with at least :data:`BACKGROUND_MIN_SPP` rays. Kernels are compiled once and reused
  (same code every frame and budget: per-frame bounds, guides and ray counts are array or opaque inputs); each
  frame costs one parameter update (one acceleration-structure rebuild) for the frame and one back to the
  background.
"""

from __future__ import annotations

import difflib
import functools
import warnings
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..frames import FrameSink, collect, resolve_sink
from ..identity import build_identity, fingerprint
from ..measurements import Measurements
from ..optics import Mincam
from ..progress import progress
from . import backend
from .change_region import ApertureRegions, box_corners, change_points, mixel_regions
from .elements import transform_update, vertex_update
from .estimation import (
    check_counts,
    derive_seed,
    heavy_tailed,
    pilot_to_target,
    warn_target_missed,
    warn_unreached,
    worst_relative_stderr,
)
from .guided_path import guide_sphere, guide_spheres, spheres_of
from .guided_path import supports as guided_path_supports
from .mask_eval import mask_model_meta
from .mincam_scene import CAMERA_KEY, SENSOR_KEY, MincamScene, geometry_meta
from .scene_dicts import mincam_body_shapes
from .stratified import (
    buffers_key,
    check_strata,
    frozen_recordings,
    stratified_lanes,
    whole_aperture_estimates,
)
from .world_input import check_frames, check_radiant_params, check_update, expand_elements

MAX_SPP = 1 << 26  # cap of the target-noise budget, samples per mixel per frame
ESTIMATORS = ("plain", "stratified")
STRATA_EXPANSIONS = (1.0, 2.0, 4.0, 8.0)  # nested rectangles: the change region, then scaled about its centre
STRATA_SHARES = (0.6, 0.1, 0.1, 0.1, 0.1)  # rays per stratum (region, rings, rest): near Neyman, guided, bench scene
BACKGROUND_MIN_SPP = 1 << 16  # stratified: rays per mixel (at least) for the background's whole-aperture value
RETRY_FACTOR = 4  # a frame whose replicates are heavy-tailed is measured again with this many times the replicates
FREEZE_ALLOWANCE = 6  # recordings of a run's frozen launch (passes x buffer addresses) before it must replay
# per frame, kept with the results
INFO_COLUMNS = ("retried", "guided", "guide_spheres", "region_area_fraction", "rays_per_mixel")
Updates = Mapping[str, np.ndarray]
__all__ = ["CAMERA_KEY", "SENSOR_KEY", "FallbackWarning", "HeavyTailWarning", "WorldParameters", "WorldRenderer",
           "transform_update", "vertex_update"]


class FallbackWarning(UserWarning):
    """The stratified estimator could not bound a change (a moving emitter or light, an environment light, a
    parameter of no shape) or guide its bounces, and fell back to a costlier, still unbiased, sampling."""


class HeavyTailWarning(UserWarning):
    """A measurement's replicates are dominated by one of them (a rare, heavy light path): its standard error is
    itself uncertain. The frame was measured again with more replicates; this warns of what stayed so."""


class WorldRenderer:
    """Render a mincam's measurements of an arbitrary Mitsuba scene.

    Parameters
    ----------
    mincam : Mincam
    elements : dict
        Scene content: name -> Mitsuba dict or object (shapes, emitters). Names are the prefixes of the
        parameters that :meth:`update` changes (e.g. ``"car.vertex_positions"``, ``"road.to_world"``).
    replicates : int
        Independent estimates per measurement (>= 2), for the standard error.
    max_depth : int
        Longest path of the ``path`` integrator, in segments from the mask: 2 = direct lighting only; 3 (the
        default) adds one inter-reflection (e.g. light the moving object throws onto the table).
    camera : dict, optional
        A ground-truth camera (``mincam_sim.render.scene_dicts.pinhole_camera``) rendered by :meth:`camera_image`.
    """

    def __init__(self, mincam: Mincam, elements: dict, replicates: int = 8, max_depth: int = 3,
                 camera: dict | None = None) -> None:
        if not isinstance(mincam, Mincam):
            raise InputError(f"mincam must be a Mincam (e.g. mincam_sim.cross_layout()), got {type(mincam).__name__}")
        if isinstance(replicates, bool) or not isinstance(replicates, (int, np.integer)) or replicates < 2:
            raise InputError(f"replicates must be an integer >= 2, got {replicates!r}")
        backend.require_jit("The fast mixel sensor (a Python Mitsuba plugin)")
        self.mi = backend.mitsuba()
        self.mincam, self.replicates = mincam, int(replicates)
        # replay the stratified launches (dr.freeze) instead of tracing them per frame: on LLVM, where the moving
        # meshes' vertices are written in place and their buffers' addresses key the recordings
        self.freeze_launches = backend.variant().startswith("llvm")
        self.pair_lanes = True  # background pass: trace again only the lanes whose frame paths met a moving shape
        elements = expand_elements(elements)
        # The scene is built around the mincam: Mitsuba offsets every secondary ray by ~1e-4 x (1 + max|p|)
        # scene units, so a table 50 m (1 km) from the origin lost 1.2 % (3.7 %) of a toy's dP to shadow rays
        # that started past it. Positions in (updates to) the user's elements are shifted on their way in and
        # out: the API speaks world coordinates only (:attr:`params`, :meth:`update`).
        self.scene_origin_m = mincam.centre_m
        self.scene_mincam = mincam.translated(-self.scene_origin_m)
        try:
            self.world = MincamScene.world(self.scene_mincam, elements, max_depth, camera)
        except ValueError as exc:
            raise InputError(str(exc)) from None
        try:
            self.scene = self.world.fast_scene
        except RuntimeError as exc:  # Mitsuba's own message names the plugin and the parameter
            raise InputError(f"Mitsuba could not build the scene: {str(exc).strip()}") from None
        self.sensor = self.world.sensor(SENSOR_KEY)
        self.camera = self.world.sensor(CAMERA_KEY)
        self._own = set(mincam_body_shapes(self.scene_mincam)) | {SENSOR_KEY}  # built in scene coordinates
        scene_params = self.world.params
        check_radiant_params(scene_params)
        self._shifted = _shifted_keys(self.scene, scene_params, self._own)
        self.world.update({key: _shift(key, scene_params[key], -self.scene_origin_m) for key in self._shifted})
        self.params = WorldParameters(self)
        self._mirrors = _delta_surfaces(self.scene)
        self._content_key: str | None = None
        self._content_key = self.content_fingerprint()  # before any update: the scene as built
        self._as_built: dict[str, object] = {}  # each updated parameter's value (world coordinates) before updates
        self._last_set: dict[str, np.ndarray] = {}  # the last numpy value each parameter was set to
        self.revisions: dict[str, int] = {}  # how often each parameter was changed (who replays a scene checks it)

    def update(self, updates: Updates) -> None:
        """Set scene parameters (numpy arrays or Mitsuba values; positions in world coordinates [m], as
        ``params`` reads them) and apply them without reloading."""
        if not isinstance(updates, Mapping):
            raise InputError(f"an update must be a dict 'name.parameter' -> value, got {type(updates).__name__}")
        scene_params = self.world.params
        for key, value in updates.items():
            if key not in scene_params or key.split(".", 1)[0] in self._own:
                raise InputError(_unknown_parameter(key, self.params.keys(), key.split(".", 1)[0] in self._own))
            check_update(key, scene_params[key], value)
        for key in updates:
            self._remember_as_built(key)
        updates = self._new_values(updates)
        for key in updates:
            self.revisions[key] = self.revisions.get(key, 0) + 1
        self.world.update({key: _shift(key, value, -self.scene_origin_m) if key in self._shifted else value
                           for key, value in updates.items()})
        if any(key.split(".", 1)[0] in self._mirrors for key in updates):
            self._mirrors = _delta_surfaces(self.scene)

    def _new_values(self, updates: Updates) -> dict:
        """The updates that change something: a numpy value equal to the one this renderer set last is left
        out, so a frame that re-parks every idle toy moves only the toy that moves (its shapes keep their
        buffers, and a frozen launch keeps its recordings)."""
        out = {}
        for key, value in updates.items():
            if isinstance(value, np.ndarray):
                last = self._last_set.get(key)
                if last is not None and last.dtype == value.dtype and np.array_equal(last, value):
                    continue
                self._last_set[key] = value.copy()
            else:
                self._last_set.pop(key, None)
            out[key] = value
        return out

    def complete_background(self, frames: Sequence[Updates], background: Updates) -> dict:
        """``background`` plus, for every parameter the frames set and it leaves out, that parameter's value in the
        scene as built (so that restoring the background undoes every frame)."""
        missing = sorted({key for f in frames for key in f} - set(background))
        for key in missing:
            self._remember_as_built(key)
        return {**background, **{key: self._as_built[key] for key in missing if key in self._as_built}}

    def _remember_as_built(self, key: str) -> None:
        if key not in self._as_built and key in self.params:
            self._as_built[key] = self.params[key]

    @functools.cached_property
    def shapes_by_id(self) -> dict:
        """The scene's shapes by their id (fixed once the scene is loaded)."""
        return {shape.id(): shape for shape in self.scene.shapes()}

    def buffers_key(self) -> tuple:
        """``stratified.buffers_key`` of every shape whose parameters were updated (the whole scene if an
        updated parameter belongs to something else: a shared BSDF, an environment emitter)."""
        names = {key.split(".", 1)[0] for key in self._as_built}
        shapes = self.shapes_by_id
        objects = [shapes[name] for name in sorted(names) if name in shapes]
        return buffers_key(objects if len(objects) == len(names) else [self.scene])

    def world_value(self, key: str):
        """Parameter ``key`` as :meth:`update` takes it back, in world coordinates: positions (``to_world``
        as a 4 x 4 matrix, ``vertex_positions`` flat (3 n,), a point light's ``position``) as float64 numpy,
        anything else as a copy of the Mitsuba value."""
        value = _param_value(self.world.params[key])
        return _shift(key, value, self.scene_origin_m) if key in self._shifted else value

    def estimates(self, spp: int, seed: int) -> np.ndarray:
        """(replicates, n_mixels) independent irradiance estimates [W/m^2], ``spp / replicates`` rays each."""
        return self.world.fast_estimates(spp, self.replicates, seed)

    def measure_changes(
        self,
        frames: Sequence[Updates],
        background: Updates,
        spp: int = 1 << 16,
        seed: int = 0,
        correlated: bool = True,
        out_dir: str | Path | None = None,
        show_progress: bool = False,
        target_rel_stderr: float = 0.0,
        overwrite: bool = False,
        estimator: str = "plain",
        strata_shares: Sequence[float] = STRATA_SHARES,
        strata_expansions: Sequence[float] = STRATA_EXPANSIONS,
        guide_bounces: bool = True,
        sink: FrameSink | None = None,
    ) -> tuple[Measurements, Measurements]:
        """Measure each frame's change from the background: ``dP = P(frame) - P(background)``.

        Parameters
        ----------
        frames : sequence of dict
            Parameter updates of each frame (applied on top of ``background``).
        background : dict
            Parameter updates that restore the background (e.g. objects moved out of view). A parameter the frames
            set that it leaves out is restored to its value in the scene as built (``{}`` = the scene as built).
        correlated : bool
            True: each frame uses the background's seed (noise cancels in dP). False: independent seeds.
        sink : FrameSink, optional
            Takes each frame's row as it comes (:class:`mincam_sim.frames.FrameSink`; default: in memory).
            :meth:`mincam_sim.run.Run.sink` keeps them on disk: a rerun of the same run (scene content, mincam,
            frames, budget, seed, versions) resumes there, a different one is refused unless the run overwrites.
        out_dir, overwrite : path, bool
            Deprecated (one release): a store in ``out_dir``, locked while written; use :class:`mincam_sim.run.Run`.
        target_rel_stderr : float
            If > 0, ``spp`` is only the pilot: up to 4 frames spread over the sequence are measured with it,
            and the sample count is extrapolated (variance ~ 1/samples, x 1.5 margin, at most ``MAX_SPP``)
            so that every significant change (``|dP| > 3 sigma`` in the pilot) reaches this relative standard
            error; ``meta["spp_per_mixel_per_frame"]`` is what was used and ``meta["reached_rel_stderr"]``
            what was reached over the significant changes.
        estimator : {"plain", "stratified"}
            ``"plain"``: whole-aperture rays for every frame (the reference). ``"stratified"``: most rays in the
            aperture region the moving shapes and their shadows can reach, the rest in rings around it and over
            the rest of the aperture; the frame and the background are both traced per frame (``spp`` rays each)
            at the same rays.
        strata_shares : sequence of float
            Share of the stratified estimator's ``spp`` per stratum (region, each ring, rest), positive.
        strata_expansions : sequence of float
            Scale factors of the nested rectangles about the region's centre, starting at 1 (one fewer than the
            shares).
        guide_bounces : bool
            Stratified only: draw half of the inter-reflection bounces toward a sphere around the moving shapes
            and their shadows (``mincam_sim.render.guided_path``; unbiased, the same expectation as the ``path``
            integrator).
            Light the object throws onto the rest of the scene is then met by many rays with small weights
            instead of a few with large ones. Ignored at ``max_depth`` the guided path does not cover.

        Returns
        -------
        (dP, P) : Measurements
            Changes and absolute frame measurements, each (n_frames, n_mixels) with standard errors.
        """
        sink = resolve_sink(sink, out_dir, overwrite, "WorldRenderer.measure_changes")
        shares = self._check_change_args(frames, background, spp, target_rel_stderr, estimator, strata_shares)
        background = self.complete_background(frames, background)
        options = {"estimator": estimator, "strata_shares": strata_shares, "strata_expansions": strata_expansions,
                   "guide_bounces": guide_bounces}
        spp, budget = self._resolve_spp(frames, background, int(spp), seed, correlated, target_rel_stderr, options)
        self.update(background)
        if estimator == "plain":
            bg_spp = spp
            bg = self.estimates(bg_spp, seed)
        else:  # traced once per run, P = background + dP: a jittered aperture, at least BACKGROUND_MIN_SPP rays
            bg_spp = max(spp, BACKGROUND_MIN_SPP)
            bg = whole_aperture_estimates(self.scene, self.sensor, self.mincam, self.replicates, bg_spp,
                                          derive_seed(seed, "background"))
        if estimator == "plain":
            run = _PlainRun(self, background, spp, seed, correlated, bg)
        else:
            run = _StratifiedRun(self, frames, background, spp, seed, correlated, shares,
                                 tuple(strata_expansions), bool(guide_bounces), bg)
        run.note_delta_movers(_moving_shapes([background, *frames]))
        identity = None
        if sink.persistent:
            identity = self._store_identity(frames, background, spp, seed, correlated, shares, options)
        values, errors = self._run_frames(run, frames, sink, identity, show_progress)
        self.update(background)
        meta = {"form": "fast_world", "estimator": estimator, **run.meta(values[:, 2 * len(self.mincam):]),
                "spp_per_mixel_per_frame": spp, "background_spp_per_mixel": int(bg_spp), "seed": seed,
                "correlated_seeds": correlated, "replicates": self.replicates, "background_w_m2": bg.mean(0).tolist(),
                "masks": {m.name: mask_model_meta(m.mask) for m in self.mincam},
                "background_stderr_w_m2": (bg.std(0, ddof=1) / np.sqrt(self.replicates)).tolist(),
                **backend.describe(), **geometry_meta(self.mincam), **budget}
        return self._changes(values, errors, meta, run, target_rel_stderr)

    def _check_change_args(self, frames, background, spp, target_rel_stderr, estimator, strata_shares) -> np.ndarray:
        """Refuse, in one line each, what measure_changes cannot honestly measure; the strata shares as an array."""
        check_frames(frames, background)
        try:
            check_counts(spp, self.replicates)
        except ValueError as exc:
            raise InputError(str(exc)) from None
        if int(spp) < self.replicates:
            raise InputError(f"spp = {spp} rays per mixel per frame is fewer than the {self.replicates} replicates "
                             "(each replicate needs rays of its own); raise spp or lower replicates")
        if not (isinstance(target_rel_stderr, (int, float)) and np.isfinite(target_rel_stderr)
                and target_rel_stderr >= 0):
            raise InputError(f"target_rel_stderr must be >= 0 (0 = use spp as given), got {target_rel_stderr!r}")
        if estimator not in ESTIMATORS:
            raise InputError(f"estimator must be one of {ESTIMATORS}, got {estimator!r}")
        shares = np.asarray(strata_shares, dtype=float)
        if shares.ndim != 1 or not np.all(np.isfinite(shares) & (shares > 0)):
            raise InputError(f"strata_shares (share of rays per stratum) must be positive numbers, "
                             f"got {strata_shares!r}")
        return shares

    def _resolve_spp(self, frames, background, spp: int, seed: int, correlated: bool, target: float,
                     options: dict) -> tuple[int, dict]:
        """``spp`` as given, or (target > 0) the count the pilots extrapolate (:func:`.estimation.pilot_to_target`
        on up to 4 frames spread over the run), with the pilots' trail."""
        if not target > 0 or not len(frames):
            return spp, {}
        pilot_idx = np.unique(np.linspace(0, len(frames) - 1, min(4, len(frames))).astype(int))

        def pilot(samples: int):
            with warnings.catch_warnings():  # a pilot's fallbacks are said by the run itself
                warnings.simplefilter("ignore", FallbackWarning)
                warnings.simplefilter("ignore", HeavyTailWarning)
                dp, _ = self.measure_changes([frames[i] for i in pilot_idx], background, samples, seed, correlated,
                                             **options)
            return dp.irradiance_w_m2, dp.stderr_w_m2

        resolved, trail = pilot_to_target(pilot, spp, target, MAX_SPP)
        return int(resolved), {"pilot_spp": spp, "pilot_worst_rel_stderr": trail[0]["worst_rel_stderr"],
                               "pilot_trail": trail, "target_rel_stderr": target}

    def _store_identity(self, frames, background, spp, seed, correlated, shares, options) -> dict:
        """Everything that determines a run's numbers, for its store (:func:`mincam_sim.identity.build_identity`,
        kind ``"world_changes"``)."""
        parts = {"spp": int(spp), "seed": int(seed), "correlated": correlated, "replicates": self.replicates,
                 "n_frames": len(frames), "frames": _fingerprint(frames), "background": _fingerprint([background]),
                 "mincam": fingerprint(self.mincam), "scene": self.content_fingerprint(), "retry_factor": RETRY_FACTOR}
        if options["estimator"] != "plain":
            parts.update(estimator=options["estimator"], strata_shares=shares.tolist(),
                         strata_expansions=[float(e) for e in options["strata_expansions"]],
                         guide_bounces=bool(options["guide_bounces"]))
        return build_identity("world_changes", parts, variant=backend.variant())

    def _run_frames(self, run: _Run, frames, sink: FrameSink, identity, show_progress: bool):
        """Values and errors (n_frames, columns: dP, P, heavy-tailed and unseen flags per mixel, run info) of
        every frame, from the sink's table where a run with this identity has already measured them."""
        names = self.mincam.names
        columns = ([f"dP_{m}" for m in names] + [f"P_{m}" for m in names]
                   + [f"heavy_tailed_{m}" for m in names] + [f"unseen_{m}" for m in names] + list(INFO_COLUMNS))
        table = sink.open(identity, len(frames), columns)

        def rows():  # one row per frame: dP and P, then the flags and info (no standard error of their own)
            for i, row_v, row_e, info in run.rows(frames, table.pending(), show_progress):
                yield [i], np.concatenate([row_v, info])[None], np.concatenate([row_e, np.zeros_like(info)])[None]

        return collect(rows(), table)

    def _changes(self, values, errors, meta: dict, run: _Run, target: float) -> tuple[Measurements, Measurements]:
        """(dP, P) with the reached noise in their meta, and the run's warnings said."""
        n, names = len(self.mincam), self.mincam.names
        reached = worst_relative_stderr(values[:, :n], errors[:, :n], significance=3.0)
        meta["reached_rel_stderr"] = reached if np.isfinite(reached) else None
        warn_target_missed(reached, target, meta["spp_per_mixel_per_frame"], MAX_SPP)
        run.warn(meta)
        warn_unreached(Measurements(values[:, n:2 * n], errors[:, n:2 * n], names))
        dp = Measurements(values[:, :n], errors[:, :n], names, {**meta, "quantity": "dP = P(frame) - P(background)"})
        p = Measurements(values[:, n:2 * n], errors[:, n:2 * n], names, {**meta, "quantity": "P(frame)"})
        return dp, p

    def change_guide(self, moving: Sequence[str]) -> list[tuple[np.ndarray, float]] | None:
        """Spheres (centre, radius [m], scene coordinates) toward which guided bounces aim
        (``mincam_sim.render.guided_path``): one per group of the named shapes, in their current place, with
        their shadow volumes (shapes close together share one); None if a change is unbounded."""
        return self._change(moving)[1]

    def change_regions(self, moving: Sequence[str]) -> ApertureRegions:
        """Aperture regions (per mixel) that the named shapes, in their current place, their shadows and their
        images in the scene's planar mirrors reach (and every other delta surface: glass, curved mirrors): the
        bounding rectangle of each shape's own region (so that far-apart shapes, one of them out of view, do
        not make one hull spanning both); the whole aperture if one of them is unbounded."""
        return self._change(moving)[0]

    def _change(self, moving: Sequence[str]) -> tuple[ApertureRegions, list | None, list[str]]:
        """:meth:`change_regions`, :meth:`change_guide` and why a change is unbounded, from one look at the
        scene."""
        points, reasons = {}, []
        for name in sorted(moving):
            points[name], why = _change_points(self.scene, [name], self._mirrors)
            if why:
                reasons.append(why)
        if reasons:
            return ApertureRegions.full(self.mincam), None, reasons
        regions = ApertureRegions.empty(self.mincam)
        for name, p in points.items():
            regions = regions.union(mixel_regions(self.scene_mincam, p))
            for seen in self._mirrors.images(p, exclude=name):
                regions = regions.union(mixel_regions(self.scene_mincam, seen))
        spheres = guide_spheres(list(points.values()))
        if spheres:  # light reaching the change through a mirror: bounces aimed at the lights' images find it
            spheres = spheres_of(spheres + self._mirrors.light_image_spheres(self.scene))
        return regions, (spheres or None), []

    def content_fingerprint(self) -> str:
        """Content key of the scene as Mitsuba holds it: every traversable parameter's value (meshes,
        textures, transforms, radiances), the element names and plugin types, and the path depth."""
        if self._content_key is None:
            params = self.params
            parts = {key: _param_array(params[key]) for key in sorted(params.keys())
                     if not key.startswith(SENSOR_KEY)}
            types = {name: (value.get("type") if isinstance(value, dict) else type(value).__name__)
                     for name, value in self.world.elements.items()}
            self._content_key = fingerprint({"params": parts, "types": types, "max_depth": self.world.max_depth})
        return self._content_key

    def camera_image(self, spp: int = 64, seed: int = 0) -> np.ndarray:
        """Image (rows, cols) of the ground-truth pinhole camera [W m^-2 sr^-1], row 0 at the top."""
        return self.world.camera_image(spp, seed)


class WorldParameters(Mapping):
    """The scene's parameters as the user's elements define them, in world coordinates (read-only).

    Keys are ``"name.parameter"`` (``mi.traverse`` names) of the user's elements; the mincam's own bodies and
    sensor are not among them. Values are what :meth:`WorldRenderer.update` takes back: positions
    (``to_world`` 4 x 4, ``vertex_positions`` flat (3 n,), a point light's ``position``) as float64 numpy in
    world coordinates [m], anything else a copy of the Mitsuba value. Reading a value and writing it back
    changes nothing.
    """

    def __init__(self, renderer: WorldRenderer) -> None:
        self._renderer = renderer

    def _visible(self, key: str) -> bool:
        return key.split(".", 1)[0] not in self._renderer._own and "." in key

    def __getitem__(self, key: str):
        if key not in self._renderer.world.params or not self._visible(key):
            raise KeyError(key)
        return self._renderer.world_value(key)

    def __contains__(self, key) -> bool:
        return isinstance(key, str) and key in self._renderer.world.params and self._visible(key)

    def __iter__(self) -> Iterator[str]:
        return (k for k in self._renderer.world.params.keys() if self._visible(k))

    def __len__(self) -> int:
        return sum(1 for _ in self)


def _unseen(diff: np.ndarray, changes: np.ndarray) -> np.ndarray:
    """(n_mixels,) True where a frame changes a shape but every replicate of its dP is the same (no ray met it)."""
    return changes & np.all(diff == diff[:1], axis=0)


def _unknown_parameter(key: str, known, own: bool) -> str:
    if own:
        return (f"{key!r} belongs to the mincam's own body or sensor; move the mixels through the Mincam, not the "
                "scene")
    close = difflib.get_close_matches(str(key), list(known), n=3)
    hint = f"; did you mean {', '.join(map(repr, close))}?" if close else "; see the renderer's params.keys()"
    return f"unknown scene parameter {key!r}{hint}"


class _Run:
    """The frames of one ``measure_changes`` run: per-frame replicate estimates, the heavy-tail check and its
    retry, and what the run says about itself (per-frame info kept with the results, so that a resumed run
    reports every frame; meta and warnings)."""

    def __init__(self, renderer: WorldRenderer, background: Updates, spp: int, seed: int, correlated: bool,
                 bg: np.ndarray) -> None:
        self.r, self.background, self.spp, self.seed, self.correlated = renderer, background, spp, seed, correlated
        self.bg = bg
        self.fallbacks: dict[str, str] = {}

    def note_delta_movers(self, moving) -> None:
        """Say it when a moving shape is glass or a mirror (a delta BSDF): the light it redirects onto the rest of
        the scene is found only by unguided delta bounces, and a run that draws none of those rare heavy paths
        reports too small a sigma (on a glass block in view, ~10x in one run of 32), which no diagnostic inside
        one run can see."""
        mi = backend.mitsuba()
        shapes = self.r.shapes_by_id
        for name in sorted(moving):
            bsdf = shapes[name].bsdf() if name in shapes else None
            if bsdf is not None and int(bsdf.flags()) & int(mi.BSDFFlags.Delta):
                self.fallbacks[f"delta:{name}"] = (
                    f"'{name}' is glass or a mirror and moves: the light it refracts or reflects onto the scene is "
                    "found only by unguided delta bounces, so one run's sigma can be too small when it draws none "
                    "of those rare paths; raise the replicates or compare a few seeds")

    def rows(self, frames, todo, show_progress: bool):
        """(frame index, values, stderr, info) per frame of ``todo``: dP then P per mixel; then heavy-tailed and
        unseen flags per mixel and :data:`INFO_COLUMNS`."""
        n = len(self.r.mincam)
        for i in progress(todo, desc="frames", disable=not show_progress):
            i = int(i)
            diff, frame_v, frame_e, changes, info = self.frame(frames, i, self.r.replicates, "")
            retried = bool((heavy_tailed(diff) | _unseen(diff, changes)).any())
            heavy = unseen = np.zeros(n, dtype=bool)
            if retried:
                diff, frame_v, frame_e, changes, _ = self.frame(frames, i, RETRY_FACTOR * self.r.replicates, "retry")
                heavy, unseen = heavy_tailed(diff), _unseen(diff, changes)
            reps = diff.shape[0]
            row_v = np.concatenate([diff.mean(0), frame_v])
            row_e = np.concatenate([diff.std(0, ddof=1) / np.sqrt(reps), frame_e])
            yield i, row_v, row_e, np.concatenate([heavy, unseen, [retried, *info]]).astype(float)

    def meta(self, info: np.ndarray) -> dict:
        """What the run did, from the per-frame info of every frame (this process's and a resumed store's)."""
        n = len(self.r.mincam)
        done = np.all(np.isfinite(info), axis=1)
        heavy, unseen, rest = info[:, :n] > 0, info[:, n:2 * n] > 0, info[:, 2 * n:]
        return {"retried_frames": np.flatnonzero(done & (rest[:, 0] > 0)).tolist(), "retry_factor": RETRY_FACTOR,
                "heavy_tailed": np.argwhere(done[:, None] & heavy).tolist(),
                "no_ray_met_the_change": np.argwhere(done[:, None] & unseen).tolist(),
                "fallbacks": sorted(self.fallbacks.values())}

    def warn(self, meta: dict) -> None:
        for message in sorted(self.fallbacks.values()):
            warnings.warn(message, FallbackWarning, stacklevel=4)
        heavy, unseen = meta["heavy_tailed"], meta["no_ray_met_the_change"]
        if heavy or unseen:
            where = heavy[:3] + unseen[:3]
            warnings.warn(
                f"{len(heavy)} value(s) stayed dominated by one replicate and {len(unseen)} saw no ray meet a change "
                f"after {RETRY_FACTOR}x the replicates (first [frame, mixel]: {where}): a rare, heavy light path (a "
                "mirror, glass, a small bright object far from the change region); their standard errors are "
                "uncertain. Raise spp or replicates; see meta['heavy_tailed'], meta['no_ray_met_the_change']",
                HeavyTailWarning, stacklevel=4)


class _PlainRun(_Run):
    """Whole-aperture rays for every frame, with the background's seed (the reference estimator)."""

    def frame(self, frames, i: int, replicates: int, purpose: str):
        r = self.r
        frame_seed = self.seed if self.correlated else derive_seed(self.seed, "frame", i)
        if purpose:
            frame_seed = derive_seed(frame_seed, purpose, i)
        spp = self.spp * replicates // r.replicates
        r.update(self.background)
        bg = self.bg if replicates == r.replicates and not purpose else r.world.fast_estimates(spp, replicates,
                                                                                             frame_seed)
        r.update(frames[i])
        est = r.world.fast_estimates(spp, replicates, frame_seed)
        changes = np.full(len(r.mincam), bool(_changed_shapes(frames[i], self.background)))
        info = (0.0, 0.0, 1.0, float(self.spp))  # not guided, no guide sphere, the whole aperture, its rays
        return est - bg, est.mean(0), est.std(0, ddof=1) / np.sqrt(replicates), changes, info

    def meta(self, info: np.ndarray) -> dict:
        return {**super().meta(info), "rays_per_mixel_per_frame": int(self.spp)}


class _StratifiedRun(_Run):
    """Most rays in the aperture region the frame's change reaches; frame and background paired lane by lane."""

    def __init__(self, renderer, frames, background, spp, seed, correlated, shares, expansions, guided, bg):
        super().__init__(renderer, background, spp, seed, correlated, bg)
        check_strata([1] * len(shares), expansions)
        self.expansions, self.guided = expansions, guided
        per_rep = -(-int(spp) // renderer.replicates)
        self.counts = [max(1, int(round(per_rep * s / shares.sum()))) for s in shares]
        self.moving = _moving_shapes([background, *frames])
        renderer.update(background)
        self.bg_regions = {}
        for name in self.moving:
            self.bg_regions[name], _, why = renderer._change([name])
            for reason in why:
                self.note_fallback(name, reason)
        self.can_guide = guided and guided_path_supports(renderer.world.max_depth)
        self.shapes = renderer.shapes_by_id
        self.bg_boxes = {name: _watch_box(self.shapes[name]) for name in self.moving if name in self.shapes}
        lights_move = _emitters_among(renderer.scene, self.moving)
        # a path that crosses no moving shape's box (in either place) is the same path in both passes
        self.pairs = (renderer.pair_lanes and correlated and self.can_guide and not lights_move
                      and set(self.bg_boxes) == self.moving)
        self.freeze = renderer.freeze_launches and not lights_move
        self.launches = ("frozen" if self.freeze else
                         "traced" + (": a moving shape emits light" if renderer.freeze_launches else ""))
        self.recordings_at_start = frozen_recordings(renderer.scene)
        self.frames_traced = 0
        if guided and not self.can_guide:
            self.fallbacks["depth"] = (f"bounces are not guided at max_depth {renderer.world.max_depth} (the guided "
                                       "path covers 1 .. 5): rays follow Mitsuba's path")

    def note_fallback(self, name: str, reason: str) -> None:
        self.fallbacks.setdefault(name, f"{reason}; the stratified estimator samples the whole aperture and does not "
                                        "guide bounces in frames that move it (unbiased, but about as noisy as the "
                                        "plain estimator at the same rays)")

    def frame(self, frames, i: int, replicates: int, purpose: str):
        r = self.r
        changed = _changed_shapes(frames[i], self.background)
        r.update({**self.background, **frames[i]})
        regions, guide, why = r._change(changed)
        for reason in why:
            self.note_fallback(next(iter(sorted(changed))), reason)
        for name in changed:
            regions = regions.union(self.bg_regions[name])
        guide = guide if self.can_guide else None
        frame_seed = (derive_seed(self.seed, "stratified") if self.correlated
                      else derive_seed(self.seed, "stratified", i))
        if purpose:
            frame_seed = derive_seed(frame_seed, purpose, i)
        kw = {"expansions": self.expansions, "guide": guide, "max_depth": r.world.max_depth}
        watch = None
        if self.pairs and guide is not None:
            watch = [_watch_box(self.shapes[name]) for name in sorted(changed)]
            watch += [self.bg_boxes[name] for name in sorted(changed)]
        lanes = stratified_lanes(r.scene, r.sensor, r.mincam, regions, replicates, self.counts, frame_seed,
                                 freeze=self._freeze_key(), watch=watch, **kw)
        r.update(self.background)
        bg_seed = frame_seed if self.correlated else derive_seed(self.seed, "stratified-background", i, purpose)
        bg_lanes = stratified_lanes(r.scene, r.sensor, r.mincam, regions, replicates, self.counts, bg_seed,
                                    freeze=self._freeze_key(), pair=lanes if watch is not None else None, **kw)
        diff = lanes.estimates() - bg_lanes.estimates()
        if not purpose:
            self.frames_traced += 1
            self._check_recordings()
        info = (float(guide is not None), 0.0 if guide is None else float(len(guide)),
                float(np.mean(regions.area_fraction())), (lanes.traced + bg_lanes.traced) / len(r.mincam))
        if replicates == self.bg.shape[0]:
            frame = self.bg + diff  # P(frame): the background traced once over the whole aperture, plus the change
            frame_v, frame_e = frame.mean(0), frame.std(0, ddof=1) / np.sqrt(replicates)
        else:  # the background and the change are independent estimates
            frame_v = self.bg.mean(0) + diff.mean(0)
            frame_e = np.hypot(self.bg.std(0, ddof=1) / np.sqrt(self.bg.shape[0]),
                               diff.std(0, ddof=1) / np.sqrt(replicates))
        changes = np.full(len(r.mincam), bool(changed))
        return diff, frame_v, frame_e, changes, info

    def _freeze_key(self) -> tuple | None:
        return self.r.buffers_key() if self.freeze else None

    def _check_recordings(self) -> None:
        """Trace instead of replaying once the frozen launch keeps recording (the moving meshes' buffers land at
        new addresses every frame, as large meshes' do): recording costs what tracing does, and replays
        would never come."""
        if not self.freeze:
            return
        recorded = frozen_recordings(self.r.scene) - self.recordings_at_start
        if recorded > FREEZE_ALLOWANCE + self.frames_traced // 4:
            self.freeze = False
            self.launches = (f"traced from frame {self.frames_traced}: the frozen launch recorded {recorded} times "
                             "(the moving shapes' buffers move in memory every frame)")

    def meta(self, info: np.ndarray) -> dict:
        counts, n = self.counts, len(self.r.mincam)
        rest = info[np.all(np.isfinite(info), axis=1), 2 * n:]
        full = self.r.replicates * sum(counts)  # the frame pass's rays per mixel; the background traces <= these
        rays = float(rest[:, 4].mean()) if len(rest) else 2.0 * full
        return {**super().meta(info), "strata_expansions": list(self.expansions), "strata_rays_per_replicate": counts,
                "rays_per_mixel_per_frame": int(round(rays)),
                "background_rays_share": (rays - full) / full,
                "paired_lanes_reused": bool(self.pairs), "launches": self.launches,
                "moving_shapes": sorted(self.moving), "guide_bounces": bool(self.guided),
                "guided_frames": int(rest[:, 1].sum()),
                "guide_spheres_per_frame": rest[:, 2].astype(int).tolist(),
                "region_area_fraction_mean": float(rest[:, 3].mean()) if len(rest) else None}


class _DeltaSurfaces:
    """The scene's delta surfaces (mirrors, glass, null BSDFs): planar ones by their plane, which mirrors a
    change into an image the mixels can see; curved ones by their bounding box (rays that reach them may go
    anywhere after)."""

    def __init__(self, planes: dict[str, tuple[np.ndarray, float]], boxes: dict[str, np.ndarray]) -> None:
        self.planes, self.boxes = planes, boxes

    def __contains__(self, name: str) -> bool:
        return name in self.planes or name in self.boxes

    def images(self, points: np.ndarray, exclude: str = "") -> list[np.ndarray]:
        """Point sets to add to a change's region: its mirror images in each planar delta surface, and the
        boxes of the curved ones (``exclude``: the moving shape itself)."""
        return self.reflect(points, exclude) + [box for name, box in self.boxes.items() if name != exclude]

    def reflect(self, points: np.ndarray, exclude: str = "") -> list[np.ndarray]:
        """``points`` (m, 3) mirrored in each planar delta surface's plane but ``exclude``'s."""
        return [points - 2.0 * (points @ n - c)[:, None] * n for name, (n, c) in self.planes.items() if name != exclude]

    def with_images(self, boxes: list, directions: list) -> tuple[list, list]:
        """Light boxes and directions plus their images in each planar delta surface (first-order reflections):
        the shadow a mover casts in light that a mirror throws."""
        images = [(im.min(axis=0), im.max(axis=0)) for lo, hi in boxes for im in self.reflect(box_corners(lo, hi))]
        turned = [d - 2.0 * (np.asarray(d) @ n) * n for d in directions for n, _ in self.planes.values()]
        return boxes + images, list(directions) + turned

    def light_image_spheres(self, scene) -> list[tuple[np.ndarray, float]]:
        """Spheres around the images of the scene's emitting shapes and point lights in each planar delta
        surface: the direction in which a bounce meets a light through a mirror."""
        if not self.planes:
            return []
        lights, _ = _light_bounds(scene)
        boxes = [] if lights is None else list(lights[0])
        boxes += [(np.array(s.bbox().min, dtype=float), np.array(s.bbox().max, dtype=float))
                  for s in scene.shapes() if s.is_emitter()]
        return [guide_sphere(im) for lo, hi in boxes for im in self.reflect(box_corners(lo, hi))]


def _delta_surfaces(scene) -> _DeltaSurfaces:
    """The scene's delta surfaces, planar or not, from 64 points sampled on each."""
    mi = backend.mitsuba()
    planes, boxes = {}, {}
    for shape in scene.shapes():
        bsdf = shape.bsdf()
        if shape.is_emitter() or shape.is_sensor() or bsdf is None:
            continue
        if not int(bsdf.flags()) & int(mi.BSDFFlags.Delta):
            continue
        bb = shape.bbox()
        lo, hi = np.array(bb.min, dtype=float), np.array(bb.max, dtype=float)
        g = np.linspace(0.05, 0.95, 8)
        uu, vv = np.meshgrid(g, g)
        ps = shape.sample_position(0.0, mi.Point2f(uu.ravel(), vv.ravel()))
        p = np.array(ps.p, dtype=float).reshape(3, -1).T
        n = np.array(ps.n, dtype=float).reshape(3, -1).T
        normal = n[0] / np.linalg.norm(n[0])
        size = max(float(np.linalg.norm(hi - lo)), 1e-9)
        if np.all(np.abs(n @ normal) > 1 - 1e-6) and np.all(np.abs((p - p[0]) @ normal) < 1e-6 * size):
            planes[shape.id()] = (normal, float(p[0] @ normal))
        else:
            boxes[shape.id()] = box_corners(lo, hi)
    return _DeltaSurfaces(planes, boxes)


def _param_array(value) -> np.ndarray:
    """A traversed Mitsuba parameter as a numeric array (transforms by their matrix)."""
    matrix = _transform_matrix(value)
    arr = matrix if matrix is not None else np.asarray(value)
    if arr.dtype.hasobject:
        arr = np.frombuffer(repr(value).encode(), dtype=np.uint8)
    return arr


def _shifted_keys(scene, params, ours: set[str]) -> set[str]:
    """Parameters that hold positions, of every element but ``ours``: ``to_world`` (not of environment or
    directional emitters, whose transforms only turn directions), ``vertex_positions`` and point lights'
    ``position``."""
    directional = {e.id() for e in scene.emitters() if e.is_environment() or
                   int(e.flags()) & int(backend.mitsuba().EmitterFlags.Infinite)}
    keys = set()
    for key in params.keys():
        name, _, rest = key.partition(".")
        if name not in ours and name not in directional and rest in ("to_world", "vertex_positions", "position"):
            keys.add(key)
    return keys


def _shift(key: str, value, offset_m: np.ndarray):
    """A position parameter moved by ``offset_m`` [m] (float64 numpy, the form :meth:`WorldRenderer.update`
    takes)."""
    if key.endswith(".to_world"):
        matrix = _transform_matrix(value)
        moved = (np.array(value, dtype=np.float64).reshape(4, 4) if matrix is None else matrix).copy()
        moved[:3, 3] += offset_m
        return moved
    points = np.array(value, dtype=np.float64).reshape(-1, 3) + offset_m
    return points.ravel()


def _transform_matrix(value) -> np.ndarray | None:
    """The matrix of a Mitsuba transform parameter (4 x 4, or 3 x 3 for texture transforms; float64), None for
    anything else."""
    if "Transform" not in type(value).__name__:
        return None
    matrix = np.array(value.matrix, dtype=np.float64)
    side = int(round(np.sqrt(matrix.size)))
    return matrix.reshape(side, side)


def _param_value(value):
    """A copy of a traversed parameter that :meth:`WorldRenderer.update` accepts back (transforms as 4 x 4 numpy
    matrices, arrays and tensors as Mitsuba values of their own type and shape)."""
    matrix = _transform_matrix(value)
    if matrix is not None:
        return matrix
    if isinstance(value, (bool, int, float)):
        return value
    return type(value)(np.array(value))


def _watch_box(shape) -> tuple[np.ndarray, np.ndarray]:
    """The shape's bounding box (scene coordinates [m]) grown by a margin past Mitsuba's ray offsets: a path that
    stays out of it cannot meet the shape."""
    box = shape.bbox()
    lo, hi = np.array(box.min, dtype=float).ravel(), np.array(box.max, dtype=float).ravel()
    margin = 1e-3 * (1.0 + float(np.max(np.abs(np.concatenate([lo, hi])))))
    return lo - margin, hi + margin


def _emitters_among(scene, names) -> bool:
    """True if one of the named shapes emits light (its sampling tables are rebuilt when it moves, at
    addresses a frozen launch cannot see: such runs are traced unfrozen)."""
    return any(s.id() in names and s.emitter() is not None for s in scene.shapes())


def _moving_shapes(updates: Sequence[Updates]) -> set[str]:
    """Names of the shapes whose parameters the updates set (the part before the first dot of each key)."""
    return {key.split(".", 1)[0] for u in updates for key in u} - {SENSOR_KEY, CAMERA_KEY}


def _changed_shapes(update: Updates, background: Updates) -> set[str]:
    """Names of the shapes that ``update``, applied on top of ``background``, sets to other values."""
    names = set()
    for key, value in update.items():
        same = False
        if key in background:
            try:
                same = np.array_equal(np.asarray(value), np.asarray(background[key]))
            except (TypeError, ValueError):
                same = False
        if not same:
            names.add(key.split(".", 1)[0])
    return names - {SENSOR_KEY, CAMERA_KEY}


def _change_points(scene, moving, mirrors: _DeltaSurfaces | None = None) -> tuple[np.ndarray | None, str]:
    """Corner points whose hull holds the moving shapes and their shadow volumes [m] (from the lights and their
    images in planar mirrors), or None and why the change is unbounded (an environment light, a moving emitter,
    an emitter of a kind not bounded here, or a moved parameter that belongs to no shape)."""
    shapes = {s.id(): s for s in scene.shapes()}
    for name in moving:
        if name not in shapes:
            return None, (f"'{name}' is not a shape (a moving light or another parameter): its change reaches "
                          "anywhere")
        if shapes[name].is_emitter():
            return None, f"'{name}' is an emitting shape: the light it moves reaches anywhere"
    lights, why = _light_bounds(scene)
    if lights is None:
        return None, why

    def box(shape):
        bb = shape.bbox()
        return np.array(bb.min, dtype=float), np.array(bb.max, dtype=float)

    objects = [box(shapes[name]) for name in sorted(moving)]
    boxes, directions = lights
    boxes = boxes + [box(s) for s in scene.shapes() if s.is_emitter()]
    if mirrors is not None:
        boxes, directions = mirrors.with_images(boxes, directions)
    return change_points(objects, boxes, box(scene), directions), ""


def _light_bounds(scene) -> tuple[tuple[list, list] | None, str]:
    """Where the scene's non-shape emitters shine from: point-like ones (point, spot) as zero-size boxes [m],
    directional ones by the direction their rays travel; None (and why) for an environment light or any other
    kind."""
    mi = backend.mitsuba()
    boxes, directions = [], []
    for emitter in scene.emitters():
        flags = int(emitter.flags())
        if flags & int(mi.EmitterFlags.Surface):
            continue  # an emitting shape: bounded by its shape's box
        if emitter.is_environment():
            return None, f"the environment light '{emitter.id()}' casts shadows anywhere"
        params = mi.traverse(emitter)
        if flags & int(mi.EmitterFlags.DeltaDirection) and "to_world" in params:
            directions.append(np.array(params["to_world"].matrix, dtype=float).reshape(4, 4)[:3, 2])
        elif flags & int(mi.EmitterFlags.DeltaPosition) and ("position" in params or "to_world" in params):
            where = (np.array(params["position"], dtype=float).ravel() if "position" in params
                     else np.array(params["to_world"].matrix, dtype=float).reshape(4, 4)[:3, 3])
            boxes.append((where, where))
        else:
            return None, f"the light '{emitter.id()}' is of a kind not bounded here (an area light without a shape?)"
    return (boxes, directions), ""


def _fingerprint(updates: Sequence[Updates]) -> list:
    import hashlib

    h = hashlib.sha256()
    for u in updates:
        for k in sorted(u):
            h.update(k.encode())
            h.update(np.ascontiguousarray(np.asarray(u[k], dtype=np.float64)).tobytes())
    return [len(updates), h.hexdigest()[:16]]
