"""Build the tracking design problem from traced samples and run the optimiser (Dr.Jit AD in
``mincam_sim.render.gradients.differentiable``), from the paper's ramps as the starting point."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mincam_sim.design import parameterization as par
from mincam_sim.design import tracking as tr
from mincam_sim.design.decoder import Decoder
from mincam_sim.design.problem import DesignProblem
from mincam_sim.estimation.polynomial import poly_terms
from mincam_sim.masks import Mask


@dataclass
class Design:
    """The outcome of an optimisation.

    Attributes
    ----------
    printer_masks : list of Mask
        Printer input (grey values on the dot grid, nearest) per mixel; print with the task's film.
    loss_rms : (iterations,) ndarray
        Training RMS position error per step [fraction of the field].
    initial_rms, final_rms : float
        Training RMS error of the paper's ramps (first step) and of the kept candidate (fixed noise draws)
        [fraction of the field].
    n_train : int
        Training objects.
    decoder : Decoder
        The polynomial decoder refitted on the final printed masks (training set, noisy read-out).
    reference_decoders : dict of Decoder
        The same decoder fitted for the printed paper ramps under each start's assignment (:data:`STARTS`):
        references that separate the masks' share of the gain from the decoder's.
    start : str
        The candidate kept: an optimised start (:data:`STARTS`) or, where none beats it, an unoptimised one
        (``"<start> (start, unoptimised)"``); ``starts`` the loss of every run, ``histories`` their curves and
        ``candidates`` every candidate's training RMS on fixed noise draws (what chose the kept one).
    problem : DesignProblem
        The linear model it was trained on (its ``model``: ``"physical"`` or ``"ideal"``).
    """

    printer_masks: list[Mask]
    loss_rms: np.ndarray
    initial_rms: float
    final_rms: float
    n_train: int
    decoder: Decoder
    reference_decoders: dict
    start: str
    starts: dict
    histories: dict
    candidates: dict | None = None
    problem: object = None


@dataclass
class TrainingFrames:
    """The training frames as combinations of traced objects ("atoms", unit radiance, one set per depth).

    Attributes
    ----------
    atoms : list of SquareScenes
        Per training depth, the rectangles traced.
    frame_atoms : list of list of (depth index, atom index, radiance change)
        Each frame's objects: its change is the sum of their rows times their radiance change.
    background : (n_frames,) ndarray
        Each frame's background radiance [W m^-2 sr^-1] (0: black plane), on the plane of its first object.
    depth_index : (n_frames,) ndarray of int
        The training plane of each frame's first object.
    """

    atoms: list
    frame_atoms: list
    background: np.ndarray
    depth_index: np.ndarray


def _log_uniform(rng: np.random.Generator, lo: float, hi: float, n: int | None = None):
    return np.exp(rng.uniform(np.log(lo), np.log(hi), n))


def training_set(task: tr.TrackingTask) -> tuple[TrainingFrames, np.ndarray]:
    """Training frames over the task's distribution and their targets (normalised field coordinates of the
    centroid of each frame's change, (n, 2)).

    Per frame: a background radiance from ``background_radiances``; one object (two with probability
    ``two_object_fraction``, on the same plane), a square of side log-uniform in ``object_size_range_m`` or,
    with probability ``bar_fraction``, a bar; its radiance change uniform in ``contrast_range`` on a black plane,
    in ``background_contrast_range`` on a background (capped at a radiance of 1); positions uniform in the
    working disc, not overlapping.
    """
    from mincam_sim.render.gradients.differentiable import SquareScenes

    rng = np.random.default_rng([task.seed, 11])
    depths = np.asarray(task.train_depths_m, dtype=np.float64)
    per_depth: list[list] = [[] for _ in depths]  # (centre x, y, width, height) [m]
    frame_atoms, backgrounds, depth_index, targets = [], [], [], []

    def draw_object(di: int):
        if rng.random() < task.bar_fraction:
            width = rng.uniform(*task.bar_width_range_m)
            length = max(_log_uniform(rng, *task.object_size_range_m), 3 * width)
            return (length, width) if rng.random() < 0.5 else (width, length)
        side = _log_uniform(rng, *task.object_size_range_m)
        return side, side

    for di in range(len(depths)):
        for _ in range(task.frames_per_depth):
            bg = float(rng.choice(task.background_radiances))
            n_obj = 2 if rng.random() < task.two_object_fraction else 1
            while True:
                planes = [di] * n_obj
                r = tr.WORKING_RADIUS * np.sqrt(rng.random(n_obj))
                phi = 2 * np.pi * rng.random(n_obj)
                q = np.column_stack([r * np.cos(phi), r * np.sin(phi)])
                dims = [draw_object(p) for p in planes]
                if n_obj == 1:
                    break
                # no overlap as seen from the mincam (field units at the nearer plane)
                reach = [0.75 * max(w, h) * tr.CALIBRATION_DEPTH_M / (tr.FIELD_M * depths[p])
                         for (w, h), p in zip(dims, planes, strict=True)]
                if np.hypot(*(q[0] - q[1])) > reach[0] + reach[1]:
                    break
            objs, points, weights = [], [], []
            for (w, h), p, qq in zip(dims, planes, q, strict=True):
                change = min(rng.uniform(*(task.background_contrast_range if bg > 0 else task.contrast_range)),
                             1.0 - bg)
                xy = tr.to_metres(qq, depths[p])
                per_depth[p].append((xy[0], xy[1], w, h))
                objs.append((p, len(per_depth[p]) - 1, change))
                points.append([xy[0], xy[1], -depths[p]])
                weights.append(change * w * h)
            centroid = np.average(np.array(points), axis=0, weights=np.array(weights))
            targets.append(tr.to_field(centroid[:2], -centroid[2]))
            frame_atoms.append(objs)
            backgrounds.append(bg)
            depth_index.append(di)
    atoms = [SquareScenes(float(d), np.array(a)[:, :2], np.array(a)[:, 2], 1.0, np.array(a)[:, 3])
             for d, a in zip(depths, per_depth, strict=True)]
    return (TrainingFrames(atoms, frame_atoms, np.array(backgrounds), np.array(depth_index)),
            np.array(targets))


def plane_scene(depth_m: float):
    """A uniform plane of unit radiance covering every mixel's field of view at ``depth_m`` (the background)."""
    from mincam_sim.render.gradients.differentiable import SquareScenes

    return SquareScenes(depth_m, np.zeros((1, 2)), 2.0 * (0.6 * depth_m + 0.05), 1.0)


def _combine(rows_per_depth: list[np.ndarray], frames: TrainingFrames) -> np.ndarray:
    """Frame rows (n_frames, D): the sum of each frame's objects' rows times their radiance change."""
    out = np.zeros((len(frames.frame_atoms), rows_per_depth[0].shape[1]))
    for f, objs in enumerate(frames.frame_atoms):
        for di, ai, change in objs:
            out[f] += change * rows_per_depth[di][ai]
    return out


MODELS = ("physical", "ideal")


def traced_rows(task: tr.TrackingTask, frames: TrainingFrames, show_progress: bool = False):
    """The physical linear model: per mixel, the training frames' rows ``(n_frames, D)`` and a uniform plane of
    unit radiance per training depth ``(n_depths, D)``, traced through the mincam geometry (Monte Carlo) and
    binned per printer dot [W/m^2 per unit transmission]."""
    from mincam_sim.progress import progress
    from mincam_sim.render.gradients import differentiable as dz

    dots = task.dot_shape()
    cam = task.mincam(tr.paper_masks(8))  # the geometry; masks are the design variables
    bodies = dz.bodies_scene(cam)
    matrices, background_rows = [], []
    for k in progress(range(len(cam)), desc="tracing training samples", disable=not show_progress, unit="mixel"):
        rows = [dz.design_matrix(dz.mixel_samples(cam, k, sc, strata=task.strata, seed=task.seed * 1000 + i,
                                                  bodies=bodies), dots)
                for i, sc in enumerate(frames.atoms)]
        matrices.append(_combine(rows, frames))
        background_rows.append(np.concatenate([
            dz.design_matrix(dz.mixel_samples(cam, k, plane_scene(sc.depth_m), strata=64,
                                              seed=task.seed * 1000 + 500 + i, bodies=bodies), dots)
            for i, sc in enumerate(frames.atoms)]))
    return matrices, background_rows


def build_problem(task: tr.TrackingTask, show_progress: bool = False, model: str = "physical"):
    """Bin the training objects and backgrounds into per-mixel linear models, and set each frame's exposure and
    noise (its background and the brightest reading of a clear print: the brightest reading fills
    ``EXPOSURE_FILL``).

    ``model``: ``"physical"`` traces them through the mincam geometry (:func:`traced_rows`); ``"ideal"`` builds
    them from :class:`~mincam_sim.render.solvers.DotProduct` response maps, the idealised model
    (:func:`mincam_sim.design.baselines.ideal_rows`). The training frames, noise and exposure rules are the same.
    """
    if model not in MODELS:
        raise ValueError(f"build_problem model must be one of {', '.join(MODELS)}, got {model!r}")
    film = task.film()
    frames, targets = training_set(task)
    if model == "physical":
        matrices, background_rows = traced_rows(task, frames, show_progress)
    else:
        from mincam_sim.design.baselines import ideal_rows

        matrices, background_rows, _ = ideal_rows(task, frames)
    n_frames, n_depths = len(targets), len(frames.atoms)
    weights = np.zeros((n_frames, n_depths))
    weights[np.arange(n_frames), frames.depth_index] = frames.background
    # exposure groups: one per (plane, background), set on the brightest reading of a clear print
    clear_change = np.array([a.sum(axis=1) for a in matrices]) * film.t_max
    clear_bg = np.array([weights @ r.sum(axis=1) for r in background_rows]) * film.t_max
    common = tr.sensor().auto_exposed(float(clear_change.max()), tr.EXPOSURE_FILL)
    gain = common.dn_per_irradiance  # DN per W/m^2 of the optimiser's read-out (gain-free features)
    groups = []
    for key in sorted(set(zip(frames.depth_index.tolist(), frames.background.tolist(), strict=True))):
        idx = np.flatnonzero((frames.depth_index == key[0]) & (frames.background == key[1]))
        s = tr.sensor().auto_exposed(float((clear_change[:, idx] + clear_bg[:, idx]).max()), tr.EXPOSURE_FILL)
        groups.append((idx, s))

    def noise_dn(change: np.ndarray, background: np.ndarray) -> np.ndarray:
        sigma = np.empty_like(change)
        for idx, s in groups:
            sigma[:, idx] = (tr.change_sigma_dn(s, change[:, idx], background_w_m2=background[:, idx])
                             * gain / s.dn_per_irradiance)
        return sigma

    index, weight = par.bilinear_upsample(task.grid, task.dot_shape())
    problem = DesignProblem(
        matrices=matrices, upsample_index=index, upsample_weight=weight, targets=targets,
        features=tr.FEATURES[task.decoder], n_params=task.grid**2, t_min=film.t_min, t_max=film.t_max, gamma=film.gamma,
        levels=film.levels, dn_per_w_m2=gain, noise_dn=noise_dn, background_rows=background_rows,
        background_weights=weights, fit_noiseless=task.decoder_fit == "noiseless",
        error_cap=0.1 if task.decoder_fit == "noiseless" else None, model=model)
    return problem


def initial_logits(task: tr.TrackingTask, swap_x: bool = False, swap_y: bool = False) -> list[np.ndarray]:
    """Logits of the paper's ramps at the grid nodes (a starting point), optionally with the two ramps of the
    x pair (mixels 0, 1) or of the y pair (mixels 2, 3) exchanged between their mixels."""
    ramps = tr.paper_masks(256)
    order = [1, 0] if swap_x else [0, 1]
    order += [3, 2] if swap_y else [2, 3]
    return [par.logits_of(par.grid_values(ramps[i], task.grid)) for i in order]


STARTS = {"paper": (False, False), "x pair swapped": (True, False), "y pair swapped": (False, True),
          "both swapped": (True, True)}


def design(task: tr.TrackingTask, show_progress: bool = False, problem=None) -> Design:
    """Optimise the four masks (and the calibration in the loop) for the tracking task, on ``problem`` (default:
    the physical one, :func:`build_problem`; the idealised model's for the ``ideal_trained`` baseline)."""
    from mincam_sim.design.optimiser import optimise_masks

    problem = problem if problem is not None else build_problem(task, show_progress)
    # Multi-start: the paper's ramps under the four assignments of each pair's two ramps to its two mixels
    # (gradient descent cannot turn a ramp into its complement); the lowest *training* loss wins.
    runs = {}
    for label, (swap_x, swap_y) in STARTS.items():
        runs[label] = optimise_masks(problem, initial_logits(task, swap_x, swap_y), iterations=task.iterations,
                                     learning_rate=task.learning_rate, seed=task.seed, show_progress=show_progress)
    index, weight = problem.upsample_index, problem.upsample_weight
    dots = task.dot_shape()
    film = task.film()
    draws = 0 if task.decoder_fit == "noiseless" else 4
    ramps = tr.paper_masks()
    # candidates: every optimised run and every unoptimised start (the printed ramps), each scored with its
    # own decoder on the same fixed noise draws of the training set; the lowest training RMS is kept
    candidates = {}
    for label, r in runs.items():
        candidates[label] = [par.printable_mask(par.dots_from_logits(t, index, weight, film), dots, tr.MASK_SIZE_M,
                                                f"designed_{name}", task="tracking", grid=task.grid)
                             for t, name in zip(r.logits, tr.POSITIONS, strict=True)]
    references = {}
    for label, (swap_x, swap_y) in STARTS.items():
        order = ([1, 0] if swap_x else [0, 1]) + ([3, 2] if swap_y else [2, 3])
        references[label] = fit_decoder(problem, [film.print(ramps[i]).transmission.ravel() for i in order], task,
                                        draws)
        candidates[f"{label} (start, unoptimised)"] = [
            par.printable_mask(par.grid_values(ramps[i], dots[0]), dots, tr.MASK_SIZE_M, f"designed_{name}",
                               task="tracking", grid=dots[0]) for i, name in zip(order, tr.POSITIONS, strict=True)]
    decoders, scores = {}, {}
    for label, masks in candidates.items():
        t = [film.print(m).transmission.ravel() for m in masks]
        decoders[label] = fit_decoder(problem, t, task, draws)
        scores[label] = training_rms(problem, t, decoders[label], task)
    chosen = min(scores, key=scores.get)
    run = runs[chosen.split(" (start")[0]]
    return Design(candidates[chosen], run.loss_history, float(runs["paper"].loss_history[0]),
                  scores[chosen], len(problem.targets), decoders[chosen], references, chosen,
                  {k: {"start_rms": float(r.loss_history[0]), "end_rms": float(np.mean(r.loss_history[-20:]))}
                   for k, r in runs.items()},
                  {k: r.loss_history for k, r in runs.items()}, scores, problem)


def training_rms(problem, transmissions: list[np.ndarray], decoder: Decoder, task: tr.TrackingTask,
                 draws: int = 4) -> float:
    """RMS position error [fraction of the field] of masks and their decoder on ``draws`` fixed noisy read-outs
    of the training set, each frame's error capped at ``problem.error_cap`` as in the optimiser's loss."""
    irr = np.array([a @ t for a, t in zip(problem.matrices, transmissions, strict=True)])
    sigma = problem.sigma_dn(irr, transmissions)
    rng = np.random.default_rng([task.seed, 29])
    err2 = []
    for _ in range(draws):
        q = decoder(problem.dn_per_w_m2 * irr.T + (sigma * rng.standard_normal(irr.shape)).T)
        e2 = np.sum((q - problem.targets) ** 2, axis=1)
        if problem.error_cap is not None:
            e2 = np.where(np.isfinite(e2), np.minimum(e2, problem.error_cap**2), problem.error_cap**2)
        err2.append(e2)
    return float(np.sqrt(np.nanmean(np.concatenate(err2))))


def fit_decoder(problem, transmissions: list[np.ndarray], task: tr.TrackingTask, draws: int = 4) -> Decoder:
    """Least-squares polynomial decoder for printed masks (flat dot transmissions) on the training set, from
    ``draws`` noisy read-outs of every object, or from the noiseless read-out with ``draws=0`` (NumPy, the
    optimiser's linear model)."""
    irr = np.array([a @ t for a, t in zip(problem.matrices, transmissions, strict=True)])
    rng = np.random.default_rng([task.seed, 23])
    sigma = problem.sigma_dn(irr, transmissions) if draws else 0.0 * irr
    dn = np.concatenate([problem.dn_per_w_m2 * irr + sigma * rng.standard_normal(irr.shape)
                         for _ in range(max(draws, 1))], axis=1)
    targets = np.tile(problem.targets, (max(draws, 1), 1))
    design_matrix = np.stack(poly_terms(*tr.FEATURES[task.decoder](dn), degree=3), axis=-1)
    ok = np.all(np.isfinite(design_matrix), axis=1)
    coef = np.stack([np.linalg.lstsq(design_matrix[ok], targets[ok, i], rcond=None)[0] for i in range(2)])
    return Decoder(task.decoder, 3, coef)


__all__ = ["MODELS", "STARTS", "Design", "TrainingFrames", "build_problem", "design", "fit_decoder", "initial_logits",
           "plane_scene", "traced_rows", "training_rms", "training_set"]
