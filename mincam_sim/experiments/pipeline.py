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
STRATIFIED_SHARE = 128  # the stratified dP estimator spends the plain budget / this per pass (issue 10)


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


def _finite_rows(a: np.ndarray) -> np.ndarray:
    return np.isfinite(a) if a.ndim == 1 else np.all(np.isfinite(a), axis=1)


def locate_in_world(world: WorldRenderer, camera: GroundTruthCamera, frames: Sequence[dict], background: dict,
                    setup: Setup, rng: np.random.Generator, predict: Callable[[np.ndarray, float], np.ndarray],
                    spp: int,
                    region: np.ndarray | None = None, axis: int | None = None,
                    show_progress: bool = False,
                    extrapolated: Callable[[np.ndarray, float], np.ndarray] | None = None) -> Located:
    """Render dP of every frame (``setup.dp_estimator``: the stratified estimator with the plain budget ``spp`` /
    ``STRATIFIED_SHARE`` rays per pass, or the plain correlated one with ``spp``), read it out, detect, predict
    positions with
    ``predict(change_dn, min_total_dn)``, propagate the noise, and compare with the ground-truth camera.

    ``min_total_dn`` is the detection threshold: a ratio estimator (Eq. 4 / Eq. 7) gives NaN (not a position) where
    its denominator, a sum of mixel changes, is within that of zero, as when an object's brightening and its
    shadow's darkening cancel; such frames count as missed, not as wild positions.

    ``axis`` picks one coordinate (1D experiments); ``region`` restricts the ground truth (e.g. the boundary
    band). ``extrapolated(change_dn, min_total_dn)``, if given, marks the frames whose observation lies outside
    the calibrated range (counted in the summary as ``extrapolated_frames``).

    Frame accounting (summary): ``frames`` = ``ground_truth_frames`` + frames without a ground truth; of the
    ground-truth frames, ``missed_frames`` were not detected, ``no_position_frames`` were detected but the ratio
    estimator gave no position (denominator within the threshold), and ``n`` were scored. ``n_missing`` (the
    error rates' count) equals ``no_position_frames``; ``unscored_frames_pct`` is the share of ground-truth
    frames that got no score for either reason. If no frame can be scored the error rates are ``None``.
    """
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
    truth, signed = np.full(shape, np.nan), np.full(shape, np.nan)
    images = []
    pick = (lambda v: v[axis]) if axis is not None else (lambda v: v)
    threshold = GROUND_TRUTH_THRESHOLD * float(bg_image.max())
    for i in progress(range(len(frames)), desc="ground truth", disable=not show_progress):
        world.update(frames[i])
        image = world.camera_image(spp=GROUND_TRUTH_SPP, seed=setup.seed)
        centroid, mask = camera.change_centroid(image, bg_image, threshold, region)
        truth[i] = pick(centroid) if mask.sum() >= 3 else np.nan
        signed[i] = pick(camera.signed_change_centroid(image, bg_image, region))
        images.append(image)
    world.update(background)

    has_truth = _finite_rows(truth)
    scored = detected & has_truth  # frames to score: a NaN prediction among them counts as missing
    ok = scored & _finite_rows(predicted)
    sigma_norm = sigma if sigma.ndim == 1 else np.hypot(*sigma.T)
    with np.errstate(divide="ignore", invalid="ignore"):
        dp_rel = np.abs(dp.stderr_w_m2 / dp.irradiance_w_m2)
    n_missed = int((has_truth & ~detected).sum())
    n_no_position = int((scored & ~_finite_rows(predicted)).sum())

    def rates(pred: np.ndarray, true: np.ndarray) -> dict | None:
        both = _finite_rows(pred) & _finite_rows(true)
        return error_rates(pred, true, setup.field_m) if both.any() else None

    headline = rates(predicted[scored], truth[scored]) or {
        "max_error_pct": None, "avg_error_pct": None, "rms_error_pct": None, "n": 0,
        "n_missing": n_no_position, "n_without_truth": 0, "missing_pct": 100.0 if scored.any() else None}
    summary = {
        **headline,
        "frames": len(frames),
        "detected_frames": int(detected.sum()),
        "ground_truth_frames": int(has_truth.sum()),
        "missed_frames": n_missed,
        "no_position_frames": n_no_position,
        "unscored_frames_pct": (100.0 * (n_missed + n_no_position) / int(has_truth.sum())
                                if has_truth.any() else None),
        "false_alarm_frames": int((~has_truth & detected).sum()),
        "extrapolated_frames": (int((extrapolated(change, readout.threshold_dn) & ok).sum())
                                if extrapolated is not None else None),
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
    arrays = {"predicted_m": predicted, "truth_m": truth, "signed_centroid_m": signed, "detected": detected,
              "evaluated": ok, "predicted_noiseless_m": predicted_ideal, "predicted_sigma_m": sigma,
              "sensor_sigma_m": sigma_sensor, "change_dn": change, "dP_w_m2": dp.irradiance_w_m2,
              "dP_stderr_w_m2": dp.stderr_w_m2}
    return Located(summary, arrays, images, bg_image)
