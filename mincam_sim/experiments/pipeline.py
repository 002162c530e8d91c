"""The locate pipeline of the tabletop experiments: render the change of every frame, read it out with the
sensor, detect, predict positions, propagate the noise, and score against the ground-truth camera."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from mincam_sim.budget import Budget
from mincam_sim.changes import RunInfo
from mincam_sim.estimation.estimators import detect_change
from mincam_sim.estimation.metrics import error_rates
from mincam_sim.experiments.ground_truth import GroundTruthCamera
from mincam_sim.experiments.setup import Setup
from mincam_sim.experiments.tabletop_world import check_spp_fraction
from mincam_sim.model.readout import propagate_sigma, read_out
from mincam_sim.render.simulation import Simulation
from mincam_sim.render.solvers import PlainChange, StratifiedChange

GROUND_TRUTH_SPP = 64  # camera samples per pixel where the change can be seen directly (its window)
GROUND_TRUTH_ELSEWHERE_SPP = 8  # ... over the whole film, for what inter-reflections change elsewhere
GROUND_TRUTH_THRESHOLD = 0.02  # binary detection: |change| > this fraction of the brightest background pixel
STRATIFIED_SHARE = 128  # the stratified dP estimator spends the plain budget / this per pass


@dataclass
class Located:
    """What :func:`locate_in_world` found: a summary (error rates and counts), per-frame arrays, the
    ground-truth images and the background image."""

    summary: dict
    arrays: dict
    images: list
    background_image: np.ndarray

    def example_frames(self, count: int = 3) -> np.ndarray:
        """Indices of ``count`` evaluated frames spread over the run (for the overlay figures)."""
        evaluated = np.flatnonzero(self.arrays["evaluated"])
        return evaluated[:: max(1, evaluated.size // count)][:count]


def _contrast(net_fraction: np.ndarray, pair_sum_dn: np.ndarray) -> dict | None:
    """How much of a frame's change survives as net change: the ground-truth camera's sum of the change over its
    sum of |change| (1: all brightening; near 0: brightening cancelled by shadow and dark sides), and the
    denominator of Eq. 4 / 7, a pair's summed change [DN] (median and 5th-95th percentiles over the frames)."""
    if net_fraction.size == 0:
        return None

    def spread(v: np.ndarray) -> list[float]:
        v = v[np.isfinite(v)]
        return [float(q) for q in np.percentile(v, (50, 5, 95))] if v.size else [float("nan")] * 3

    return {"net_to_absolute_change_median_p5_p95": spread(net_fraction),
            "pair_sum_dn_median_p5_p95": spread(pair_sum_dn)}


def _finite_rows(a: np.ndarray) -> np.ndarray:
    return np.isfinite(a) if a.ndim == 1 else np.all(np.isfinite(a), axis=1)


GROUND_TRUTHS = ("object", "change")  # the paper's: the object's centroid; the change's (with the shadow)


@dataclass(frozen=True)
class LocateOptions:
    """How :func:`locate_in_world` predicts and scores the frames.

    Attributes
    ----------
    predict : callable
        ``predict(change_dn, min_total_dn)`` -> positions [m] (one per frame).
    region : (rows, cols) bool ndarray, optional
        Restricts both ground truths (e.g. the boundary band).
    axis : int, optional
        Picks one coordinate (1D experiments).
    extrapolated : callable, optional
        ``extrapolated(change_dn, min_total_dn)`` marks the frames read outside the calibrated range.
    objects : list, optional
        Per frame, the meshes (world vertices [m], faces) of the object ground truth.
    ground_truth : {"object", "change"}
        The ground truth of the headline numbers.
    groups : list of str, optional
        One label per frame (which toy or car it shows): splits the statistics.
    spp_fraction : float
        Share of the set-up's tabletop budget (``Setup.tabletop_spp``) this experiment's dP spends, in (0, 1].
    show_progress : bool
    """

    predict: Callable[[np.ndarray, float], np.ndarray]
    region: np.ndarray | None = None
    axis: int | None = None
    extrapolated: Callable[[np.ndarray, float], np.ndarray] | None = None
    objects: Sequence[list[tuple[np.ndarray, np.ndarray]]] | None = None
    ground_truth: str = "object"
    groups: Sequence[str] | None = None
    spp_fraction: float = 1.0
    show_progress: bool = False


def locate_in_world(sim: Simulation, camera: GroundTruthCamera, frames: Sequence[dict], background: dict,
                    setup: Setup, rng: np.random.Generator, options: LocateOptions,
                    truth_sim: Simulation | None = None) -> Located:
    """Render dP of every frame (``setup.dp_solver``: the stratified solver with ``options.spp_fraction`` of the
    plain budget ``setup.tabletop_spp``, / ``STRATIFIED_SHARE``, rays per pass, or the plain correlated one with
    it: :func:`dp_rays_per_pass`), read it out, detect, predict positions with
    ``options.predict(change_dn, min_total_dn)``, propagate the noise, and compare with the ground-truth camera
    of ``truth_sim`` (a second simulation of the same scene, so that dP and the ground truth share no mutable
    scene; default: ``sim`` itself).

    ``min_total_dn`` is the detection threshold: a ratio estimator (Eq. 4 / Eq. 7) gives NaN (not a position) where
    its denominator, a sum of mixel changes, is within that of zero, as when an object's brightening and its
    shadow's darkening cancel; such frames count as missed, not as wild positions.

    Two ground truths are computed for every frame (:class:`LocateOptions` for the fields named here): the centroid
    of the **object** (the paper's definition: the silhouette of the frame's meshes ``objects[i]``, each (world
    vertices [m], faces), in the camera) and the centroid of the **change** (background subtraction, binary
    detection: object and shadow, within the window of the camera where the movers and their shadows can be
    seen: :meth:`Simulation.camera_changes`). ``ground_truth`` ("object" or "change") picks the one the headline
    numbers use; the other is scored too. Without ``objects`` only the change centroid exists and must be the
    one chosen.

    ``axis`` picks one coordinate (1D experiments); ``region`` restricts both ground truths (e.g. the boundary
    band). ``extrapolated(change_dn, min_total_dn)``, if given, marks the frames whose observation lies outside
    the calibrated range (counted as ``extrapolated_frames``; ``without_extrapolated`` scores the others).
    ``groups`` (one label per frame: which toy or car it shows) splits the statistics (``by_group``).

    Frame accounting (summary): ``frames`` = ``ground_truth_frames`` + frames without a ground truth; of the
    ground-truth frames, ``missed_frames`` were not detected, ``no_position_frames`` were detected but the ratio
    estimator gave no position (denominator within the threshold), and ``n`` were scored. ``n_missing`` (the
    error rates' count) equals ``no_position_frames``; ``unscored_frames`` is their sum and
    ``unscored_frames_pct`` its share of the ground-truth frames. If no frame can be scored the error rates are
    ``None``. Rates are Euclidean (``normalisation``); ``per_axis`` gives the same frames per axis.
    """
    o = options
    ground_truth, objects, extrapolated, groups = o.ground_truth, o.objects, o.extrapolated, o.groups
    _check_ground_truth(ground_truth, objects, frames)
    rays = dp_rays_per_pass(setup, o.spp_fraction)
    seen = _observe(sim, frames, background, setup, rng, o.predict, rays, o.show_progress)
    truths = _ground_truths(sim if truth_sim is None else truth_sim, camera, frames, background, setup, o)
    truth = truths.by_name[ground_truth]
    other_name = "change" if ground_truth == "object" else "object"
    extrap = (extrapolated(seen.change, seen.readout.threshold_dn) if extrapolated is not None
              else np.zeros(len(frames), dtype=bool))
    labels = np.asarray(groups if groups is not None else ["all"] * len(frames))
    pair_sum_dn = seen.change.sum(axis=1) / (seen.change.shape[1] / 2)  # the mean denominator of Eq. 4 / 7 [DN]
    score = _Scoring(seen.detected, seen.predicted, truths.net_fraction, pair_sum_dn, extrap,
                     extrapolated is not None, setup.field_m)
    everything = np.ones(len(frames), dtype=bool)
    main = score(truth, everything)
    ok = main.pop("_ok")
    other = score(truths.by_name[other_name], everything) if objects is not None else None
    if other is not None:
        other.pop("_ok")
    by_group = {}
    for label in sorted(set(labels.tolist()), key=labels.tolist().index):
        g = score(truth, labels == label)
        g.pop("_ok")
        by_group[label] = g
    summary = {**main, "ground_truth": ground_truth, "by_group": by_group, f"vs_{other_name}_centroid": other,
               **_summary_extras(seen, truths, truth, ok, objects is not None, score.rates, setup, rays)}
    arrays = {"predicted_m": seen.predicted, "truth_m": truth, "truth_object_m": truths.object,
              "truth_change_m": truths.change, "signed_centroid_m": truths.signed, "detected": seen.detected,
              "evaluated": ok, "extrapolated": extrap & ok, "group": labels,
              "net_change_fraction": truths.net_fraction, "pair_sum_dn": pair_sum_dn,
              "predicted_noiseless_m": seen.predicted_ideal, "predicted_sigma_m": seen.sigma,
              "sensor_sigma_m": seen.sigma_sensor, "change_dn": seen.change, "dP_w_m2": seen.dp.irradiance_w_m2,
              "dP_stderr_w_m2": seen.dp.stderr_w_m2}
    return Located(summary, arrays, truths.images, truths.background_image)


def dp_rays_per_pass(setup: Setup, spp_fraction: float = 1.0) -> int:
    """Rays per mixel per pass of a tabletop experiment's dP: ``spp_fraction`` of the set-up's plain-estimator
    budget ``setup.tabletop_spp`` [samples per mixel per frame], divided by ``STRATIFIED_SHARE`` for the
    stratified solver (the plain solver traces it as it is). The stratified solver traces the paired background
    lanes on top of these (``rays_per_mixel_per_frame`` in the results counts both)."""
    check_spp_fraction(spp_fraction)
    spp = int(setup.tabletop_spp * spp_fraction)
    return spp // STRATIFIED_SHARE if setup.dp_solver == "stratified_change" else spp


def _check_ground_truth(ground_truth: str, objects, frames: Sequence[dict]) -> None:
    if ground_truth not in GROUND_TRUTHS:
        raise ValueError(f"ground_truth must be one of {GROUND_TRUTHS}, got {ground_truth!r}")
    if ground_truth == "object" and objects is None:
        raise ValueError("the object ground truth needs the frames' meshes (objects=...)")
    if objects is not None and len(objects) != len(frames):
        raise ValueError(f"objects lists {len(objects)} frames, the run has {len(frames)}")


@dataclass
class _Observed:
    """What the mincam saw: dP, its read-out, detections, predicted positions and their noise."""

    dp: object
    info: RunInfo
    readout: object
    detected: np.ndarray
    change: np.ndarray
    predicted: np.ndarray
    predicted_ideal: np.ndarray
    sigma: np.ndarray
    sigma_sensor: np.ndarray


def _observe(sim: Simulation, frames, background, setup: Setup, rng: np.random.Generator, predict,
             rays: int, show_progress: bool) -> _Observed:
    """Render dP of every frame, read it out with the sensor, detect, predict and propagate the noise."""
    solver = StratifiedChange() if setup.dp_solver == "stratified_change" else PlainChange()
    changes = sim.measure_changes(frames, background, solver, Budget(spp=rays, seed=setup.seed),
                                  show_progress=show_progress)
    dp = changes.dp
    bg_irr = np.asarray(dp.meta["background_w_m2"])
    frame_irr = bg_irr + dp.irradiance_w_m2
    readout = read_out(frame_irr, bg_irr, setup.sensor(), rng, setup.exposure_fill)
    detected = detect_change(readout.frames_dn, readout.background_dn, readout.threshold_dn)
    change = readout.change_dn

    def estimate(c: np.ndarray) -> np.ndarray:
        return predict(c, readout.threshold_dn)

    predicted = estimate(change)
    predicted_ideal = estimate(readout.ideal_change_dn(frame_irr, bg_irr))
    sigma = propagate_sigma(estimate, change, readout.change_sigma_dn(frame_irr, bg_irr, dp.stderr_w_m2))
    sigma_sensor = propagate_sigma(estimate, change, readout.change_sigma_dn(frame_irr, bg_irr))
    return _Observed(dp, changes.info, readout, detected, change, predicted, predicted_ideal, sigma, sigma_sensor)


@dataclass
class _Truths:
    """The ground-truth camera's view: both centroids, the signed centroid, the net change fraction, images."""

    change: np.ndarray
    object: np.ndarray
    signed: np.ndarray
    net_fraction: np.ndarray
    images: list
    background_image: np.ndarray

    @property
    def by_name(self) -> dict:
        return {"object": self.object, "change": self.change}


def _ground_truths(sim: Simulation, camera: GroundTruthCamera, frames, background, setup: Setup,
                   options: LocateOptions) -> _Truths:
    """Render the ground-truth camera for the background and every frame (the world is left at the
    background) and take each frame's centroids: the change centroid from the window where the frame's
    movers and their shadows can be seen (:meth:`Simulation.camera_changes`, ``GROUND_TRUTH_SPP``); the signed
    centroid and the net change fraction, sums over the whole film, from the window plus the rest of the film
    at ``GROUND_TRUTH_ELSEWHERE_SPP`` (inter-reflections; both parts unbiased)."""
    objects, region, axis = options.objects, options.region, options.axis
    sim.update(background)
    bg_image = sim.camera_image(spp=GROUND_TRUTH_SPP, seed=setup.seed)
    shape = (len(frames),) if axis is not None else (len(frames), 2)
    truth_change, truth_object, signed = (np.full(shape, np.nan) for _ in range(3))
    net_fraction = np.full(len(frames), np.nan)
    images = []
    pick = (lambda v: v[axis]) if axis is not None else (lambda v: v)
    threshold = GROUND_TRUTH_THRESHOLD * float(bg_image.max())
    changes = sim.camera_changes(frames, background, spp=GROUND_TRUTH_SPP, seed=setup.seed,
                                 elsewhere_spp=GROUND_TRUTH_ELSEWHERE_SPP, show_progress=options.show_progress)
    for i, change in enumerate(changes):
        near = bg_image + change.change_image(bg_image.shape)
        centroid, mask = camera.change_centroid(near, bg_image, threshold, region)
        truth_change[i] = pick(centroid) if mask.sum() >= 3 else np.nan
        if objects is not None:
            centroid, mask = camera.object_centroid(objects[i], bg_image.shape, region)
            truth_object[i] = pick(centroid) if mask.sum() >= 3 else np.nan
        diff = change.change_image(bg_image.shape, elsewhere=True)
        image = bg_image + diff
        signed[i] = pick(camera.signed_change_centroid(image, bg_image, region))
        if region is not None:
            diff = np.where(region, diff, 0.0)
        total = np.abs(diff).sum()
        net_fraction[i] = diff.sum() / total if total > 0 else np.nan
        images.append(image)
    return _Truths(truth_change, truth_object, signed, net_fraction, images, bg_image)


@dataclass
class _Scoring:
    """Scores predictions against a ground truth over a subset of the frames (see :func:`locate_in_world`)."""

    detected: np.ndarray
    predicted: np.ndarray
    net_fraction: np.ndarray
    pair_sum_dn: np.ndarray
    extrap: np.ndarray
    has_extrapolation: bool
    field_m: float

    def rates(self, pred: np.ndarray, true: np.ndarray, normalisation: str = "euclidean") -> dict | None:
        both = _finite_rows(pred) & _finite_rows(true)
        return error_rates(pred, true, self.field_m, normalisation) if both.any() else None

    def __call__(self, true: np.ndarray, keep: np.ndarray) -> dict:
        """Rates and frame accounting against ``true`` over the frames in ``keep``."""
        detected, predicted, extrap = self.detected, self.predicted, self.extrap
        has_truth = _finite_rows(true) & keep
        scored = detected & has_truth  # frames to score: a NaN prediction among them counts as missing
        ok = scored & _finite_rows(predicted)
        n_missed = int((has_truth & ~detected).sum())
        n_no_position = int((scored & ~_finite_rows(predicted)).sum())
        headline = self.rates(predicted[scored], true[scored]) or {
            "max_error_pct": None, "p95_error_pct": None, "avg_error_pct": None, "rms_error_pct": None, "n": 0,
            "n_missing": n_no_position, "n_without_truth": 0, "missing_pct": 100.0 if scored.any() else None,
            "normalisation": "euclidean"}
        return {
            **headline,
            "frames": int(keep.sum()),
            "detected_frames": int((detected & keep).sum()),
            "ground_truth_frames": int(has_truth.sum()),
            "missed_frames": n_missed,
            "no_position_frames": n_no_position,
            "unscored_frames": n_missed + n_no_position,
            "unscored_frames_pct": (100.0 * (n_missed + n_no_position) / int(has_truth.sum())
                                    if has_truth.any() else None),
            "false_alarm_frames": int((~_finite_rows(true) & keep & detected).sum()),
            "extrapolated_frames": int((extrap & ok).sum()) if self.has_extrapolation else None,
            "without_extrapolated": self.rates(predicted[ok & ~extrap], true[ok & ~extrap]),
            "per_axis": self.rates(predicted[ok], true[ok], "per_axis"),
            "contrast": _contrast(self.net_fraction[ok], self.pair_sum_dn[ok]),
            "_ok": ok,
        }


def _summary_extras(seen: _Observed, truths: _Truths, truth: np.ndarray, ok: np.ndarray, with_objects: bool,
                    rates, setup: Setup, rays: int) -> dict:
    """The summary beyond the headline: the two truths against each other, noiseless and signed-centroid
    references, the noise, the dP estimator and the exposure."""
    sigma_norm = seen.sigma if seen.sigma.ndim == 1 else np.hypot(*seen.sigma.T)
    with np.errstate(divide="ignore", invalid="ignore"):
        dp_rel = np.abs(seen.dp.stderr_w_m2 / seen.dp.irradiance_w_m2)
    both_truths = _finite_rows(truths.object) & _finite_rows(truths.change)
    return {
        "object_vs_change_centroid": (rates(truths.change[both_truths], truths.object[both_truths])
                                      if with_objects else None),
        "noiseless": rates(seen.predicted_ideal[ok], truth[ok]),
        "signed_centroid_vs_ground_truth": rates(truths.signed[ok], truth[ok]),
        "vs_signed_centroid": rates(seen.predicted[ok], truths.signed[ok]),
        "noise_sigma_median_pct": float(100 * np.median(sigma_norm[ok]) / setup.field_m) if ok.any() else None,
        "dP_worst_rel_stderr": float(np.nanmax(dp_rel[ok])) if ok.any() else None,
        "spp_per_mixel_per_frame": rays,
        "dP_solver": seen.info.solver,
        "rays_per_mixel_per_frame": seen.info.rays_per_mixel_per_frame,
        "launches": seen.info.launches,
        "exposure_s": seen.readout.sensor.exposure_s,
    }
