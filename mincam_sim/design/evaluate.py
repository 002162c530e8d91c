"""Physical evaluation of a tracking mincam on held-out scenes, with the simulator's non-differentiable
response-map solver (:meth:`Simulation.response_maps <mincam_sim.render.simulation.Simulation.response_maps>`:
rays from the detectors through the masks, as printed on the film, to every display texel, with visibility in
the mincam's scene), the 12-bit sensor and the paper's protocol: Eq. 7 ratios, cubic calibration on a grid of
3 cm squares at 0.5 m, scaled by ``depth / 0.5`` at other depths (:mod:`mincam_sim.design.tracking` for the
coordinates)."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from mincam_sim.budget import Budget
from mincam_sim.design import tracking as tr
from mincam_sim.estimation.calibration import Calibration2D, ExtrapolationWarning
from mincam_sim.estimation.metrics import error_rates
from mincam_sim.model.geometry import Pose
from mincam_sim.model.optics import Mincam
from mincam_sim.progress import progress
from mincam_sim.scene.display import Screen, coverage


@dataclass
class HeldOut:
    """Held-out scenes: per depth, object field positions, sides [m] and radiances."""

    depths_m: np.ndarray
    q: list
    sizes_m: list
    radiance: list

    @classmethod
    def draw(cls, task: tr.TrackingTask) -> HeldOut:
        """Depths stratified over the working range (one uniform draw in each of ``eval_depths`` equal bins, so
        the whole range is covered) and objects in the working disc, from a seed of their own (disjoint from
        the training draw)."""
        rng = np.random.default_rng([task.seed, 97])
        lo, hi = task.depth_range_m
        edges = np.linspace(lo, hi, task.eval_depths + 1)
        depths = edges[:-1] + (edges[1:] - edges[:-1]) * rng.random(task.eval_depths)
        q, s, r = zip(*(tr.random_objects(rng, task.eval_frames_per_depth) for _ in depths), strict=True)
        return cls(depths, list(q), list(s), list(r))


def _screen(depth_m: float, texels: int) -> Screen:
    side = 1.3 * tr.FIELD_M * depth_m / tr.CALIBRATION_DEPTH_M  # covers the calibrated disc and a margin
    return Screen(side, side, (texels, texels), Pose((0.0, 0.0, -depth_m), (0.0, 0.0, 1.0)))


def _frames(screen: Screen, centers_m: np.ndarray, sizes_m: np.ndarray, radiance: np.ndarray) -> np.ndarray:
    return np.stack([r * coverage(screen, x - s / 2, x + s / 2, y - s / 2, y + s / 2)
                     for (x, y), s, r in zip(centers_m, sizes_m, radiance, strict=True)])


def irradiances(cam: Mincam, depth_m: float, centers_m: np.ndarray, sizes_m: np.ndarray, radiance: np.ndarray,
                task: tr.TrackingTask, seed: int) -> np.ndarray:
    """Irradiance (n, 4) [W/m^2] of every object on a display at ``depth_m`` (response-map form)."""
    from mincam_sim.render.simulation import Simulation

    screen = _screen(depth_m, task.screen_texels)
    maps = Simulation(cam, screen=screen).response_maps(Budget(samples_per_texel=task.samples_per_texel, seed=seed))
    return maps.measure(_frames(screen, centers_m, sizes_m, radiance)).irradiance_w_m2


def measure(cam: Mincam, task: tr.TrackingTask, held_out: HeldOut, show_progress: bool = False) -> list:
    """Irradiances [W/m^2]: the calibration sweep at 0.5 m, then each held-out depth's objects (response maps)."""
    cal_xy = tr.calibration_positions(task.calibration_grid)
    n_cal = len(cal_xy)
    blocks = [irradiances(cam, tr.CALIBRATION_DEPTH_M, cal_xy, np.full(n_cal, tr.CALIBRATION_SQUARE_M),
                          np.ones(n_cal), task, seed=task.seed)]
    for i, depth in enumerate(progress(held_out.depths_m, desc="held-out depths", disable=not show_progress)):
        blocks.append(irradiances(cam, float(depth), tr.to_metres(held_out.q[i], depth), held_out.sizes_m[i],
                                  held_out.radiance[i], task, seed=task.seed + 1 + i))
    return blocks


def score(blocks: list, task: tr.TrackingTask, held_out: HeldOut, decoder=None) -> dict:
    """Read the irradiances out with the 12-bit sensor and locate every held-out object; errors as % of the
    field (paper's definition).

    Without ``decoder``: the paper's protocol (Eq. 7 ratios, cubic calibration on the physical sweep at 0.5 m,
    scaled by depth / 0.5). With a :class:`~.decoder.Decoder`: its prediction, with no physical calibration.
    Returns ``avg_error_pct``, ``max_error_pct``, ``n`` (evaluated objects), per-depth averages, the noiseless
    read-out's errors, and per-object arrays (``arrays``) for plots.
    """
    cal_xy = tr.calibration_positions(task.calibration_grid)
    # one exposure for the whole session: the brightest reading fills EXPOSURE_FILL of the range
    peak = max(float(b.max()) for b in blocks)
    s = tr.sensor().auto_exposed(peak, tr.EXPOSURE_FILL)
    rng = np.random.default_rng([task.seed, 5])
    noisy = _locate(cal_xy, [tr.read_out(b, s, rng) for b in blocks], held_out, decoder)
    noiseless = _locate(cal_xy, [s.expected(b) - s.expected(0.0) for b in blocks], held_out, decoder)
    return {**noisy, "exposure_s": s.exposure_s,
            "noiseless": {k: v for k, v in noiseless.items() if k in ("avg_error_pct", "max_error_pct", "n")}}


def evaluate(cam: Mincam, task: tr.TrackingTask, held_out: HeldOut, decoder=None, show_progress: bool = False) -> dict:
    """:func:`measure` then :func:`score`."""
    return score(measure(cam, task, held_out, show_progress), task, held_out, decoder)


def _locate(cal_xy: np.ndarray, dn: list, held_out: HeldOut, decoder=None) -> dict:
    """Fit the calibration on ``dn[0]`` (the sweep at 0.5 m) and locate the held-out objects ``dn[1:]``, or
    apply ``decoder`` to them."""
    cal = None
    if decoder is None:
        obs_cal = np.column_stack(tr.features(dn[0].T))
        ok = np.all(np.isfinite(obs_cal), axis=1)
        cal = Calibration2D.fit(obs_cal[ok], cal_xy[ok], degree=3, metadata={"task": "tracking design",
                                                                           "depth_m": tr.CALIBRATION_DEPTH_M})
    predicted, truth, depth_of, n_extrapolated = [], [], [], 0
    for i, depth in enumerate(held_out.depths_m):
        if cal is None:
            predicted.append(decoder(dn[i + 1]))
        else:
            obs = np.column_stack(tr.features(dn[i + 1].T))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ExtrapolationWarning)  # counted below instead
                pred_m, extrapolated = cal.apply(obs, return_extrapolated=True)
            n_extrapolated += int(np.sum(extrapolated))
            predicted.append(tr.to_field(pred_m * depth / tr.CALIBRATION_DEPTH_M, depth))
        truth.append(held_out.q[i])
        depth_of.append(np.full(len(held_out.q[i]), depth))
    predicted, truth, depth_of = np.concatenate(predicted), np.concatenate(truth), np.concatenate(depth_of)
    finite = np.all(np.isfinite(predicted), axis=1)
    rates = error_rates(predicted[finite], truth[finite], 1.0)  # q is in units of the field
    err = 100 * np.hypot(*(predicted - truth).T)
    per_depth = [float(np.nanmean(err[depth_of == d])) for d in held_out.depths_m]
    return {
        "avg_error_pct": rates["avg_error_pct"],
        "max_error_pct": rates["max_error_pct"],
        "rms_error_pct": rates["rms_error_pct"],
        "n": int(finite.sum()),
        "n_without_estimate": int((~finite).sum()),
        "n_outside_calibrated_range": n_extrapolated if cal is not None else None,
        "per_depth_avg_error_pct": dict(zip([f"{d:.3f}" for d in held_out.depths_m], per_depth, strict=True)),
        "calibration_rms_residual_m": np.asarray(cal.rms_residual_m).tolist() if cal is not None else None,
        "arrays": {"predicted_q": predicted, "truth_q": truth, "depth_m": depth_of, "error_pct": err},
    }


__all__ = ["HeldOut", "evaluate", "irradiances", "measure", "score"]
