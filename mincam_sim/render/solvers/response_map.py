"""The response-map solver: each mixel's map over the screen's texels (stratified, with its variance), then any
frame is ``sum(W * frame)``, exact in expectation.

The kernel (:class:`~mincam_sim.render.kernels.map_tracing.ResponseMaps`, the stratified tracer and its content cache)
is ``mincam_sim.render.kernels.map_tracing``; this module plans a measurement with it: maps at the budget's samples
per texel, or the quantised search for the samples per texel whose measurements of the frames reach the
budget's target (:func:`maps_to_target`), then the frames measured through the maps chunk by chunk.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from mincam_sim.budget import DEFAULT_SAMPLES_PER_TEXEL, Budget
from mincam_sim.measurements import Measurements
from mincam_sim.model.optics import Mincam
from mincam_sim.progress import progress
from mincam_sim.render.kernels.map_tracing import (
    FIRST_SAMPLES_PER_TEXEL,
    FRAME_CHUNK_BYTES,
    MAX_SAMPLES_PER_TEXEL,
    SEARCH_EXPONENT,
    SEARCH_GROWTH,
    MapSampling,
    ResponseMaps,
    response_maps,
)
from mincam_sim.render.kernels.monte_carlo import (
    UncertainSigmaWarning,
    UnseenWarning,
    pilot_to_target,
    warn_unreached,
)
from mincam_sim.render.solvers.base import Plan, Row, Solver, finish_display
from mincam_sim.scene.display import Screen, visible_screen_area_m2

DEFAULT_MAP_BLOCKS = 4  # independent blocks of samples per texel
FRAME_CHUNK = 64  # frames measured per row chunk (at most FRAME_CHUNK_BYTES of frame data)


@dataclass(frozen=True)
class ResponseMap(Solver):
    """Per-mixel response maps over the screen's texels (stratified, with their variance); then any frame is
    a dot product. Displays only; the budget's ``samples_per_texel`` or target sets the work."""

    name: ClassVar[str] = "response_map"
    budget_reads: ClassVar[tuple[str, ...]] = ("samples_per_texel", "target_rel_stderr", "replicates", "seed")
    scenes: ClassVar[tuple[str, ...]] = ("display",)

    def maps(self, sim, budget: Budget, frames=None, cache=None, show_progress: bool = False):
        """(maps, provenance): at the budget's samples per texel, or (a target and ``frames``) the search's."""
        replicates = budget.replicates_or(DEFAULT_MAP_BLOCKS)
        if budget.target_rel_stderr > 0 and frames is not None:
            maps, trail = maps_to_target(sim, frames, budget.target_rel_stderr, budget.seed, MAX_SAMPLES_PER_TEXEL,
                                         cache, show_progress, replicates)
            return maps, {"budget_trail": trail}
        return response_maps(sim.mincam, sim.screen, budget.samples_per_texel or DEFAULT_SAMPLES_PER_TEXEL,
                             budget.seed, cache=cache, show_progress=show_progress, replicates=replicates), {}

    def plan(self, sim, frames, budget: Budget, *, background=None, cache=None, show_progress: bool = False) -> Plan:
        return MapPlan(self, sim, frames, budget, cache, show_progress)


class MapPlan(Plan):
    """Response maps (to the target noise, or at the budget's samples per texel); frames are then products
    with them, a chunk at a time."""

    def __init__(self, solver: ResponseMap, sim, frames, budget: Budget, cache, show_progress: bool) -> None:
        self.solver, self.sim, self.show_progress = solver, sim, show_progress
        self.frames, self.target = sim.frame_source(frames), budget.target_rel_stderr
        self.replicates = budget.replicates_or(DEFAULT_MAP_BLOCKS)
        self.maps, self.provenance = solver.maps(sim, budget, self.frames, cache, show_progress)
        self.used = int(self.maps.meta["samples_per_texel"])
        self.n_rows, self.columns = len(self.frames), list(sim.mincam.names)
        self.dof = DofWatch(len(self.columns))

    def rows(self, pending: np.ndarray) -> Iterator[Row]:
        step = max(1, min(FRAME_CHUNK, self.frames.chunk_size(FRAME_CHUNK_BYTES)))
        batches = [pending[i : i + step] for i in range(0, len(pending), step)]
        for idx in progress(batches, desc="response_map: frames", disable=not self.show_progress,
                            total=len(batches), unit="chunk" if step > 1 else "frame"):
            m = self.maps.measure_source(self.frames, idx, show_progress=False, desc="frames")
            self.dof.note(idx, m.stderr_dof)
            yield idx, m.irradiance_w_m2, m.stderr_w_m2

    def result(self, values: np.ndarray, errors: np.ndarray) -> Measurements:
        # 4 x 8^2 and 16 x 4^2 samples per texel are different maps: the replicates are part of the budget
        budget = {"target_rel_stderr": self.target, "samples_per_texel": self.used, "replicates": self.replicates}
        m = Measurements(values, errors, self.sim.mincam.names, {**self.maps.meta, **budget, **self.provenance})
        m.maps = self.maps
        m.meta["stderr_dof_min"] = self.dof.fewest()
        self.dof.warn(m.mixel_names, self.replicates)
        return finish_display(m, self.solver, self.target, self.used, MAX_SAMPLES_PER_TEXEL,
                              lambda result: warn_unseen_maps(result, self.maps, self.sim.mincam, self.sim.screen,
                                                              self.used, self.replicates))


SIGMA_DOF_FLOOR = 7.0  # the ray solvers' 8 replicates: |z| > 4.5 in ~0.3 % of runs (Student's t, 7 d.o.f.)


class DofWatch:
    """The fewest degrees of freedom of the standard errors a map plan measured, per mixel, and the values
    below ``SIGMA_DOF_FLOOR`` (rows found done in a resumed run were watched when they were measured)."""

    def __init__(self, n_mixels: int) -> None:
        self.least = np.full(n_mixels, np.inf)
        self.few = np.zeros(n_mixels, dtype=int)
        self.first_frame: int | None = None

    def note(self, frames: np.ndarray, dof: np.ndarray) -> None:
        """Take the degrees of freedom ``dof`` (len(frames), n_mixels) of the values of ``frames``."""
        self.least = np.minimum(self.least, dof.min(axis=0, initial=np.inf))
        few = dof < SIGMA_DOF_FLOOR * (1 - 1e-9)  # 8 blocks in one texel: 7 up to rounding
        self.few += few.sum(axis=0)
        if few.any() and self.first_frame is None:
            self.first_frame = int(np.asarray(frames)[np.flatnonzero(few.any(axis=1))[0]])

    def fewest(self) -> float | None:
        """The fewest degrees of freedom of any value's standard error (None: none had a spread)."""
        least = float(self.least.min(initial=np.inf))
        return least if np.isfinite(least) else None

    def warn(self, names: list[str], replicates: int) -> None:
        """One ``UncertainSigmaWarning`` if any value's standard error has fewer than
        ``SIGMA_DOF_FLOOR`` degrees of freedom: which mixels, how many values, what to do."""
        if not self.few.any():
            return
        from scipy import stats

        least = self.fewest()
        mixels = [names[k] for k in np.flatnonzero(self.few)]
        wanted = int(np.ceil(1 + (replicates - 1) * SIGMA_DOF_FLOOR / least))
        warnings.warn(
            f"the standard errors of {int(self.few.sum())} value(s) of mixel(s) {', '.join(mixels)} (first: frame "
            f"{self.first_frame}) rest on fewer than {SIGMA_DOF_FLOOR:g} degrees of freedom (fewest {least:.3g}): "
            f"each is the spread of the maps' {replicates} blocks over the few texels that carry the value (a "
            f"frame lit in a few texels, or texels larger than what the mixel sees), so |z| > 4.5 happens in about "
            f"{100 * 2 * stats.t.sf(4.5, least):.2g} % of runs (Student's t), not the 0.3 % of 8 replicates. "
            f"Raise replicates to {wanted} or more (Budget(replicates=...); samples_per_texel a multiple of "
            f"replicates x k^2), or measure with ms.Aperture(); see meta['stderr_dof_min'] and "
            f"Measurements.stderr_dof", UncertainSigmaWarning, stacklevel=5)


SPARSE_VIEW_SAMPLES = 10.0  # a map that found nothing with fewer samples than this expected in the view missed it
WANTED_VIEW_SAMPLES = 1000  # samples in the view the advice of samples per texel aims at (a few % noise)


def warn_unseen_maps(m: Measurements, maps: ResponseMaps, mincam: Mincam, screen: Screen, samples_per_texel: int,
                     replicates: int) -> None:
    """The ``UnseenWarning`` of a response-map result, with why each unseen mixel read 0 +/- 0.

    A mixel whose map holds weights saw the screen, and the frames' lit texels lay outside its view
    (``monte_carlo.warn_unreached``). A mixel whose map is empty saw the screen
    too (a display scene refuses a screen outside a mixel's field of view), so either its view on the screen
    (:func:`~mincam_sim.scene.display.visible_screen_area_m2`) is so much smaller than a texel that the
    per-texel samples hardly land in it (fewer than ``SPARSE_VIEW_SAMPLES`` expected: say so, with the
    samples per texel that would put ``WANTED_VIEW_SAMPLES`` there), or its mask or the other mixels' bodies
    shut it off.

    Parameters
    ----------
    m : Measurements
        The result [W/m^2].
    maps : ResponseMaps
        The maps it was measured with.
    mincam, screen : Mincam, Screen
        The set-up the maps were traced for.
    samples_per_texel, replicates : int
        The maps' samples per texel and their independent blocks.
    """
    dark = (m.irradiance_w_m2 == 0) & (m.stderr_w_m2 == 0)
    if not dark.any():
        return
    texel_area = screen.texel_area_m2
    sparse: list[tuple[int, float]] = []
    shut: list[int] = []
    seen: list[int] = []
    for k in (int(k) for k in np.flatnonzero(dark.any(axis=0))):
        if np.any(maps.weights_sr[k]):
            seen.append(k)
            continue
        view = visible_screen_area_m2(screen, mincam[k])
        if view > 0 and samples_per_texel * view / texel_area < SPARSE_VIEW_SAMPLES:
            sparse.append((k, view))
        else:
            shut.append(k)
    if seen:
        warn_unreached(Measurements(m.irradiance_w_m2[:, seen], m.stderr_w_m2[:, seen],
                                    [m.mixel_names[k] for k in seen]))

    def where(columns: list[int]) -> str:
        frames = np.flatnonzero(dark[:, columns].any(axis=1))
        return (f"mixel(s) {', '.join(m.mixel_names[k] for k in columns)} read 0 +/- 0 W/m^2 in {len(frames)} "
                f"frame(s) (first: {frames[0]})")

    if sparse:
        k, view = min(sparse, key=lambda member: member[1])  # the smallest view: its numbers are said
        width_mm, height_mm = (1e3 * v for v in screen.texel_size_m)
        strata = int(np.ceil(np.sqrt(WANTED_VIEW_SAMPLES * texel_area / view / replicates)))
        warnings.warn(
            f"{where([k for k, _ in sparse])}, and their response maps are empty though the screen is in view: the "
            f"maps sample each texel, and a texel ({width_mm:.3g} x {height_mm:.3g} mm, {1e6 * texel_area:.4g} "
            f"mm^2) is {texel_area / view:.4g} times the part of the screen {m.mixel_names[k]} sees through its "
            f"aperture ({1e6 * view:.3g} mm^2), so {samples_per_texel} samples per texel put about "
            f"{samples_per_texel * view / texel_area:.2g} sample(s) in that view and none got through: this 0 is "
            f"not a measurement. Measure with ms.Aperture() (rays through the aperture, whatever the texels' "
            f"size), or raise samples_per_texel to at least {replicates * strata * strata} (about "
            f"{WANTED_VIEW_SAMPLES} samples in the view)", UnseenWarning, stacklevel=3)
    if shut:
        warnings.warn(
            f"{where(shut)}: no sample of their response maps ({samples_per_texel} per texel) got through their "
            "apertures to the screen, though the screen lies in their fields of view: their masks are opaque "
            "toward it or the other mixels' bodies hide it; 0 +/- 0 there means 'not seen', not a certain zero "
            "(ms.Aperture() traces rays through the apertures to check)", UnseenWarning, stacklevel=3)


def maps_to_target(sim, frames, target_rel_stderr: float, seed: int = 0,
                   max_samples_per_texel: int = MAX_SAMPLES_PER_TEXEL, cache=None, show_progress: bool = False,
                   replicates: int = DEFAULT_MAP_BLOCKS) -> tuple[ResponseMaps, list[dict]]:
    """Response maps whose measurements of ``frames`` all reach ``target_rel_stderr`` (if the cap allows).

    The budget rule of every solver (``estimation.pilot_to_target``), fitted to maps: from 16 samples
    per texel, each attempt's maps measure the frames and the count is extrapolated with the convergence rate
    ``rel ~ n^-a`` measured on the last two attempts (``a`` in [0.5, 1.5]: stratified sampling converges
    faster than ``n^-1/2``; 0.5 until two attempts exist), by 2x to 8x per step, and traced as ``replicates x
    k^2`` (at least one stratum per axis more each step), until an attempt reaches the target or the cap.
    The first attempt puts at least ``SPARSE_VIEW_SAMPLES`` samples in every mixel's view on the screen
    (:func:`view_floor_samples_per_texel`; more than 16 per texel only where texels dwarf a view), so that an
    attempt that registers nothing is a frame that changes nothing the mixels see, where the search stops.
    Every attempt's maps go to ``cache`` (so a rerun or a resumed run repeats the search in milliseconds).
    Returns the last attempt's maps and the trail of (samples_per_texel, worst relative stderr) tried.
    """
    frames = sim.frame_source(frames)

    def trace(n: int) -> ResponseMaps:
        return response_maps(sim.mincam, sim.screen, n, seed, cache=cache, show_progress=show_progress,
                             replicates=replicates)

    last: list = [None, None]  # (samples per texel, maps) of the latest attempt only: maps can be large

    def measure(n: int):
        last[:] = n, trace(n)
        m = last[1].measure_source(frames, show_progress=show_progress, desc=f"target search ({n} samples/texel)")
        return m.irradiance_w_m2, m.stderr_w_m2

    floor = min(max_samples_per_texel, view_floor_samples_per_texel(sim.mincam, sim.screen))
    first = MapSampling.of(max(FIRST_SAMPLES_PER_TEXEL, replicates), replicates).samples_per_texel
    if floor > first:  # onto the search's steps (replicates x k^2, k the strata the floor asks for), within the cap
        first = stratum_steps(replicates, max_samples_per_texel)(floor, first)
    n, trail = pilot_to_target(measure, first, target_rel_stderr, max_samples_per_texel, significance=0.0,
                               rounds=None, measured_exponent=SEARCH_EXPONENT, growth=SEARCH_GROWTH, unseen_growth=1,
                               quantize=stratum_steps(replicates, max_samples_per_texel))
    maps = last[1] if n == last[0] else trace(n)  # the quantised search ends on its latest attempt
    return maps, [{"samples_per_texel": t["samples"], "worst_rel_stderr": t["worst_rel_stderr"]} for t in trail]


def view_floor_samples_per_texel(mincam: Mincam, screen: Screen) -> int:
    """Samples per texel that put ``SPARSE_VIEW_SAMPLES`` in the smallest of the mixels' views on the screen
    (:func:`~mincam_sim.scene.display.visible_screen_area_m2`; a texel's samples spread over its area): small
    wherever every view holds several texels, 1 where no mixel sees the screen."""
    views = [visible_screen_area_m2(screen, mixel) for mixel in mincam]
    smallest = min((v for v in views if v > 0), default=0.0)
    if smallest <= 0:
        return 1
    return max(1, int(np.ceil(SPARSE_VIEW_SAMPLES * screen.texel_area_m2 / smallest)))


def stratum_steps(replicates: int, cap: int):
    """The search's quantisation: ``wanted`` samples per texel after maps of ``samples`` are traced as
    ``replicates x k^2`` with at least one stratum per axis more (rounding 2x back down to the same ``k`` would
    repeat an attempt forever), at most the cap's strata, never fewer than ``samples``."""
    max_strata = max(1, int(np.sqrt(cap / replicates)))

    def quantize(wanted: float, samples: int) -> int:
        strata = int(round(np.sqrt(samples / replicates)))
        strata = min(max_strata, max(strata + 1, int(np.sqrt(wanted / replicates))))
        return max(samples, replicates * strata * strata)

    return quantize


__all__ = ["DofWatch", "MapPlan", "ResponseMap", "maps_to_target", "stratum_steps", "view_floor_samples_per_texel",
           "warn_unseen_maps"]
