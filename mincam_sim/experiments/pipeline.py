"""The locate pipeline of the tabletop experiments: render the change of every frame, read it out with the
sensor, detect, predict positions, propagate the noise, and score against the ground-truth camera."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..estimators import detect_change
from ..metrics import error_rates
from ..progress import progress
from ..readout import propagate_sigma, read_out
from ..render.world import WorldRenderer
from .ground_truth import GroundTruthCamera
from .setup import Setup

GROUND_TRUTH_SPP = 32  # camera samples per pixel
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


def locate_in_world(world: WorldRenderer, camera: GroundTruthCamera, frames: Sequence[dict], background: dict,
                    setup: Setup, rng: np.random.Generator, predict: Callable[[np.ndarray, float], np.ndarray],
                    spp: int,
                    region: np.ndarray | None = None, axis: int | None = None,
                    show_progress: bool = False,
                    extrapolated: Callable[[np.ndarray, float], np.ndarray] | None = None,
                    objects: Sequence[list[tuple[np.ndarray, np.ndarray]]] | None = None,
                    ground_truth: str = "object", groups: Sequence[str] | None = None) -> Located:
    """Render dP of every frame (``setup.dp_estimator``: the stratified estimator with the plain budget ``spp`` /
    ``STRATIFIED_SHARE`` rays per pass, or the plain correlated one with ``spp``), read it out, detect, predict
    positions with ``predict(change_dn, min_total_dn)``, propagate the noise, and compare with the ground-truth
    camera.

    ``min_total_dn`` is the detection threshold: a ratio estimator (Eq. 4 / Eq. 7) gives NaN (not a position) where
    its denominator, a sum of mixel changes, is within that of zero, as when an object's brightening and its
    shadow's darkening cancel; such frames count as missed, not as wild positions.

    Two ground truths are computed for every frame: the centroid of the **object** (the paper's definition: the
    silhouette of the frame's meshes ``objects[i]``, each (world vertices [m], faces), in the camera) and the
    centroid of the **change** (background subtraction, binary detection: object and shadow). ``ground_truth``
    ("object" or "change") picks the one the headline numbers use; the other is scored too. Without
    ``objects`` only the change centroid exists and must be the one chosen.

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
    if ground_truth not in GROUND_TRUTHS:
        raise ValueError(f"ground_truth must be one of {GROUND_TRUTHS}, got {ground_truth!r}")
    if ground_truth == "object" and objects is None:
        raise ValueError("the object ground truth needs the frames' meshes (objects=...)")
    if objects is not None and len(objects) != len(frames):
        raise ValueError(f"objects lists {len(objects)} frames, the run has {len(frames)}")
    rays = spp // STRATIFIED_SHARE if setup.dp_estimator == "stratified" else spp
    dp, _ = world.measure_changes(frames, background, spp=rays, seed=setup.seed, show_progress=show_progress,
                                  estimator=setup.dp_estimator)
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

    world.update(background)
    bg_image = world.camera_image(spp=GROUND_TRUTH_SPP, seed=setup.seed)
    shape = (len(frames),) if axis is not None else (len(frames), 2)
    truth_change, truth_object, signed = (np.full(shape, np.nan) for _ in range(3))
    net_fraction = np.full(len(frames), np.nan)
    images = []
    pick = (lambda v: v[axis]) if axis is not None else (lambda v: v)
    threshold = GROUND_TRUTH_THRESHOLD * float(bg_image.max())
    for i in progress(range(len(frames)), desc="ground truth", disable=not show_progress):
        world.update(frames[i])
        image = world.camera_image(spp=GROUND_TRUTH_SPP, seed=setup.seed)
        centroid, mask = camera.change_centroid(image, bg_image, threshold, region)
        truth_change[i] = pick(centroid) if mask.sum() >= 3 else np.nan
        if objects is not None:
            centroid, mask = camera.object_centroid(objects[i], image.shape, region)
            truth_object[i] = pick(centroid) if mask.sum() >= 3 else np.nan
        signed[i] = pick(camera.signed_change_centroid(image, bg_image, region))
        diff = (image - bg_image) if region is None else np.where(region, image - bg_image, 0.0)
        total = np.abs(diff).sum()
        net_fraction[i] = diff.sum() / total if total > 0 else np.nan
        images.append(image)
    world.update(background)

    truths = {"object": truth_object, "change": truth_change}
    truth = truths[ground_truth]
    other_name = "change" if ground_truth == "object" else "object"
    extrap = (extrapolated(change, readout.threshold_dn) if extrapolated is not None
              else np.zeros(len(frames), dtype=bool))
    labels = np.asarray(groups if groups is not None else ["all"] * len(frames))
    pair_sum_dn = change.sum(axis=1) / (change.shape[1] / 2)  # the mean denominator of Eq. 4 / 7 [DN]

    def rates(pred: np.ndarray, true: np.ndarray, normalisation: str = "euclidean") -> dict | None:
        both = _finite_rows(pred) & _finite_rows(true)
        return error_rates(pred, true, setup.field_m, normalisation) if both.any() else None

    def scoring(true: np.ndarray, keep: np.ndarray) -> dict:
        """Rates and frame accounting against ``true`` over the frames in ``keep``."""
        has_truth = _finite_rows(true) & keep
        scored = detected & has_truth  # frames to score: a NaN prediction among them counts as missing
        ok = scored & _finite_rows(predicted)
        n_missed = int((has_truth & ~detected).sum())
        n_no_position = int((scored & ~_finite_rows(predicted)).sum())
        headline = rates(predicted[scored], true[scored]) or {
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
            "extrapolated_frames": int((extrap & ok).sum()) if extrapolated is not None else None,
            "without_extrapolated": rates(predicted[ok & ~extrap], true[ok & ~extrap]),
            "per_axis": rates(predicted[ok], true[ok], "per_axis"),
            "contrast": _contrast(net_fraction[ok], pair_sum_dn[ok]),
            "_ok": ok,
        }

    everything = np.ones(len(frames), dtype=bool)
    main = scoring(truth, everything)
    ok = main.pop("_ok")
    other = scoring(truths[other_name], everything) if objects is not None else None
    if other is not None:
        other.pop("_ok")
    by_group = {}
    for label in sorted(set(labels.tolist()), key=labels.tolist().index):
        g = scoring(truth, labels == label)
        g.pop("_ok")
        by_group[label] = g
    sigma_norm = sigma if sigma.ndim == 1 else np.hypot(*sigma.T)
    with np.errstate(divide="ignore", invalid="ignore"):
        dp_rel = np.abs(dp.stderr_w_m2 / dp.irradiance_w_m2)
    both_truths = _finite_rows(truth_object) & _finite_rows(truth_change)
    summary = {
        **main,
        "ground_truth": ground_truth,
        "by_group": by_group,
        f"vs_{other_name}_centroid": other,
        "object_vs_change_centroid": (rates(truth_change[both_truths], truth_object[both_truths])
                                      if objects is not None else None),
        "noiseless": rates(predicted_ideal[ok], truth[ok]),
        "signed_centroid_vs_ground_truth": rates(signed[ok], truth[ok]),
        "vs_signed_centroid": rates(predicted[ok], signed[ok]),
        "noise_sigma_median_pct": float(100 * np.median(sigma_norm[ok]) / setup.field_m) if ok.any() else None,
        "dP_worst_rel_stderr": float(np.nanmax(dp_rel[ok])) if ok.any() else None,
        "spp_per_mixel_per_frame": rays,
        "dP_estimator": dp.meta["estimator"],
        "rays_per_mixel_per_frame": dp.meta["rays_per_mixel_per_frame"],
        "exposure_s": readout.sensor.exposure_s,
    }
    arrays = {"predicted_m": predicted, "truth_m": truth, "truth_object_m": truth_object,
              "truth_change_m": truth_change, "signed_centroid_m": signed, "detected": detected,
              "evaluated": ok, "extrapolated": extrap & ok, "group": labels,
              "net_change_fraction": net_fraction, "pair_sum_dn": pair_sum_dn,
              "predicted_noiseless_m": predicted_ideal, "predicted_sigma_m": sigma,
              "sensor_sigma_m": sigma_sensor, "change_dn": change, "dP_w_m2": dp.irradiance_w_m2,
              "dP_stderr_w_m2": dp.stderr_w_m2}
    return Located(summary, arrays, images, bg_image)
