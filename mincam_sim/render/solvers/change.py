"""The change solvers: each frame's change from a background, ``dP = P(frame) - P(background)``, and ``P``.

A frame and its background are traced with the same seed, replicate by replicate, so the Monte Carlo noise of
the two largely cancels in their difference; the standard error of ``dP`` comes from the spread of the
per-replicate differences, so it includes that correlation.

* :class:`PlainChange` (the reference): every frame traced over the whole aperture with the background's seed;
  the background traced once.
* :class:`StratifiedChange`: per frame and mixel, the aperture region where the frame can differ from the
  background (``mincam_sim.render.kernels.change_geometry``, ``change_region``: the moving shapes' bounds and their
  shadow
  volumes from the emitting shapes, for both the frame and the background) gets most rays, the rest of the
  aperture a few, both strata unbiased (``mincam_sim.render.kernels.stratified``). The frame and the background are
  traced with the same seed, counts and regions, so their rays pair up lane by lane (several moving shapes that a
  mixel sees apart each keep a rectangle of their own, with their background places: ``change_region.RegionSet``,
  sampled by multi-sample importance sampling; one rectangle keeps the nested strata); inter-reflection bounces
  are guided toward the moving shapes (``mincam_sim.render.kernels.guided_path``); the background's whole-aperture
  value (for ``P``) is traced once per run, on a jittered aperture grid with at least
  ``BACKGROUND_MIN_SPP`` rays. Kernels are compiled once and reused. Where the moving shapes are meshes moved
  by their vertices (``mincam_sim.render.scene.static_split``) and the static shapes hold at least
  ``SPLIT_MIN_TRIANGLES`` triangles, the static geometry is a scene of its own, built once, and a frame rebuilds
  only a scene of its moving shapes; otherwise each frame costs one parameter update
  of the world for the frame and one back to the background (the run's meta ``static_geometry`` says which).

A target noise is reached by pilots: the solver's own plan on up to 4 frames spread over the run, at the
budget's rays, extrapolated by ``estimation.pilot_to_target`` (no recursion through the front door). The
stratified solver instead sizes every (frame, mixel) value itself (``StratifiedChange.allocate``, on by default):
the budget's rays and replicates are each frame's pilot part, and a mixel gets the extra replicates its own pilot
spread asks for at the target (``_StratifiedRun.allocate``), not the rays the worst value of the run needs.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import ClassVar, NamedTuple

import numpy as np

from mincam_sim.budget import Budget
from mincam_sim.changes import Changes, RunInfo
from mincam_sim.errors import InputError
from mincam_sim.frames import MemoryTable, collect
from mincam_sim.measurements import Measurements
from mincam_sim.progress import progress
from mincam_sim.render import backend
from mincam_sim.render.kernels.change_geometry import (
    MAX_FACE_PLANES,
    changed_shapes,
    delta_bsdf,
    delta_face_planes,
    drawn_parts,
    emitters_among,
    light_bounds,
    merge_parked,
    moving_shapes,
    redirects_light,
    static_box,
    watch_box,
)
from mincam_sim.render.kernels.change_region import ApertureRegions, mover_regions
from mincam_sim.render.kernels.frozen import keeps_recording
from mincam_sim.render.kernels.guided_path import supports as guided_path_supports
from mincam_sim.render.kernels.mask_eval import mask_model_meta
from mincam_sim.render.kernels.monte_carlo import (
    check_counts,
    derive_seed,
    dominance_threshold,
    heavy_tailed,
    pilot_to_target,
    warn_target_missed,
    warn_unreached,
    worst_relative_stderr,
)
from mincam_sim.render.kernels.stratified import (
    buffers_key,
    check_strata,
    frozen_recordings,
    stratified_lanes,
    whole_aperture_estimates,
)
from mincam_sim.render.scene.mincam_scene import geometry_meta
from mincam_sim.render.scene.static_split import StaticSplit, split_refusal
from mincam_sim.render.scene.world_checks import EngulfWatch
from mincam_sim.render.scene.world_input import check_frames
from mincam_sim.render.solvers.base import Plan, Row, Solver

MAX_SPP = 1 << 26  # cap of the target-noise budget, samples per mixel per frame
MAX_RAYS_PER_REPLICATE = 1 << 25  # stratified: a replicate's rays of a mixel are one launch (Dr.Jit: < 2^32 lanes)
STRATA_EXPANSIONS = (1.0, 2.0, 4.0, 8.0)  # nested rectangles: the change region, then scaled about its centre
STRATA_SHARES = (0.6, 0.1, 0.1, 0.1, 0.1)  # rays per stratum (region, rings, rest): near Neyman, guided, bench scene
BACKGROUND_MIN_SPP = 1 << 16  # stratified: rays per mixel (at least) for the background's whole-aperture value
RETRY_FACTOR = 4  # a frame whose replicates are heavy-tailed is measured again with this many times the replicates
SPLIT_MIN_TRIANGLES = 10_000  # static split by default from these static triangles (rebuilt: ~0.65 us a triangle)
DEFAULT_REPLICATES = 8
ALLOCATION_MAX_FACTOR = 4  # per-mixel allocation: a value gets at most this many times the pilot's replicates
ALLOCATION_SIGNIFICANCE = 4.0  # |dP| under this many pilot sigmas: the value is not sized (it gets the floor)
ALLOCATION_PILOT_REPLICATES = 24  # per-mixel allocation, a budget naming no replicates: each frame's pilot part
ALLOCATION_PILOT_SPP = 24 * 180  # ... and naming no spp: its rays per mixel per pass (180 per replicate)
ALLOCATION_SIGMA = ("pilot", "independent", "pooled")  # where a per-mixel allocated value's sigma comes from
# per frame, kept with the results
INFO_COLUMNS = ("retried", "guided", "guide_spheres", "region_area_fraction", "rays_per_mixel")
Updates = Mapping[str, np.ndarray]


class Target(NamedTuple):
    """What a solver that sizes each (frame, mixel) value itself aims at."""

    rel_stderr: float = 0.0  # relative standard error of dP (0: none; the counts as given)
    max_spp: int = MAX_SPP  # rays per mixel per pass at most


NO_TARGET = Target()

class FallbackWarning(UserWarning):
    """The stratified estimator could not bound a change (a moving emitter or light, an environment light, a
    parameter of no shape) or guide its bounces, and fell back to a costlier, still unbiased, sampling."""


class HeavyTailWarning(UserWarning):
    """A measurement's replicates are dominated by one of them (a rare, heavy light path): its standard error is
    itself uncertain. The frame was measured again with more replicates; this warns of what stayed so."""


@dataclass(frozen=True)
class ChangeSolver(Solver):
    """A solver of changes against a background (world scenes).

    Parameters
    ----------
    correlated : bool
        True: each frame is traced with the background's seed (noise cancels in dP). False: independent seeds.
    """

    correlated: bool = True
    scenes: ClassVar[tuple[str, ...]] = ("world",)
    changes: ClassVar[bool] = True

    def run(self, sim, frames, background, spp: int, seed: int, replicates: int, bg: np.ndarray,
            target: Target = NO_TARGET) -> _Run:
        """The per-frame machinery of one run at ``spp`` rays per pass (the background's estimates ``bg``); a
        solver that sizes each value itself aims at ``target``."""
        raise NotImplementedError

    def background_estimates(self, sim, spp: int, seed: int, replicates: int) -> tuple[int, np.ndarray]:
        """(rays per mixel, (replicates, n_mixels) estimates) of the background, traced once per run."""
        raise NotImplementedError

    def plan(self, sim, frames, budget: Budget, *, background=None, cache=None, show_progress: bool = False) -> Plan:
        background = {} if background is None else background
        replicates = budget.replicates_or(self.default_replicates(budget))
        self._check(frames, background, budget.rays(), replicates, budget.target_rel_stderr)
        background = sim.complete_background(frames, background)
        spp, resolved = self._resolve_spp(sim, frames, background, budget, replicates)
        return ChangePlan(self, sim, frames, background, replace(budget, spp=spp), replicates, resolved,
                          show_progress)

    def allocates(self, budget: Budget) -> bool:
        """True if this solver sizes each (frame, mixel) value's replicates itself to the budget's target."""
        return False

    def default_replicates(self, budget: Budget) -> int:
        """Replicates when the budget names none."""
        return ALLOCATION_PILOT_REPLICATES if self.allocates(budget) else DEFAULT_REPLICATES

    def _check(self, frames, background, spp, replicates, target) -> None:
        """Refuse, in one line each, what a change run cannot honestly measure."""
        check_frames(frames, background)
        try:
            check_counts(spp, replicates)
        except ValueError as exc:
            raise InputError(str(exc)) from None
        if int(spp) < replicates:
            raise InputError(f"spp = {spp} rays per mixel per frame is fewer than the {replicates} replicates "
                             "(each replicate needs rays of its own); raise spp or lower replicates")

    def _resolve_spp(self, sim, frames, background, budget: Budget, replicates: int) -> tuple[int, dict]:
        """The budget's rays, or (target > 0) the count the pilots extrapolate (``estimation.pilot_to_target``
        on up to 4 frames spread over the run), with the pilots' trail."""
        spp, target = budget.rays(), budget.target_rel_stderr
        if not target > 0 or not len(frames):
            return spp, {}
        if self.allocates(budget):  # sized per mixel and frame by the run itself, from each frame's pilot part
            return (budget.spp if budget.spp is not None else ALLOCATION_PILOT_SPP), {"target_rel_stderr": target}
        pilot_idx = np.unique(np.linspace(0, len(frames) - 1, min(4, len(frames))).astype(int))
        pilot_frames = [frames[i] for i in pilot_idx]

        def pilot(samples: int):
            with warnings.catch_warnings():  # a pilot's fallbacks are said by the run itself
                warnings.simplefilter("ignore", FallbackWarning)
                warnings.simplefilter("ignore", HeavyTailWarning)
                plan = ChangePlan(self, sim, pilot_frames, background, replace(budget, spp=int(samples)), replicates,
                                  {}, False)
                table = MemoryTable(plan.n_rows, len(plan.columns))
                ch = plan.result(*collect(plan.rows(table.pending()), table))
            return ch.dp.irradiance_w_m2, ch.dp.stderr_w_m2

        resolved, trail = pilot_to_target(pilot, spp, target, budget.max_spp or MAX_SPP)
        return int(resolved), {"pilot_spp": spp, "pilot_worst_rel_stderr": trail[0]["worst_rel_stderr"],
                               "pilot_trail": trail, "target_rel_stderr": target}


@dataclass(frozen=True)
class PlainChange(ChangeSolver):
    """dP with whole-aperture rays per frame, traced with the background's seed (the reference)."""

    name: ClassVar[str] = "plain_change"

    def background_estimates(self, sim, spp, seed, replicates):
        return spp, sim.mincam_scene.fast_estimates(spp, replicates, seed)

    def run(self, sim, frames, background, spp, seed, replicates, bg, target=NO_TARGET):
        return _PlainRun(sim, background, spp, seed, self.correlated, replicates, bg)


@dataclass(frozen=True)
class StratifiedChange(ChangeSolver):
    """dP with most rays in the aperture region the frame's moving shapes, their shadows and their mirror
    images can reach; every stratum unbiased, frame and background paired ray by ray, bounces guided.

    Parameters
    ----------
    strata_shares : sequence of float
        Share of rays per stratum (region, each ring, rest), positive.
    strata_expansions : sequence of float
        Scale factors of the nested rectangles about the region's centre, from 1 (one fewer than the shares).
    guide_bounces : bool
        Draw half the inter-reflection bounces toward spheres around the moving shapes
        (``mincam_sim.render.kernels.guided_path``; unbiased). Ignored at a ``max_depth`` the guided path does not
        cover.
    allocate : bool
        With a budget's ``target_rel_stderr``: size each (frame, mixel) value's replicates to the target from the
        frame's own first ``replicates`` (the pilot part: the budget's spp and replicates, by default
        ``ALLOCATION_PILOT_SPP`` and ``ALLOCATION_PILOT_REPLICATES``), up to ``ALLOCATION_MAX_FACTOR`` times them,
        instead of every value at the rays the worst needs (``_StratifiedRun.allocate``; no pilot runs). Only on
        the guided path (frames whose rays are not guided keep the pilot part). False: the pilot runs size the
        whole run by its worst value, as before.
    allocation_sigma : str
        Where an allocated value's sigma comes from (the mean always pools all its replicates): ``"pilot"``
        (default) the pilot's spread over sqrt(all its replicates), Stein's two-stage: for Gaussian replicates
        (dP - true) / sigma is exactly Student's t with R0 - 1 degrees of freedom, and a sized value's sigma sits
        near the target by construction; ``"independent"`` the spread of the replicates traced after the
        decision only (every value gets at least half the pilot's count more), unbiased whatever the pilot drew,
        but with fewer degrees of freedom (a noisier sigma); ``"pooled"`` the spread of all its replicates, pilot
        included (biased low by a few percent: values whose pilot spread came out large get more replicates,
        which dilute it).
    correlated : bool
        As ``ChangeSolver``.
    """

    strata_shares: Sequence[float] = STRATA_SHARES
    strata_expansions: Sequence[float] = STRATA_EXPANSIONS
    guide_bounces: bool = True
    allocate: bool = True
    allocation_sigma: str = "pilot"
    name: ClassVar[str] = "stratified_change"

    def allocates(self, budget: Budget) -> bool:
        return bool(self.allocate) and budget.target_rel_stderr > 0

    def identity(self) -> dict:
        # the allocation options at their defaults leave the identity of stores written before them as it was
        # (a store of a target run before them has no replicate columns, and is refused for that)
        out = super().identity()
        for name, default in (("allocate", True), ("allocation_sigma", "pilot")):
            if out.get(name) == default:
                out.pop(name)
        return out

    def _check(self, frames, background, spp, replicates, target) -> None:
        super()._check(frames, background, spp, replicates, target)
        per = -(-int(spp) // int(replicates))
        if per > MAX_RAYS_PER_REPLICATE:
            raise InputError(f"spp = {spp} with {replicates} replicates traces {per} rays per replicate, and a "
                             f"replicate's rays are one launch: at most {MAX_RAYS_PER_REPLICATE} "
                             f"(2^{MAX_RAYS_PER_REPLICATE.bit_length() - 1}, its memory); raise replicates to "
                             f"{-(-int(spp) // MAX_RAYS_PER_REPLICATE)} or more, or lower spp")
        self.shares()
        if self.allocation_sigma not in ALLOCATION_SIGMA:
            raise InputError(f"allocation_sigma (where an allocated value's sigma comes from) must be one of "
                             f"{ALLOCATION_SIGMA}, got {self.allocation_sigma!r}")

    def shares(self) -> np.ndarray:
        """The shares as an array, after refusing (naming ``strata_shares`` / ``strata_expansions``, the fields
        a user gives) what the strata cannot use."""
        try:
            shares = np.asarray(self.strata_shares, dtype=float)
            expansions = np.asarray(self.strata_expansions, dtype=float)
        except (TypeError, ValueError):
            raise InputError(f"strata_shares and strata_expansions must be sequences of numbers, got "
                             f"{self.strata_shares!r} and {self.strata_expansions!r}") from None
        if shares.ndim != 1 or not np.all(np.isfinite(shares) & (shares > 0)):
            raise InputError(f"strata_shares (share of rays per stratum) must be positive numbers, "
                             f"got {self.strata_shares!r}")
        if expansions.ndim != 1 or not len(expansions) or expansions[0] != 1.0 or np.any(np.diff(expansions) <= 0):
            raise InputError(f"strata_expansions (scale factors of the nested rectangles) must start at 1 and grow, "
                             f"got {self.strata_expansions!r}")
        if len(shares) != len(expansions) + 1:
            raise InputError(f"strata_shares needs {len(expansions) + 1} shares (one per strata_expansions entry, "
                             f"{len(expansions)}, plus one for the rest of the aperture), got {len(shares)}: "
                             f"{self.strata_shares!r}")
        return shares

    def background_estimates(self, sim, spp, seed, replicates):
        # traced once per run, P = background + dP: a jittered aperture, at least BACKGROUND_MIN_SPP rays
        bg_spp = max(spp, BACKGROUND_MIN_SPP)
        return bg_spp, whole_aperture_estimates(sim.scene, sim.sensor, sim.mincam, replicates, bg_spp,
                                                derive_seed(seed, "background"))

    def run(self, sim, frames, background, spp, seed, replicates, bg, target=NO_TARGET):
        run = _StratifiedRun(sim, frames, background, spp, seed, self.correlated, replicates, self.shares(),
                             tuple(self.strata_expansions), bool(self.guide_bounces), bg)
        if self.allocate and target.rel_stderr > 0:
            run.allocate(float(target.rel_stderr), int(target.max_spp), str(self.allocation_sigma))
        return run


class ChangePlan(Plan):
    """One change run at the budget's ``spp`` rays per pass (the target already resolved): the background traced
    once, then a row per frame (dP and P per mixel, then heavy-tailed and unseen flags per mixel and
    ``INFO_COLUMNS``, then, where replicates are allocated per mixel, the replicates traced per mixel)."""

    def __init__(self, solver: ChangeSolver, sim, frames, background, budget: Budget, replicates: int,
                 resolved: dict, show_progress: bool) -> None:
        self.solver, self.sim, self.frames, self.background = solver, sim, frames, background
        self.spp, self.seed, self.replicates, self.resolved = budget.rays(), budget.seed, replicates, resolved
        self.target, self.show_progress = budget.target_rel_stderr, show_progress
        self.cap = budget.max_spp or MAX_SPP
        sim.update(background)
        self.bg_spp, self.bg = solver.background_estimates(sim, self.spp, self.seed, replicates)
        self.run = solver.run(sim, frames, background, self.spp, self.seed, replicates, self.bg,
                              Target(self.target or 0.0, self.cap))
        self.run.note_delta_movers(moving_shapes([background, *frames]))
        # the world scene holds the background here: a moved shape closed round a mixel there is said too
        self.run.watch(sim.scene, sim.shapes_by_id, moving_shapes([background]), "the background")
        names = sim.mincam.names
        self.n_rows = len(frames)
        self.columns = ([f"dP_{m}" for m in names] + [f"P_{m}" for m in names]
                        + [f"heavy_tailed_{m}" for m in names] + [f"unseen_{m}" for m in names] + list(INFO_COLUMNS)
                        + ([f"replicates_{m}" for m in names] if self.run.per_mixel_replicates else []))

    def rows(self, pending: np.ndarray) -> Iterator[Row]:
        # one row per frame: dP and P, then the flags and info (no standard error of their own)
        for i, row_v, row_e, info in self.run.rows(self.frames, pending, self.show_progress):
            yield [i], np.concatenate([row_v, info])[None], np.concatenate([row_e, np.zeros_like(info)])[None]

    def result(self, values: np.ndarray, errors: np.ndarray) -> Changes:
        """(dP, P) with the reached noise in their meta and the run's ``RunInfo``, the warnings said."""
        sim, run, bg = self.sim, self.run, self.bg
        sim.update(self.background)
        n, names = len(sim.mincam), sim.mincam.names
        meta = {"form": "fast_world", "solver": self.solver.name,
                **run.meta(values[:, 2 * n:]),
                "spp_per_mixel_per_frame": self.spp, "background_spp_per_mixel": int(self.bg_spp), "seed": self.seed,
                "correlated_seeds": self.solver.correlated, "replicates": self.replicates,
                "background_w_m2": bg.mean(0).tolist(), "masks": {m.name: mask_model_meta(m.mask) for m in sim.mincam},
                "background_stderr_w_m2": (bg.std(0, ddof=1) / np.sqrt(self.replicates)).tolist(),
                **backend.describe(), **geometry_meta(sim.mincam), **sim.world_meta(), **self.resolved}
        reached = worst_relative_stderr(values[:, :n], errors[:, :n], significance=3.0)
        meta["reached_rel_stderr"] = reached if np.isfinite(reached) else None
        meta["target_rel_stderr"] = self.target
        alloc = meta.get("allocation")
        warn_target_missed(reached, self.target, self.spp, self.cap,
                           None if not alloc else
                           f"per-mixel allocation: sigma's own noise, or values at the most replicates, "
                           f"{alloc['max_replicates']}; see meta['allocation']")
        run.warn(meta)
        warn_unreached(Measurements(values[:, n:2 * n], errors[:, n:2 * n], names))
        dp = Measurements(values[:, :n], errors[:, :n], names, {**meta, "quantity": "dP = P(frame) - P(background)"})
        p = Measurements(values[:, n:2 * n], errors[:, n:2 * n], names, {**meta, "quantity": "P(frame)"})
        info = RunInfo(
            solver=self.solver.name, seed=int(self.seed), replicates=int(self.replicates),
            rays_per_mixel_per_frame=int(meta["rays_per_mixel_per_frame"]), spp_per_mixel_per_frame=self.spp,
            target_rel_stderr=float(self.target), reached_rel_stderr=meta["reached_rel_stderr"],
            retried_frames=tuple(int(i) for i in meta["retried_frames"]),
            heavy_tailed=tuple((int(i), int(k)) for i, k in meta["heavy_tailed"]),
            fallbacks=tuple(meta["fallbacks"]), guided_frames=meta.get("guided_frames"),
            launches=meta.get("launches"))
        return Changes(dp, p, info)


def _unseen(diff: np.ndarray, changes: np.ndarray) -> np.ndarray:
    """(n_mixels,) True where a frame changes a shape but every replicate of its dP is the same (no ray met it);
    replicates not traced (NaN) left out."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return changes & (np.nanmax(diff, axis=0) == np.nanmin(diff, axis=0))


def _heavy_tailed(diff: np.ndarray, pilot: int) -> np.ndarray:
    """``heavy_tailed`` per mixel; where replicates were allocated per mixel (NaN where not traced), on the first
    ``pilot`` replicates and, apart, on each mixel's replicates after them (3 or more)."""
    if not np.isnan(diff).any():
        return heavy_tailed(diff)
    flags = heavy_tailed(diff[:pilot])
    for k, col in enumerate(diff[pilot:].T):
        more = col[~np.isnan(col)]
        if len(more) >= 3:
            dev2 = (more - more.mean()) ** 2
            total = dev2.sum()
            flags[k] |= total > 0 and dev2.max() / total > dominance_threshold(len(more))
    return flags


def pooled_mean_stderr(diff: np.ndarray, sigma_rows: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per mixel (column of ``diff``, (R, n) replicates, NaN where not traced): the mean of the replicates
    traced and its standard error, ``s / sqrt(R_k)`` with ``R_k`` the replicates traced and ``s`` the spread
    (ddof 1) of those in ``sigma_rows`` ((R, n) bool; None: all traced)."""
    traced = ~np.isnan(diff)
    if sigma_rows is None and traced.all():  # every replicate traced: as a plain mean and spread
        return diff.mean(0), diff.std(0, ddof=1) / np.sqrt(diff.shape[0])
    count = traced.sum(axis=0)
    mean = np.where(traced, diff, 0.0).sum(axis=0) / count
    rows = traced if sigma_rows is None else traced & sigma_rows
    k = rows.sum(axis=0)
    centre = np.where(rows, diff, 0.0).sum(axis=0) / k
    var = np.where(rows, (diff - centre) ** 2, 0.0).sum(axis=0) / (k - 1)
    return mean, np.sqrt(var / count)


def allocate_replicates(pilot: np.ndarray, target: float, floor: int, most: int,
                        significance: float = ALLOCATION_SIGNIFICANCE) -> np.ndarray:
    """(n,) replicates per mixel sized from its pilot replicates ``pilot`` (R0, n) of dP.

    ``R_k = clip(ceil(R0 (s_k / target)^2), floor, most)`` with ``s_k`` the pilot's relative standard error of
    the mean (its spread / sqrt(R0) / |mean|): the replicates at which the value's relative sigma is the target.
    A value whose pilot mean is insignificant (``|mean| < significance x`` its standard error, zero spread
    included: no ray met a change) is not sized: it gets ``floor``."""
    r0 = pilot.shape[0]
    mean = pilot.mean(axis=0)
    err = pilot.std(axis=0, ddof=1) / np.sqrt(r0)
    significant = (err > 0) & (np.abs(mean) >= significance * err)
    with np.errstate(divide="ignore", invalid="ignore"):
        need = np.ceil(r0 * (err / np.abs(mean) / target) ** 2)
    need = np.where(significant & np.isfinite(need), need, floor)
    return np.clip(need, floor, most).astype(int)


class _Run:
    """The frames of one ``measure_changes`` run: per-frame replicate estimates, the heavy-tail check and its
    retry, and what the run says about itself (per-frame info kept with the results, so that a resumed run
    reports every frame; meta and warnings)."""

    def __init__(self, sim, background: Updates, spp: int, seed: int, correlated: bool, replicates: int,
                 bg: np.ndarray) -> None:
        self.r, self.background, self.spp, self.seed, self.correlated = sim, background, spp, seed, correlated
        self.replicates = replicates
        self.bg = bg
        self.fallbacks: dict[str, str] = {}
        self.sigma_rows: np.ndarray | None = None  # the last frame's replicates whose spread gives sigma (None: all)
        self.per_mixel_replicates = False  # replicates allocated per mixel: a column of them per mixel
        self.engulf = EngulfWatch(sim.scene_mincam, sim.known_parts)  # a shape closing round a mixel: said once

    def watch(self, scene, shapes: Mapping, names, where: str) -> None:
        """Check the shapes ``names`` (of ``shapes``, by id, as ``scene`` has them now) for one that closes round
        a mixel (:class:`~mincam_sim.render.scene.world_checks.EngulfWatch`)."""
        self.engulf.check(scene, [shapes[name] for name in sorted(names) if name in shapes], where)

    def note_delta_movers(self, moving) -> None:
        """Say it when a moving shape is glass or a mirror (a delta BSDF) whose redirected light is not guided:
        the light it refracts or reflects onto the rest of the scene is then found only by delta bounces drawn
        as the BSDF draws them, and a run that draws none of those rare heavy paths reports too small a sigma
        (on a glass block in view, ~10x in one run of 32), which no diagnostic inside one run can see."""
        shapes = self.r.shapes_by_id
        for name in sorted(moving):
            if (name in shapes and redirects_light(self.r.scene, shapes[name], self.r.known_parts)
                    and not self.guides_through(name)):
                self.fallbacks[f"delta:{name}"] = (
                    f"'{name}' is glass or a mirror (or an instance of one) and moves, and is curved, a mirror, an "
                    "instance or not guided: the light it refracts or reflects onto the scene is found only by delta "
                    "bounces not aimed at it, so one run's sigma can be too small when it draws none of those rare "
                    "paths; raise the replicates or compare a few seeds")

    def guides_through(self, name: str) -> bool:
        """True if the bounces of this run are guided through the moving delta shape ``name``."""
        return False

    def rows(self, frames, todo, show_progress: bool):
        """(frame index, values, stderr, info) per frame of ``todo``: dP then P per mixel; then heavy-tailed and
        unseen flags per mixel, ``INFO_COLUMNS`` and (allocated per mixel) the replicates traced per mixel."""
        n = len(self.r.mincam)
        for i in progress(todo, desc="frames", disable=not show_progress):
            i = int(i)
            diff, frame_v, frame_e, changes, info = self.frame(frames, i, self.replicates, "")
            retried = bool((_heavy_tailed(diff, self.replicates) | _unseen(diff, changes)).any())
            heavy = unseen = np.zeros(n, dtype=bool)
            if retried:
                diff, frame_v, frame_e, changes, _ = self.frame(frames, i, RETRY_FACTOR * self.replicates, "retry")
                heavy, unseen = _heavy_tailed(diff, RETRY_FACTOR * self.replicates), _unseen(diff, changes)
            mean, err = pooled_mean_stderr(diff, self.sigma_rows)
            row_v = np.concatenate([mean, frame_v])
            row_e = np.concatenate([err, frame_e])
            reps = (~np.isnan(diff)).sum(axis=0) if self.per_mixel_replicates else []  # replicates traced per mixel
            yield i, row_v, row_e, np.concatenate([heavy, unseen, [retried, *info], reps]).astype(float)

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
        spp = self.spp * replicates // self.replicates
        r.update(self.background)
        bg = (self.bg if replicates == self.replicates and not purpose
              else r.mincam_scene.fast_estimates(spp, replicates, frame_seed))
        r.update(frames[i])
        changed = changed_shapes(frames[i], self.background)
        if not purpose:
            self.watch(r.scene, r.shapes_by_id, changed, f"frame {i}")
        est = r.mincam_scene.fast_estimates(spp, replicates, frame_seed)
        changes = np.full(len(r.mincam), bool(changed))
        info = (0.0, 0.0, 1.0, float(self.spp))  # not guided, no guide sphere, the whole aperture, its rays
        return est - bg, est.mean(0), est.std(0, ddof=1) / np.sqrt(replicates), changes, info

    def meta(self, info: np.ndarray) -> dict:
        return {**super().meta(info), "rays_per_mixel_per_frame": int(self.spp)}


class _StratifiedRun(_Run):
    """Most rays in the aperture region the frame's change reaches; frame and background paired lane by lane."""

    def __init__(self, sim, frames, background, spp, seed, correlated, replicates, shares, expansions, guided, bg):
        super().__init__(sim, background, spp, seed, correlated, replicates, bg)
        check_strata([1] * len(shares), expansions)
        self.expansions, self.guided = expansions, guided
        per_rep = -(-int(spp) // replicates)
        self.counts = [max(1, int(round(per_rep * s / shares.sum()))) for s in shares]
        self.moving = moving_shapes([background, *frames])
        sim.update(background)
        self.bg_regions = {}
        for name, (regions, why) in sim.change_regions_each(self.moving).items():
            self.bg_regions[name] = regions
            if why:
                self.note_fallback(name, why)
        self.can_guide = guided and guided_path_supports(sim.mincam_scene.max_depth)
        self.shapes = sim.shapes_by_id
        self.bg_boxes = {name: watch_box(self.shapes[name]) for name in self.moving if name in self.shapes}
        lights_move = emitters_among(sim.scene, self.moving)
        # a path that crosses no moving shape's box (in either place) is the same path in both passes
        self.pairs = (sim.pair_lanes and correlated and self.can_guide and not lights_move
                      and set(self.bg_boxes) == self.moving)
        # background places outside the static shapes' box (parked movers) watched as one box (same numbers)
        self.keep_clear = static_box(sim.scene, self.moving) if self.pairs else None
        self.freeze = sim.freeze_launches and not lights_move
        self.launches = ("frozen" if self.freeze else
                         "traced" + (": a moving shape emits light" if sim.freeze_launches else ""))
        self.traversals: dict = {}  # the split copies' mi.traverse, kept for buffers_key over the run
        self.split, self.static_geometry = self._split(sim, frames, background)
        self.recordings_at_start = self._recordings()
        self.frames_traced = 0
        self.target, self.cap, self.allocation_sigma = 0.0, MAX_SPP, "pilot"
        if guided and not self.can_guide:
            self.fallbacks["depth"] = (f"bounces are not guided at max_depth {sim.mincam_scene.max_depth} (the "
                                       "guided path covers 1 .. 5): rays follow Mitsuba's path")

    def allocate(self, target: float, cap: int, sigma: str) -> None:
        """Size each (frame, mixel) value's replicates to ``target`` (relative sigma of dP), at most ``cap`` rays
        per mixel per pass, its sigma from ``sigma`` (``StratifiedChange.allocation_sigma``).

        Per frame, every mixel first gets the run's ``replicates`` (R0, the pilot part), frame and background
        paired as always; from their spread each mixel's count ``R_k`` (:func:`allocate_replicates`, between the
        floor ``R0 + extra_floor(R0)`` and :meth:`allocation_layout`); then only the replicates ``R0 .. R_k - 1``
        of the mixels that need them are traced (background pass first, the scene being there, then the frame's,
        paired the other way round). Launches are laid out for the most replicates, so a replicate draws the same
        numbers whichever pass traces it. A value whose pilot |dP| is under ``ALLOCATION_SIGNIFICANCE`` pilot
        sigmas gets the floor. The mean pools all ``R_k`` replicates; sigma, with ``"pilot"``, is the pilot's
        spread over sqrt(R_k) (Stein's two-stage), with ``"independent"`` the spread of the replicates traced
        after the decision only (unbiased: their number is fixed before they are drawn) over sqrt(R_k), with
        ``"pooled"`` the spread of all of them."""
        self.target, self.cap, self.allocation_sigma = target, cap, sigma
        self.per_mixel_replicates = True

    def extra_floor(self, replicates: int) -> int:
        """Replicates every allocated value gets beyond the pilot's: half the pilot's (at least 2) when its sigma
        comes from them alone, else none."""
        return max(2, replicates // 2) if self.allocation_sigma == "independent" else 0

    def allocation_layout(self, replicates: int) -> int:
        """The most replicates an allocated value gets (the launch layout): ``ALLOCATION_MAX_FACTOR`` times the
        pilot's, at most the cap's rays, at least the floor."""
        most = min(ALLOCATION_MAX_FACTOR * replicates, int(self.cap) // max(1, sum(self.counts)))
        return max(replicates + self.extra_floor(replicates), most)

    def _split(self, sim, frames, background) -> tuple[StaticSplit | None, str]:
        """The run's static / movers split (static geometry built once) and what the run's meta says of it, or
        None and why the world scene is updated per frame instead."""
        mode = getattr(sim, "split_static", False)
        if mode is False:
            return None, "one scene, updated per frame: the split is switched off"
        if not self.can_guide:
            return None, "one scene, updated per frame: bounces are not guided (the split traces the guided path)"
        why = split_refusal(sim.scene, self.moving, [background, *frames])
        if not why and light_bounds(sim.scene)[0] is None:
            why = "a light of a kind the change regions do not bound"
        if not why and mode is None:
            triangles = sum(int(shape.primitive_count()) for shape in sim.scene.shapes()
                            if shape.id() not in self.moving)
            if triangles < SPLIT_MIN_TRIANGLES:
                why = (f"the static shapes hold {triangles} triangles, fewer than {SPLIT_MIN_TRIANGLES} (their rebuild "
                       "costs less than tracing a second scene)")
        if why:
            return None, f"one scene, updated per frame: {why}"
        # kept with the simulation while no parameter but the movers' vertices changes: a run over the same
        # shapes reuses the static scene and the frozen launches recorded on the split
        positions = {f"{name}.vertex_positions" for name in self.moving}
        key = (frozenset(self.moving), tuple(sorted((k, n) for k, n in sim.revisions.items() if k not in positions)))
        split = sim.static_splits.get(key)
        built = split is None
        if built:
            sim.static_splits.clear()  # one kept: another's static scene may hold a million triangles as well
            split = sim.static_splits[key] = StaticSplit(sim.scene, self.moving)
        self.background_movers = sim.scene_updates({k: v for k, v in background.items() if k in positions})
        split.move(self.background_movers)
        return split, ("split: the static shapes in a scene built " + ("for this run" if built else "by an earlier "
                       "run") + ", the moving meshes in a scene of their own, rebuilt per pass")

    def _recordings(self) -> int:
        """Recordings of the frozen launches of the scenes this run traces."""
        count = frozen_recordings(self.r.scene)
        if self.split is not None:
            count += frozen_recordings(self.split.scene)
        return count

    def guides_through(self, name: str) -> bool:
        """A moving glass or mirror mesh with at most ``MAX_FACE_PLANES`` face planes (a block, a slab, a prism; or
        an instance of a group of such meshes: its planes under the instance's ``to_world``), with bounces guided:
        they are aimed at the lights and at the lights' images in its faces, and smooth glass draws reflection and
        refraction with even odds (``mincam_sim.render.kernels.guided_path``), so the light it throws is found in
        every run. Curved glass and moving mirrors are not (only the lights guide there).
        """
        mi = backend.mitsuba()
        shape = self.shapes.get(name)
        if not self.can_guide or shape is None:
            return False
        glass = int(mi.BSDFFlags.DeltaReflection) | int(mi.BSDFFlags.DeltaTransmission)
        parts = [part for part in drawn_parts(self.r.scene, shape, self.r.known_parts) if delta_bsdf(part)]
        planes = delta_face_planes(self.r.scene, shape, self.r.known_parts)
        return (bool(parts) and all(int(part.bsdf().flags()) & glass == glass for part in parts)
                and all(planes) and 0 < sum(len(p) for p in planes) <= MAX_FACE_PLANES)

    def note_fallback(self, name: str, reason: str) -> None:
        self.fallbacks.setdefault(name, f"{reason}; the stratified estimator samples the whole aperture and does not "
                                        "guide bounces in frames that move it (unbiased, but about as noisy as the "
                                        "plain estimator at the same rays)")

    def frame(self, frames, i: int, replicates: int, purpose: str):
        r = self.r
        changed = changed_shapes(frames[i], self.background)

        def to_frame():  # split: the world scene stays at the background; the movers scene moves
            if self.split is None:
                r.update({**self.background, **frames[i]})
            else:
                self.split.move(r.scene_updates({**self.background, **frames[i]}))

        def to_background():
            if self.split is None:
                r.update(self.background)
            else:
                self.split.move(self.background_movers)

        to_frame()
        if not purpose:
            if self.split is None:
                self.watch(r.scene, self.shapes, changed, f"frame {i}")
            else:
                self.watch(self.split.scene, self.split.copies, changed, f"frame {i}")
        each, guide, why = r.change_reach_each(changed, scene=None if self.split is None else self.split.view)
        for reason in why:
            self.note_fallback(next(iter(sorted(changed))), reason)
        # a rectangle per mover and per mover's background place, where a mixel sees two or more apart; else the
        # one rectangle that holds them all, sampled with nested strata
        apart = None if why or not changed else mover_regions(each + [self.bg_regions[n] for n in sorted(changed)])
        if apart is not None and apart.n_regions > 1:
            regions = apart
        else:
            regions = ApertureRegions.empty(r.mincam)
            for part in each:
                regions = regions.union(part)
            for name in changed:
                regions = regions.union(self.bg_regions[name])
        guide = guide if self.can_guide else None
        frame_seed = (derive_seed(self.seed, "stratified") if self.correlated
                      else derive_seed(self.seed, "stratified", i))
        if purpose:
            frame_seed = derive_seed(frame_seed, purpose, i)
        kw = {"expansions": self.expansions, "guide": guide, "max_depth": r.mincam_scene.max_depth}
        # split: the static scene with the movers where the frame has them, then where the background has them
        # a frame that changes nothing (no guide) is the background, which the world scene holds
        split = self.split is not None and guide is not None
        if self.split is not None and guide is None and changed:  # split_refusal lets no unbounded change through
            raise RuntimeError(f"frame {i}: a split run met an unbounded change of {sorted(changed)}: {why}")
        shapes = self.split.copies if split else self.shapes
        watch = None
        if self.pairs and guide is not None:
            watch = [watch_box(shapes[name]) for name in sorted(changed)]
            watch += merge_parked([self.bg_boxes[name] for name in sorted(changed)], self.keep_clear)
        scene = self.split.scene if split else r.scene
        allocating = self.target > 0 and guide is not None  # groups are traced on the guided path only
        layout = self.allocation_layout(replicates) if allocating else replicates
        pilot = None
        if allocating:
            pilot = np.zeros((layout, len(r.mincam)), dtype=bool)
            pilot[:replicates] = True
        bg_seed = frame_seed if self.correlated else derive_seed(self.seed, "stratified-background", i, purpose)

        def trace(seed, groups, first=None):
            """One pass over the scene as it stands: watching the boxes, or paired to the ``first`` pass."""
            pairing = {"watch": watch} if first is None else {"pair": first if watch is not None else None}
            return stratified_lanes(scene, r.sensor, r.mincam, regions, layout, self.counts, seed,
                                    freeze=self._freeze_key(), groups=groups, **pairing, **kw)

        lanes = trace(frame_seed, pilot)
        to_background()
        bg_lanes = trace(bg_seed, pilot, first=lanes)
        diff = lanes.estimates() - bg_lanes.estimates()
        traced = lanes.traced + bg_lanes.traced
        self.sigma_rows = None
        if allocating:
            want = allocate_replicates(diff[:replicates], self.target, replicates + self.extra_floor(replicates),
                                       layout)
            rows = np.arange(layout)[:, None]
            extra = (rows >= replicates) & (rows < want[None, :])
            if self.allocation_sigma == "independent":
                self.sigma_rows = extra
            elif self.allocation_sigma == "pilot":  # Stein's two-stage: the pilot's spread, the mean of all
                self.sigma_rows = np.broadcast_to(rows < replicates, extra.shape)
            if extra.any():
                # the scene holds the background now: its pass first (watching the boxes), then the frame's
                bg_more = trace(bg_seed, extra)
                to_frame()
                more = trace(frame_seed, extra, first=bg_more)
                # the scene stays at the frame: the next frame (or a retry) sets every moving parameter before it
                # reads or traces anything, and the run's result restores the background (one update less)
                diff = np.where(extra, more.estimates() - bg_more.estimates(), diff)
                traced += more.traced + bg_more.traced
        if not purpose:
            self.frames_traced += 1
            self._check_recordings()
        info = (float(guide is not None), 0.0 if guide is None else float(len(guide)),
                float(np.mean(regions.area_fraction())), traced / len(r.mincam))
        # per replicate only where the change's replicates pair with the background's (every mixel all of them,
        # the spread taken over all): an allocated frame pools per mixel (every mixel may reach the maximum)
        if self.sigma_rows is None and diff.shape[0] == self.bg.shape[0] and not np.isnan(diff).any():
            frame = self.bg + diff  # P(frame): the background traced once over the whole aperture, plus the change
            frame_v, frame_e = frame.mean(0), frame.std(0, ddof=1) / np.sqrt(replicates)
        else:  # the background and the change are independent estimates
            mean, err = pooled_mean_stderr(diff, self.sigma_rows)
            frame_v = self.bg.mean(0) + mean
            frame_e = np.hypot(self.bg.std(0, ddof=1) / np.sqrt(self.bg.shape[0]), err)
        changes = np.full(len(r.mincam), bool(changed))
        if guide is not None and r.mincam_scene.max_depth <= 2:
            # direct light only: a mixel whose view holds none of the change regions (the movers, their shadows and
            # mirror images) has dP = 0 exactly, not a rare path that no ray met
            changes &= ~(regions.is_empty() if isinstance(regions, ApertureRegions) else regions.distinct == 0)
        return diff, frame_v, frame_e, changes, info

    def _freeze_key(self) -> tuple | None:
        if not self.freeze:
            return None
        return self.r.buffers_key() + (() if self.split is None else
                                       buffers_key(list(self.split.copies.values()), self.traversals))

    def _check_recordings(self) -> None:
        """Trace instead of replaying once the frozen launch keeps recording (the moving meshes' buffers land at
        new addresses every frame, as large meshes' do): recording costs what tracing does, and replays
        would never come."""
        if not self.freeze:
            return
        recorded = self._recordings() - self.recordings_at_start
        if keeps_recording(recorded, self.frames_traced):
            self.freeze = False
            self.launches = (f"traced from frame {self.frames_traced}: the frozen launch recorded {recorded} times "
                             "(the moving shapes' buffers move in memory every frame)")

    def meta(self, info: np.ndarray) -> dict:
        counts, n = self.counts, len(self.r.mincam)
        rest = info[np.all(np.isfinite(info), axis=1), 2 * n:]
        full = self.replicates * sum(counts)  # the frame pass's rays per mixel; the background traces <= these
        rays = float(rest[:, 4].mean()) if len(rest) else 2.0 * full
        reps = rest[:, len(INFO_COLUMNS):]
        allocation = None
        if self.target > 0:
            allocation = {
                "target_rel_stderr": self.target, "pilot_replicates": self.replicates,
                "floor_replicates": self.replicates + self.extra_floor(self.replicates),
                "max_replicates": self.allocation_layout(self.replicates), "sigma_from": self.allocation_sigma,
                "insignificant_rule": f"|dP| < {ALLOCATION_SIGNIFICANCE:g} pilot sigmas (or no spread): the floor",
                "replicates_min": int(reps.min()) if reps.size else None,
                "replicates_median": float(np.median(reps)) if reps.size else None,
                "replicates_mean": float(reps.mean()) if reps.size else None,
                "replicates_max": int(reps.max()) if reps.size else None,
                "rays_per_frame_pass_per_replicate": int(sum(counts)),
                "replicates_per_frame_and_mixel": reps.astype(int).tolist()}
        return {**super().meta(info), "strata_expansions": list(self.expansions), "strata_rays_per_replicate": counts,
                "allocation": allocation,
                "rays_per_mixel_per_frame": int(round(rays)),
                "background_rays_share": None if allocation else (rays - full) / full,  # allocated: no one full pass
                "paired_lanes_reused": bool(self.pairs), "launches": self.launches,
                "static_geometry": self.static_geometry,
                "moving_shapes": sorted(self.moving), "guide_bounces": bool(self.guided),
                "guided_frames": int(rest[:, 1].sum()),
                "guide_spheres_per_frame": rest[:, 2].astype(int).tolist(),
                "region_area_fraction_mean": float(rest[:, 3].mean()) if len(rest) else None}


__all__ = ["BACKGROUND_MIN_SPP", "INFO_COLUMNS", "MAX_SPP", "RETRY_FACTOR", "SPLIT_MIN_TRIANGLES", "STRATA_EXPANSIONS",
           "STRATA_SHARES", "ChangePlan", "ChangeSolver", "FallbackWarning", "HeavyTailWarning", "PlainChange",
           "StratifiedChange"]
