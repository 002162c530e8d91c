"""Masks and decoders for any :class:`~mincam_sim.design.scene_tasks.TaskSpec`, trained through the traced
physics, beside the baselines the field uses, on the task's held-out suite.

A run: draw the training frames, trace them through the mincam's geometry (per mixel a linear model on the
printer dots), set one fixed exposure (the brightest reading of a clear print fills ``EXPOSURE_FILL``), run the
optimiser of :mod:`.optimiser` (Adam on the logits through the film, the sensor noise and the task's decoder
fitted in the loop) from each of the task's starts and keep the start with the best training metric; then make
the baselines (hand where one exists, random, PCA of the training images, trained through the idealised
``DotProduct`` model), refit every decoder on the *physical* training model (noiseless read-out, as a user
calibrates printed masks), and measure all of them on the held-out suite: each case's frames traced with their
own scenes and Monte Carlo seed (never the training samples), read out at the task's exposure with 12-bit sensor
noise (the same draws for every mask set), decoded and scored.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from mincam_sim.design import parameterization as par
from mincam_sim.design import scene_tasks as st
from mincam_sim.design import tracking as tr
from mincam_sim.design.problem import DesignProblem
from mincam_sim.estimation.polynomial import poly_terms

FULL_SCALE_DN = 2.0**tr.BIT_DEPTH - 1
HAND = {"counting": "open apertures (clear film): the total light, the obvious hand design for a count",
        "depth": "the paper's ramps in the mirrored layout (x on the left mixel, 1 - x on the right, y top, 1 - y "
                 "bottom): the parallax of the x pair and of the y pair add in the decoder's third feature"}
DESIGNED, RANDOM, PCA, IDEAL, HAND_KEY = "designed", "random", "pca", "ideal_trained", "hand"


@dataclass
class Camera:
    """The task's fixed exposure: the sensor model at its gain, and the optimiser's problem built with it."""

    problem: DesignProblem
    sensor: object

    @property
    def gain(self) -> float:
        return float(self.problem.dn_per_w_m2)


def build_problem(spec: st.TaskSpec, sizes: st.Sizes, frames: st.Frames, matrices: list[np.ndarray],
                  model: str = "physical") -> Camera:
    """The optimiser's problem on ``matrices`` (per mixel (n_frames, D)), one exposure for all frames."""
    film = sizes.film()
    clear = max(float(a.sum(axis=1).max()) for a in matrices) * film.t_max
    sensor = tr.sensor().auto_exposed(clear, tr.EXPOSURE_FILL)

    def noise_dn(irradiance: np.ndarray) -> np.ndarray:
        return tr.change_sigma_dn(sensor, irradiance)

    index, weight = par.bilinear_upsample(sizes.grid, sizes.dot_shape())
    problem = DesignProblem(
        matrices=matrices, upsample_index=index, upsample_weight=weight, targets=frames.targets(spec.target),
        features=st.FEATURES[spec.features], n_params=sizes.grid**2, t_min=film.t_min, t_max=film.t_max,
        gamma=film.gamma, levels=film.levels, dn_per_w_m2=sensor.dn_per_irradiance, noise_dn=noise_dn,
        fit_noiseless=True, error_cap=spec.error_cap, model=model, degree=spec.degree)
    return Camera(problem, sensor)


def initial_logits(start: str, sizes: st.Sizes) -> list[np.ndarray]:
    """Logits of a start: ``ramps`` (the paper's, tracking order), ``grey`` (mid grey, perturbation N(0, 0.3^2)),
    ``random`` (N(0, 1)); seeded by the run's seed."""
    from mincam_sim.design.optimise import initial_logits as ramp_logits

    if start == "ramps":
        return ramp_logits(sizes)
    rng = np.random.default_rng([sizes.seed, 71 if start == "grey" else 73])
    std = 0.3 if start == "grey" else 1.0
    if start not in ("grey", "random"):
        raise ValueError(f"unknown start {start!r}: choose ramps, grey or random")
    return [std * rng.standard_normal(sizes.grid**2) for _ in range(4)]


def printed(masks: list, sizes: st.Sizes) -> list[np.ndarray]:
    """Flat dot transmissions of printer-input masks as the task's film prints them."""
    film = sizes.film()
    return [film.print(m).transmission.ravel() for m in masks]


def read_out(matrices: list, transmissions: list, camera: Camera, rng: np.random.Generator | None) -> np.ndarray:
    """Changes (n_frames, 4) [DN] at the camera's exposure: noiseless with ``rng=None``, else with 12-bit
    Gaussian noise, clipped to the range."""
    irr = np.array([a @ t for a, t in zip(matrices, transmissions, strict=True)])
    dn = camera.gain * irr
    if rng is not None:
        dn = dn + tr.change_sigma_dn(camera.sensor, irr) * rng.standard_normal(irr.shape)
    return np.minimum(dn, FULL_SCALE_DN).T


def calibrate(spec: st.TaskSpec, camera: Camera, frames: st.Frames, transmissions: list) -> st.SceneDecoder:
    """The decoder of printed masks fitted on the noiseless read-out of ``camera``'s training model."""
    return st.fit_decoder(spec, read_out(camera.problem.matrices, transmissions, camera, None),
                          frames.targets(spec.target))


def training_metric(spec: st.TaskSpec, camera: Camera, frames: st.Frames, transmissions: list,
                    decoder: st.SceneDecoder, seed: int, draws: int = 2) -> float:
    """The task's metric on ``draws`` fixed noisy read-outs of the training frames (chooses among starts)."""
    rng = np.random.default_rng([seed, 29])
    scores = [st.score(spec, decoder(read_out(camera.problem.matrices, transmissions, camera, rng)), frames)
              for _ in range(draws)]
    return st.metric(spec, np.concatenate(scores))


@dataclass
class Trained:
    """The masks kept (printer input), every start's loss history and training metric, and the start kept."""

    printer_masks: list
    histories: dict
    training_metric: dict
    start: str


def train(spec: st.TaskSpec, sizes: st.Sizes, camera: Camera, frames: st.Frames, show_progress: bool = False,
          label: str = "designed") -> Trained:
    """Optimise from each of the task's starts on ``camera.problem``; keep the candidate (every optimised start
    and every unoptimised start) with the best training metric on that problem (the physical one for the
    design, the idealised one for ``ideal_trained``): where optimisation does not help, the start is kept and
    ``start`` says so."""
    from mincam_sim.design.optimiser import optimise_masks

    problem, film, dots = camera.problem, sizes.film(), sizes.dot_shape()
    masks, histories, scores = {}, {}, {}

    def printable(logits: list, kind: str) -> list:
        return [par.printable_mask(par.dots_from_logits(t, problem.upsample_index, problem.upsample_weight, film),
                                   dots, tr.MASK_SIZE_M, f"{label}_{name}", task=spec.name, grid=sizes.grid,
                                   start=kind) for t, name in zip(logits, tr.POSITIONS, strict=True)]

    for start in spec.starts:
        r = optimise_masks(problem, initial_logits(start, sizes), iterations=sizes.iterations,
                           learning_rate=sizes.learning_rate, seed=sizes.seed, show_progress=show_progress)
        histories[start] = r.loss_history
        masks[start] = printable(r.logits, start)
        masks[f"{start} (start, unoptimised)"] = printable(initial_logits(start, sizes), start)
    for key, ms in masks.items():
        t = printed(ms, sizes)
        scores[key] = training_metric(spec, camera, frames, t, calibrate(spec, camera, frames, t), sizes.seed)
    pick = min if spec.lower_is_better else max
    kept = pick(masks, key=lambda s: scores[s])
    return Trained(masks[kept], histories, scores, kept)


def hand_masks(spec: st.TaskSpec, sizes: st.Sizes) -> list | None:
    """The hand design of the task where one exists (:data:`HAND`), as printer input."""
    if spec.name == "counting":
        dots = sizes.dot_shape()
        return [par.printable_mask(np.ones(int(np.prod(dots))), dots, tr.MASK_SIZE_M, f"open_{p}", task=spec.name)
                for p in tr.POSITIONS]
    if spec.name == "depth":
        return tr.paper_masks(256)
    return None


def reference_masks(spec: st.TaskSpec, sizes: st.Sizes) -> dict:
    """Extra rows of the suite (not baselines of the summary): for depth, the ramps of the layout the package
    builds (each ramp brightest on its own mixel's side: the x and y pairs' parallax cancels in the features)."""
    if spec.name == "depth":
        return {"ramps_current_layout": tr.current_layout_masks(256, sizes.spacing_m)}
    return {}


def baseline_masks(spec: st.TaskSpec, sizes: st.Sizes, frames: st.Frames, show_progress: bool = False) -> tuple:
    """Printer-input masks of the baselines ``{hand?, random, pca, ideal_trained}`` and the ideal training."""
    from mincam_sim.design import baselines as bl

    ideal_matrices, _, images = bl.ideal_rows(sizes, frames.planes)
    ideal_camera = build_problem(spec, sizes, frames, ideal_matrices, model="ideal")
    ideal = train(spec, sizes, ideal_camera, frames, show_progress, label="ideal_trained")
    out = {}
    hand = hand_masks(spec, sizes)
    if hand is not None:
        out[HAND_KEY] = hand
    out.update({RANDOM: bl.random_masks(sizes), PCA: bl.pca_masks(sizes, images), IDEAL: ideal.printer_masks})
    return out, ideal


def evaluate_suite(spec: st.TaskSpec, sizes: st.Sizes, camera: Camera, mask_sets: dict, decoders: dict,
                   show_progress: bool = False) -> dict:
    """Every mask set with its decoder on every held-out case: ``{"cases": [...], "per_frame": {case: {label:
    scores}}}``; each case traced with its own seed, the same noise draws for every mask set."""
    from mincam_sim.progress import progress

    cases, per_frame = [], {}
    for i, case in enumerate(progress(spec.suite, desc="held-out suite", disable=not show_progress, unit="case")):
        frames = st.draw_frames(case.scenes, sizes.suite_frames, [sizes.seed, 90, i])
        matrices = st.traced_rows(sizes, frames, 10_000 + 100 * sizes.seed + i)
        rows = {}
        for label, transmissions in mask_sets.items():
            dn = read_out(matrices, transmissions, camera, np.random.default_rng([sizes.seed, 97, i]))
            rows[label] = st.score(spec, decoders[label](dn), frames)
        per_frame[case.name] = rows
        cases.append({"name": case.name, "description": case.description, "n_frames": len(frames),
                      "depths_m": list(case.scenes.depths_m),
                      spec.metric: {label: st.metric(spec, s) for label, s in rows.items()}})
    return {"cases": cases, "per_frame": per_frame}


SUMMARY_KEYS = (DESIGNED, HAND_KEY, RANDOM, PCA, IDEAL)


def suite_summary(spec: st.TaskSpec, suite: dict) -> dict:
    """``suite.summary`` of ``design.json``: means over the cases, and in how many cases the design is better
    (or worse) than each baseline (the references' rows stay in the cases only)."""
    labels = [k for k in suite["cases"][0][spec.metric] if k in SUMMARY_KEYS]
    mean = {label: float(np.mean([c[spec.metric][label] for c in suite["cases"]])) for label in labels}
    sign = -1.0 if spec.lower_is_better else 1.0

    def better(label: str) -> int:
        return int(sum(sign * (c[spec.metric][DESIGNED] - c[spec.metric][label]) > 0 for c in suite["cases"]))

    others = [label for label in labels if label != DESIGNED]
    return {"metric": spec.metric, "lower_is_better": spec.lower_is_better, "designed": mean[DESIGNED],
            "baselines": {label: mean[label] for label in others}, "n_cases": len(suite["cases"]),
            "n_cases_designed_better": {label: better(label) for label in others},
            "n_cases_designed_worse": {label: int(sum(sign * (c[spec.metric][DESIGNED] - c[spec.metric][label]) < 0
                                                      for c in suite["cases"])) for label in others}}


def check_loss_gradient(problem: DesignProblem, logits: list, seed: int = 0, n_params: int = 6,
                        step: float = 1e-2) -> dict:
    """The optimiser's loss gradient (Dr.Jit reverse mode, float32) against central finite differences of a
    float64 NumPy twin, for the task's decoder: the same noise draw and noise sigma, the decoder's coefficients
    fitted on the noiseless read-out and held fixed (as in every optimiser step), no grey-level quantisation.
    Checked: the ``n_params`` logits of mixel 0 with the largest AD gradient. Returns ``{"rel_error", ...}``."""
    from mincam_sim.design.optimiser import masks_from_logits
    from mincam_sim.render.gradients import autodiff

    ad = autodiff.namespace()
    p = replace(problem, levels=None)
    logits = [np.asarray(t, dtype=np.float64) for t in logits]
    t_np = [_transmission_np(p, t) for t in logits]
    irr = np.array([a @ t for a, t in zip(p.matrices, t_np, strict=True)])
    sigma = p.sigma_dn(irr, t_np)
    eps = np.random.default_rng([seed, 5]).standard_normal(irr.shape)
    clean = np.stack(poly_terms(*p.features(list(p.dn_per_w_m2 * irr), np), degree=p.degree), axis=1)
    ok = np.all(np.isfinite(clean), axis=1)
    coef = np.stack([np.linalg.lstsq(clean[ok], p.targets[ok, i], rcond=None)[0] for i in range(p.targets.shape[1])])

    with ad.single_threaded():
        theta = [ad.Float(np.asarray(t, dtype=np.float32)) for t in logits]
        ad.xp.enable_grad(theta[0])
        masks = masks_from_logits(p, theta, straight_through=False, ad=ad)
        d = p.matrices[0].shape[1]
        n = len(p.targets)
        col = ad.arange(ad.UInt32, n * d) % d
        dn = [p.dn_per_w_m2 * ad.block_sum(ad.Float(np.asarray(a, dtype=np.float32).ravel())
                                           * ad.gather(ad.Float, m, col), d) + ad.Float(sigma[k] * eps[k])
              for k, (a, m) in enumerate(zip(p.matrices, masks, strict=True))]
        loss = _loss_ad(p, ad, poly_terms(*p.features(dn, ad.xp), degree=p.degree), coef)
        ad.backward(loss)
        grad_ad = np.asarray(ad.xp.grad(theta[0]), dtype=np.float64)
    chosen = np.argsort(-np.abs(grad_ad))[:n_params]
    fd = []
    for j in chosen:
        plus, minus = [t.copy() for t in logits], [t.copy() for t in logits]
        plus[0][j] += step
        minus[0][j] -= step
        fd.append((_loss_np(p, plus, sigma, eps, coef) - _loss_np(p, minus, sigma, eps, coef)) / (2 * step))
    fd = np.array(fd)
    rel = float(np.linalg.norm(grad_ad[chosen] - fd) / np.linalg.norm(fd))
    return {"rel_error": rel, "n_checked": int(len(chosen)), "ad": grad_ad[chosen].tolist(), "fd": fd.tolist(),
            "method": "reverse-mode AD (float32) vs central differences of a float64 twin, step "
                      f"{step:g} in the logits, same noise draw, decoder held fixed"}


def _transmission_np(p: DesignProblem, logits: np.ndarray) -> np.ndarray:
    z = (logits[p.upsample_index] * p.upsample_weight).sum(axis=1)
    return p.t_min + (p.t_max - p.t_min) * (1.0 / (1.0 + np.exp(-z))) ** p.gamma


def _loss_np(p: DesignProblem, logits: list, sigma: np.ndarray, eps: np.ndarray, coef: np.ndarray) -> float:
    t = [_transmission_np(p, z) for z in logits]
    dn = np.array([p.dn_per_w_m2 * (a @ tt) for a, tt in zip(p.matrices, t, strict=True)]) + sigma * eps
    terms = np.stack(poly_terms(*p.features(list(dn), np), degree=p.degree), axis=1)
    err2 = sum((terms @ c - p.targets[:, i]) ** 2 for i, c in enumerate(coef))
    if p.error_cap is not None:
        err2 = np.where(np.isfinite(err2), np.minimum(err2, p.error_cap**2), p.error_cap**2)
    return float(np.mean(err2))


def _loss_ad(p: DesignProblem, ad, terms: list, coef: np.ndarray):
    from mincam_sim.design.optimiser import _loss

    return _loss(p, ad, terms, coef, tuple(ad.Float(p.targets[:, i]) for i in range(p.targets.shape[1])))


def write_dataset(path: str | Path, measurements_dn: dict, frames: st.Frames, attrs: dict) -> Path:
    """Training data as a Zarr group (written beside, then moved in place): per mask set a ``(n_frames, 4)``
    array of changes [DN], and the labels ``count`` and ``depth_m`` [m] per frame; ``attrs`` describe them."""
    import zarr

    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    g = zarr.open_group(str(tmp), mode="w")
    for name, dn in measurements_dn.items():
        g.create_array(f"measurements_dn/{name}", data=np.asarray(dn, dtype=np.float64))
    g.create_array("count", data=frames.count.astype(np.int64))
    g.create_array("depth_m", data=frames.depth_m.astype(np.float64))
    g.attrs.update({"units": {"measurements_dn": "DN (background-subtracted change, 12-bit, task exposure)",
                              "count": "objects", "depth_m": "m"},
                    "mixels": list(tr.POSITIONS), **attrs})
    if path.exists():
        shutil.rmtree(path)
    tmp.rename(path)
    return path


__all__ = ["DESIGNED", "HAND", "IDEAL", "PCA", "RANDOM", "Camera", "Trained", "baseline_masks", "build_problem",
           "calibrate", "check_loss_gradient", "evaluate_suite", "hand_masks", "initial_logits", "printed",
           "read_out", "suite_summary", "train", "training_metric", "write_dataset"]
