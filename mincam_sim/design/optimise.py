"""Build the tracking design problem from traced samples and run the optimiser (Dr.Jit AD in
``mincam_sim.render.differentiable``), from the paper's ramps as the starting point."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..masks import Mask
from . import parameterization as par
from . import tracking as tr
from .decoder import Decoder, poly_terms


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
        Training RMS error of the paper's ramps and of the result (mean of the last 20 steps) [fraction of the
        field].
    n_train : int
        Training objects.
    decoder : Decoder
        The polynomial decoder refitted on the final printed masks (training set, noisy read-out).
    reference_decoders : dict of Decoder
        The same decoder fitted for the printed paper ramps under each start's assignment (:data:`STARTS`):
        references that separate the masks' share of the gain from the decoder's.
    start : str
        The starting assignment kept (:data:`STARTS`), ``starts`` the training RMS of every start and
        ``histories`` their loss curves.
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


def training_set(task: tr.TrackingTask) -> tuple[list, np.ndarray]:
    """Square scenes per training depth and their targets (normalised field coordinates, (n, 2))."""
    from ..render.differentiable import SquareScenes

    rng = np.random.default_rng([task.seed, 11])
    scenes, targets = [], []
    for depth in task.train_depths_m:
        q, sizes, radiance = tr.random_objects(rng, task.frames_per_depth)
        scenes.append(SquareScenes(depth, tr.to_metres(q, depth), sizes, radiance))
        targets.append(q)
    return scenes, np.concatenate(targets)


def build_problem(task: tr.TrackingTask, show_progress: bool = False):
    """Trace the training samples through the mincam geometry and bin them into per-mixel linear models."""
    from ..progress import progress
    from ..render import differentiable as dz

    dots = task.dot_shape()
    film = task.film()
    scenes, targets = training_set(task)
    cam = tr.mincam(tr.paper_masks(8))  # the geometry; masks are the design variables
    bodies = dz.bodies_scene(cam)
    matrices = []
    for k in progress(range(len(cam)), desc="tracing training samples", disable=not show_progress, unit="mixel"):
        rows = []
        for i, sc in enumerate(scenes):
            smp = dz.mixel_samples(cam, k, sc, strata=task.strata, seed=task.seed * 1000 + i, bodies=bodies)
            rows.append(dz.design_matrix(smp, dots))
        matrices.append(np.concatenate(rows))
    # Fixed exposure: the brightest training reading of a fully clear print fills EXPOSURE_FILL of the range.
    peak = max(float((a * film.t_max).sum(axis=1).max()) for a in matrices)
    s = tr.sensor().auto_exposed(peak, tr.EXPOSURE_FILL)
    gain = s.dn_per_irradiance  # DN per W/m^2 (expected(1) - expected(0) saturates: peaks are ~0.01 W/m^2)
    index, weight = par.bilinear_upsample(task.grid, dots)
    problem = dz.DesignProblem(
        matrices=matrices, upsample_index=index, upsample_weight=weight, targets=targets,
        features=tr.FEATURES[task.decoder], n_params=task.grid**2, t_min=film.t_min, t_max=film.t_max, gamma=film.gamma,
        levels=film.levels, dn_per_w_m2=gain, noise_dn=lambda irr: tr.change_sigma_dn(s, irr))
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


def design(task: tr.TrackingTask, show_progress: bool = False) -> Design:
    """Optimise the four masks (and the calibration in the loop) for the tracking task."""
    from ..render import differentiable as dz

    problem = build_problem(task, show_progress)
    # Multi-start: the paper's ramps under the four assignments of each pair's two ramps to its two mixels
    # (gradient descent cannot turn a ramp into its complement); the lowest *training* loss wins.
    runs = {}
    for label, (swap_x, swap_y) in STARTS.items():
        runs[label] = dz.optimise_masks(problem, initial_logits(task, swap_x, swap_y), iterations=task.iterations,
                                        learning_rate=task.learning_rate, seed=task.seed,
                                        show_progress=show_progress)
    scores = {k: float(np.mean(r.loss_history[-20:])) for k, r in runs.items()}
    chosen = min(scores, key=scores.get)
    result = runs[chosen]
    index, weight = problem.upsample_index, problem.upsample_weight
    dots = task.dot_shape()
    film = task.film()
    printer = [par.printable_mask(par.dots_from_logits(t, index, weight, film), dots, tr.MASK_SIZE_M,
                                  f"designed_{name}", task="tracking", grid=task.grid)
               for t, name in zip(result.logits, tr.POSITIONS, strict=True)]
    decoder = fit_decoder(problem, [film.print(m).transmission.ravel() for m in printer], task)
    ramps = tr.paper_masks()
    references = {}
    for label, (swap_x, swap_y) in STARTS.items():
        order = ([1, 0] if swap_x else [0, 1]) + ([3, 2] if swap_y else [2, 3])
        references[label] = fit_decoder(problem, [film.print(ramps[i]).transmission.ravel() for i in order], task)
    return Design(printer, result.loss_history, float(runs["paper"].loss_history[0]),
                  scores[chosen], len(problem.targets), decoder, references, chosen,
                  {k: {"start_rms": float(r.loss_history[0]), "end_rms": scores[k]} for k, r in runs.items()},
                  {k: r.loss_history for k, r in runs.items()})


def fit_decoder(problem, transmissions: list[np.ndarray], task: tr.TrackingTask, draws: int = 4) -> Decoder:
    """Least-squares polynomial decoder for printed masks (flat dot transmissions) on the training set, from
    ``draws`` noisy read-outs of every object (NumPy, the optimiser's linear model)."""
    irr = np.array([a @ t for a, t in zip(problem.matrices, transmissions, strict=True)])
    rng = np.random.default_rng([task.seed, 23])
    sigma = problem.noise_dn(irr)
    dn = np.concatenate([problem.dn_per_w_m2 * irr + sigma * rng.standard_normal(irr.shape)
                         for _ in range(draws)], axis=1)
    targets = np.tile(problem.targets, (draws, 1))
    design_matrix = poly_terms(list(tr.FEATURES[task.decoder](dn)), 3)
    ok = np.all(np.isfinite(design_matrix), axis=1)
    coef = np.stack([np.linalg.lstsq(design_matrix[ok], targets[ok, i], rcond=None)[0] for i in range(2)])
    return Decoder(task.decoder, 3, coef)


__all__ = ["STARTS", "Design", "build_problem", "design", "fit_decoder", "initial_logits", "training_set"]
