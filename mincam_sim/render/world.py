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

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ..identity import fingerprint, library_versions
from ..measurements import Measurements
from ..optics import Mincam
from ..progress import progress
from ..store import ResultStore
from . import backend
from .change_region import ApertureRegions, change_points, mixel_regions
from .elements import transform_update, vertex_update
from .estimation import derive_seed, pilot_to_target, warn_target_missed, warn_unreached, worst_relative_stderr
from .guided_path import guide_sphere
from .guided_path import supports as guided_path_supports
from .mask_eval import mask_model_meta
from .mincam_scene import CAMERA_KEY, SENSOR_KEY, MincamScene, geometry_meta
from .scene_dicts import mincam_body_shapes
from .stratified import check_strata, stratified_estimates, whole_aperture_estimates

MAX_SPP = 1 << 26  # cap of the target-noise budget, samples per mixel per frame
ESTIMATORS = ("plain", "stratified")
STRATA_EXPANSIONS = (1.0, 2.0, 4.0, 8.0)  # nested rectangles: the change region, then scaled about its centre
STRATA_SHARES = (0.6, 0.1, 0.1, 0.1, 0.1)  # rays per stratum (region, rings, rest): near Neyman, guided, bench scene
BACKGROUND_MIN_SPP = 1 << 16  # stratified: rays per mixel (at least) for the background's whole-aperture value
Updates = Mapping[str, np.ndarray]
__all__ = ["CAMERA_KEY", "SENSOR_KEY", "WorldRenderer", "transform_update", "vertex_update"]


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
        if isinstance(replicates, bool) or int(replicates) != replicates or replicates < 2:
            raise ValueError(f"replicates must be an integer >= 2, got {replicates!r}")
        backend.require_jit("The fast mixel sensor (a Python Mitsuba plugin)")
        self.mi = backend.mitsuba()
        self.mincam, self.replicates = mincam, int(replicates)
        # The scene is built around the mincam: Mitsuba offsets every secondary ray by ~1e-4 x (1 + max|p|)
        # scene units, so a table 50 m (1 km) from the origin lost 1.2 % (3.7 %) of a toy's dP to shadow rays
        # that started past it. Positions in (updates to) the user's elements are shifted on their way in.
        self.scene_origin_m = mincam.centre_m
        self.scene_mincam = mincam.translated(-self.scene_origin_m)
        self.world = MincamScene.world(self.scene_mincam, elements, max_depth, camera)
        self.scene = self.world.fast_scene
        self.sensor = self.world.sensor(SENSOR_KEY)
        self.camera = self.world.sensor(CAMERA_KEY)
        self.params = self.world.params  # Mitsuba's parameters, in scene coordinates (world - scene_origin_m)
        ours = set(mincam_body_shapes(self.scene_mincam)) | {SENSOR_KEY}  # built in scene coordinates already
        self._shifted = _shifted_keys(self.scene, self.params, ours)
        self.world.update({key: _shift(key, self.params[key], -self.scene_origin_m) for key in self._shifted})
        self._content_key: str | None = None
        self._content_key = self.content_fingerprint()  # before any update: the scene as built
        self._as_built: dict[str, object] = {}  # each updated parameter's value (world coordinates) before updates

    def update(self, updates: Updates) -> None:
        """Set scene parameters (numpy arrays or Mitsuba values, positions in world coordinates [m]) and apply them
        without reloading."""
        for key in updates:
            self._remember_as_built(key)
        self.world.update({key: _shift(key, value, -self.scene_origin_m) if key in self._shifted else value
                           for key, value in updates.items()})

    def complete_background(self, frames: Sequence[Updates], background: Updates) -> dict:
        """``background`` plus, for every parameter the frames set and it leaves out, that parameter's value in the
        scene as built (so that restoring the background undoes every frame)."""
        missing = sorted({key for f in frames for key in f} - set(background))
        for key in missing:
            self._remember_as_built(key)
        return {**background, **{key: self._as_built[key] for key in missing if key in self._as_built}}

    def _remember_as_built(self, key: str) -> None:
        if key not in self._as_built and key in self.params:
            value = _param_value(self.params[key])
            self._as_built[key] = _shift(key, value, self.scene_origin_m) if key in self._shifted else value

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
        out_dir : path, optional
            Write results per frame as they come; a rerun of the same run (scene content, mincam, frames,
            budget, seed, versions) resumes there, a different one is refused unless ``overwrite``.
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
        n = len(self.mincam)
        if not (np.isfinite(target_rel_stderr) and target_rel_stderr >= 0):
            raise ValueError(f"target_rel_stderr must be >= 0 (0 = use spp as given), got {target_rel_stderr!r}")
        if estimator not in ESTIMATORS:
            raise ValueError(f"estimator must be one of {ESTIMATORS}, got {estimator!r}")
        shares = np.asarray(strata_shares, dtype=float)
        if shares.ndim != 1 or not np.all(np.isfinite(shares) & (shares > 0)):
            raise ValueError(f"strata_shares (share of rays per stratum) must be positive numbers, "
                             f"got {strata_shares!r}")
        background = self.complete_background(frames, background)
        budget: dict = {}
        if target_rel_stderr > 0 and len(frames):
            pilot_idx = np.unique(np.linspace(0, len(frames) - 1, min(4, len(frames))).astype(int))

            def pilot(samples: int):
                dp, _ = self.measure_changes([frames[i] for i in pilot_idx], background, samples, seed, correlated,
                                             estimator=estimator, strata_shares=strata_shares,
                                             strata_expansions=strata_expansions, guide_bounces=guide_bounces)
                return dp.irradiance_w_m2, dp.stderr_w_m2

            first = int(spp)
            spp, trail = pilot_to_target(pilot, first, target_rel_stderr, MAX_SPP)
            budget = {"pilot_spp": first, "pilot_worst_rel_stderr": trail[0]["worst_rel_stderr"],
                      "pilot_trail": trail, "target_rel_stderr": target_rel_stderr}
        self.update(background)
        if estimator == "plain":
            bg_spp = spp
            bg = self.estimates(bg_spp, seed)
        else:  # traced once per run, P = background + dP: a jittered aperture, at least BACKGROUND_MIN_SPP rays
            bg_spp = max(int(spp), BACKGROUND_MIN_SPP)
            bg = whole_aperture_estimates(self.scene, self.sensor, self.mincam, self.replicates, bg_spp,
                                          derive_seed(seed, "background"))
        columns = [f"dP_{m}" for m in self.mincam.names] + [f"P_{m}" for m in self.mincam.names]
        values = np.full((len(frames), 2 * n), np.nan)
        errors = np.full_like(values, np.nan)
        store = None
        todo = np.arange(len(frames))
        if out_dir is not None:
            identity = {"spp": int(spp), "seed": int(seed), "correlated": correlated, "replicates": self.replicates,
                        "n_frames": len(frames), "frames": _fingerprint(frames),
                        "background": _fingerprint([background]), "mincam": fingerprint(self.mincam),
                        "scene": self.content_fingerprint(), "variant": backend.variant(),
                        "versions": library_versions()}
            if estimator != "plain":
                identity.update(estimator=estimator, strata_shares=shares.tolist(),
                                strata_expansions=[float(e) for e in strata_expansions],
                                guide_bounces=bool(guide_bounces))
            store = ResultStore(out_dir, len(frames), columns, identity, overwrite=overwrite)
            values[:], errors[:] = store.values, store.stderr
            todo = store.pending()
        strata: dict = {}
        try:
            if estimator == "plain":
                self._measure_into(frames, background, todo, spp, seed, correlated, bg, values, errors, store,
                                   show_progress)
            else:
                strata = self._measure_stratified_into(frames, background, todo, spp, seed, correlated,
                                                       (shares, tuple(strata_expansions), bool(guide_bounces)), bg,
                                                       values, errors, store, show_progress)
        finally:
            if store is not None:
                store.close()
        self.update(background)

        meta = {"form": "fast_world", "estimator": estimator, **strata,
                "spp_per_mixel_per_frame": int(spp), "background_spp_per_mixel": int(bg_spp), "seed": seed,
                "correlated_seeds": correlated,
                "replicates": self.replicates, "background_w_m2": bg.mean(0).tolist(),
                "masks": {m.name: mask_model_meta(m.mask) for m in self.mincam},
                "background_stderr_w_m2": (bg.std(0, ddof=1) / np.sqrt(self.replicates)).tolist(),
                **backend.describe(), **geometry_meta(self.mincam)}
        meta.update(budget)
        reached = worst_relative_stderr(values[:, :n], errors[:, :n], significance=3.0)
        meta["reached_rel_stderr"] = reached if np.isfinite(reached) else None
        warn_target_missed(reached, target_rel_stderr, int(spp), MAX_SPP)
        names = self.mincam.names
        warn_unreached(Measurements(values[:, n:], errors[:, n:], names))
        dp = Measurements(values[:, :n], errors[:, :n], names, {**meta, "quantity": "dP = P(frame) - P(background)"})
        p = Measurements(values[:, n:], errors[:, n:], names, {**meta, "quantity": "P(frame)"})
        return dp, p

    def _measure_into(self, frames, background, todo, spp, seed, correlated, bg, values, errors, store,
                      show_progress) -> None:
        for i in progress(todo, desc="frames", disable=not show_progress):
            self.update(background)
            self.update(frames[i])
            frame_seed = seed if correlated else derive_seed(seed, "frame", int(i))
            est = self.estimates(spp, frame_seed)
            diff = est - bg
            r = self.replicates
            row_v = np.concatenate([diff.mean(0), est.mean(0)])
            row_e = np.concatenate([diff.std(0, ddof=1), est.std(0, ddof=1)]) / np.sqrt(r)
            values[i], errors[i] = row_v, row_e
            if store is not None:
                store.write([i], row_v[None], row_e[None])

    def _measure_stratified_into(self, frames, background, todo, spp, seed, correlated, strata, bg, values,
                                 errors, store, show_progress) -> dict:
        r = self.replicates
        shares, expansions, guided = strata
        check_strata([1] * len(shares), expansions)
        per_rep = -(-int(spp) // r)
        counts = [max(1, int(round(per_rep * s / shares.sum()))) for s in shares]
        moving = _moving_shapes([background, *frames])
        self.update(background)
        bg_regions = {name: self.change_regions([name]) for name in moving}
        fractions, guided_frames = [], 0
        for i in progress(todo, desc="frames", disable=not show_progress):
            changed = _changed_shapes(frames[i], background)
            self.update({**background, **frames[i]})
            regions, guide = self._change(changed)
            for name in changed:
                regions = regions.union(bg_regions[name])
            guide = guide if guided else None
            guided_frames += guide is not None and guided_path_supports(self.world.max_depth)
            frame_seed = derive_seed(seed, "stratified") if correlated else derive_seed(seed, "stratified", int(i))
            est = stratified_estimates(self.scene, self.sensor, self.mincam, regions, r, counts, frame_seed,
                                       expansions, guide=guide, max_depth=self.world.max_depth)
            self.update(background)
            bg_seed = frame_seed if correlated else derive_seed(seed, "stratified-background", int(i))
            bg_est = stratified_estimates(self.scene, self.sensor, self.mincam, regions, r, counts, bg_seed,
                                          expansions, guide=guide, max_depth=self.world.max_depth)
            diff = est - bg_est
            frame = bg + diff  # P(frame): the background traced once over the whole aperture, plus the change
            row_v = np.concatenate([diff.mean(0), frame.mean(0)])
            row_e = np.concatenate([diff.std(0, ddof=1), frame.std(0, ddof=1)]) / np.sqrt(r)
            values[i], errors[i] = row_v, row_e
            fractions.append(regions.area_fraction())
            if store is not None:
                store.write([i], row_v[None], row_e[None])
        return {"strata_expansions": list(expansions), "strata_rays_per_replicate": counts,
                "rays_per_mixel_per_frame": 2 * r * sum(counts),
                "moving_shapes": sorted(moving), "guide_bounces": bool(guided),
                "guided_frames": int(guided_frames),
                "region_area_fraction_mean": float(np.mean(fractions)) if fractions else None}

    def change_guide(self, moving: Sequence[str]) -> tuple[np.ndarray, float] | None:
        """Sphere (centre, radius [m], scene coordinates) around the named shapes, in their current place, and
        their shadow volumes: where guided bounces aim (``mincam_sim.render.guided_path``); None if unbounded."""
        return self._change(moving)[1]

    def change_regions(self, moving: Sequence[str]) -> ApertureRegions:
        """Aperture regions (per mixel) that the named shapes, in their current place, and their shadows reach:
        the bounding rectangle of each shape's own region (so that far-apart shapes, one of them out of view,
        do not make one hull spanning both); the whole aperture if one of them is unbounded."""
        return self._change(moving)[0]

    def _change(self, moving: Sequence[str]) -> tuple[ApertureRegions, tuple[np.ndarray, float] | None]:
        """:meth:`change_regions` and :meth:`change_guide` from one look at the scene."""
        points = {name: _change_points(self.scene, [name]) for name in sorted(moving)}
        if any(p is None for p in points.values()):
            return ApertureRegions.full(self.mincam), None
        regions = ApertureRegions.empty(self.mincam)
        for p in points.values():
            regions = regions.union(mixel_regions(self.scene_mincam, p))
        return regions, (guide_sphere(np.concatenate(list(points.values()))) if points else None)

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


def _change_points(scene, moving) -> np.ndarray | None:
    """Corner points whose hull holds the moving shapes and their shadow volumes [m]; None if unbounded
    (an environment light, a moving emitter, an emitter of a kind not bounded here, or a moved parameter that
    belongs to no shape)."""
    shapes = {s.id(): s for s in scene.shapes()}
    if any(name not in shapes or shapes[name].is_emitter() for name in moving):
        return None
    lights = _light_bounds(scene)
    if lights is None:
        return None

    def box(shape):
        bb = shape.bbox()
        return np.array(bb.min, dtype=float), np.array(bb.max, dtype=float)

    objects = [box(shapes[name]) for name in sorted(moving)]
    boxes, directions = lights
    boxes = boxes + [box(s) for s in scene.shapes() if s.is_emitter()]
    return change_points(objects, boxes, box(scene), directions)


def _light_bounds(scene) -> tuple[list, list] | None:
    """Where the scene's non-shape emitters shine from: point-like ones (point, spot) as zero-size boxes [m],
    directional ones by the direction their rays travel; None for an environment light or any other kind."""
    mi = backend.mitsuba()
    boxes, directions = [], []
    for emitter in scene.emitters():
        flags = int(emitter.flags())
        if flags & int(mi.EmitterFlags.Surface):
            continue  # an emitting shape: bounded by its shape's box
        if emitter.is_environment():
            return None
        params = mi.traverse(emitter)
        if flags & int(mi.EmitterFlags.DeltaDirection) and "to_world" in params:
            directions.append(np.array(params["to_world"].matrix, dtype=float).reshape(4, 4)[:3, 2])
        elif flags & int(mi.EmitterFlags.DeltaPosition) and ("position" in params or "to_world" in params):
            where = (np.array(params["position"], dtype=float).ravel() if "position" in params
                     else np.array(params["to_world"].matrix, dtype=float).reshape(4, 4)[:3, 3])
            boxes.append((where, where))
        else:
            return None
    return boxes, directions


def _fingerprint(updates: Sequence[Updates]) -> list:
    import hashlib

    h = hashlib.sha256()
    for u in updates:
        for k in sorted(u):
            h.update(k.encode())
            h.update(np.ascontiguousarray(np.asarray(u[k], dtype=np.float64)).tobytes())
    return [len(updates), h.hexdigest()[:16]]
