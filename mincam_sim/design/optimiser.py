"""Adam on the mask logits through the linear forward model, the film, the sensor noise and a decoder fitted in
the loop: the design logic, written against the Dr.Jit array namespace of
:func:`mincam_sim.render.gradients.autodiff.namespace`
(so that this floor imports no renderer)."""

from __future__ import annotations

import numpy as np

from mincam_sim.design.problem import DesignProblem, DesignResult
from mincam_sim.estimation.polynomial import poly_terms
from mincam_sim.progress import bar


def _namespace():
    from mincam_sim.render.gradients import autodiff

    return autodiff.namespace()


def masks_from_logits(problem: DesignProblem, logits: list, straight_through: bool = True, ad=None) -> list:
    """Dr.Jit transmissions of the printed dots from parameter logits (sigmoid -> levels -> film).

    ``ad`` is the array namespace (:func:`mincam_sim.render.gradients.autodiff.namespace`, made when not given). With
    ``straight_through`` the printer's grey levels quantise the forward pass and pass the gradient unchanged.
    """
    ad = ad if ad is not None else _namespace()
    out = []
    idx = [ad.UInt32(problem.upsample_index[:, c].astype(np.uint32)) for c in range(4)]
    wts = [ad.Float(problem.upsample_weight[:, c]) for c in range(4)]
    for theta in logits:
        z = wts[0] * ad.gather(ad.Float, theta, idx[0])
        for c in range(1, 4):
            z += wts[c] * ad.gather(ad.Float, theta, idx[c])
        value = 1.0 / (1.0 + ad.exp(-z))  # printer grey value in (0, 1)
        if problem.levels is not None and straight_through:
            q = problem.levels - 1
            value = value + ad.detach(ad.round(value * q) / q - value)
        out.append(problem.t_min + (problem.t_max - problem.t_min) * ad.power(value, problem.gamma))
    return out


def optimise_masks(
    problem: DesignProblem,
    initial_logits: list,
    iterations: int = 300,
    learning_rate: float = 0.1,
    seed: int = 0,
    show_progress: bool = False,
) -> DesignResult:
    """Adam on the mask logits through the linear forward model, the sensor noise and the film.

    Each iteration: printed dot transmissions (straight-through quantisation to the film's levels) ->
    irradiances ``A_k @ T_k`` -> DN with Gaussian sensor noise (fresh draws from ``seed`` and the iteration)
    -> decoder features -> cubic polynomial whose coefficients are the least-squares fit on this batch (the
    calibration; by the envelope theorem the gradient with coefficients held fixed is the gradient of the
    calibrated loss), or on its noiseless read-out with ``problem.fit_noiseless`` (then the gradient holds
    the calibration fixed) -> mean squared position error. Returns the masks and the loss history.
    """
    ad = _namespace()
    n_frames = len(problem.targets)
    d = problem.matrices[0].shape[1]
    a_flat = [ad.Float(np.asarray(a, dtype=np.float32).ravel()) for a in problem.matrices]
    opt = ad.Adam(lr=learning_rate)
    keys = [f"theta{k}" for k in range(len(initial_logits))]
    for key, theta in zip(keys, initial_logits, strict=True):
        opt[key] = ad.Float(np.asarray(theta, dtype=np.float32))
    targets = tuple(ad.Float(problem.targets[:, i]) for i in range(problem.targets.shape[1]))
    history = []
    coef = None
    with ad.single_threaded():  # reverse passes scatter-add: one thread keeps their order (same seed, same numbers)
        with bar(iterations, "optimising masks", disable=not show_progress, unit="step") as b:
            for it in range(iterations):
                masks = masks_from_logits(problem, [opt[key] for key in keys], ad=ad)
                irr = [_matvec(ad, a_flat[k], masks[k], n_frames, d) for k in range(len(masks))]
                irr_np = np.array([np.asarray(ad.detach(e)) for e in irr], dtype=np.float64)
                terms = poly_terms(*problem.features(_noisy_dn(problem, ad, irr, irr_np, masks, seed, it), ad.xp),
                                   degree=problem.degree)
                coef = _fit_decoder(problem, ad, terms, irr_np)
                loss = _loss(problem, ad, terms, coef, targets)
                ad.backward(loss)
                opt.step()
                history.append(float(np.sqrt(np.asarray(loss, dtype=np.float64).ravel()[0])))
                b.update(1)
                b.set_postfix_str(f"rms {100 * history[-1]:.2f} % of field")
    logits_np = [np.asarray(opt[key], dtype=np.float64) for key in keys]
    final = masks_from_logits(problem, [ad.Float(t) for t in logits_np], ad=ad)
    return DesignResult(logits_np, [np.asarray(t, dtype=np.float64) for t in final], np.array(history), coef)


def _matvec(ad, a_flat, t, n_frames: int, d: int):
    """``A @ t`` per frame, ``A`` flattened row-major (n_frames * d lanes)."""
    col = ad.arange(ad.UInt32, n_frames * d) % d
    return ad.block_sum(a_flat * ad.gather(ad.Float, t, col), d)


def _noisy_dn(problem: DesignProblem, ad, irr: list, irr_np: np.ndarray, masks: list, seed: int, it: int) -> list:
    """The read-out of iteration ``it`` [DN]: gain x irradiance plus Gaussian noise of the frames' sigma
    (drawn from ``seed`` and ``it``; the noise carries no gradient)."""
    sigma = problem.sigma_dn(irr_np, [np.asarray(ad.detach(t)) for t in masks])
    eps = np.random.default_rng([int(seed), it]).standard_normal(sigma.shape)
    return [problem.dn_per_w_m2 * irr[k] + ad.Float(sigma[k] * eps[k]) for k in range(len(irr))]


def _fit_decoder(problem: DesignProblem, ad, terms: list, irr_np: np.ndarray) -> np.ndarray:
    """Least-squares coefficients (n_outputs, n_terms) of the polynomial on this batch's read-out, or on its noiseless
    read-out with ``problem.fit_noiseless``; frames with a non-finite feature are left out."""
    if problem.fit_noiseless:  # coefficients of the noiseless read-out, scored on the noisy one
        clean = [problem.dn_per_w_m2 * e for e in irr_np]
        with np.errstate(divide="ignore", invalid="ignore"):
            design = np.stack(poly_terms(*problem.features(clean, np), degree=problem.degree), axis=1)
    else:
        design = np.stack([np.asarray(ad.detach(t), dtype=np.float64) for t in terms], axis=1)
    ok = np.all(np.isfinite(design), axis=1)
    return np.stack([np.linalg.lstsq(design[ok], problem.targets[ok, i], rcond=None)[0]
                     for i in range(problem.targets.shape[1])])


def _loss(problem: DesignProblem, ad, terms: list, coef: np.ndarray, targets: tuple):
    """Mean squared error of the decoder ``coef`` (held fixed) on the noisy terms, summed over its outputs (the
    two position coordinates for tracking), each frame's error capped at ``problem.error_cap`` (a lost frame
    counts as that error and carries no gradient)."""
    err2 = None
    for c, target in zip(coef.astype(np.float32), targets, strict=True):
        c_ad = ad.Float(c)  # an array, not literals: one kernel
        pred = sum(ad.gather(ad.Float, c_ad, i) * t for i, t in enumerate(terms))
        err2 = ad.square(pred - target) if err2 is None else err2 + ad.square(pred - target)
    if problem.error_cap is not None:
        cap2 = float(problem.error_cap) ** 2
        err2 = ad.select(ad.isfinite(err2), ad.minimum(err2, cap2), cap2)
    return ad.mean(err2)


__all__ = ["masks_from_logits", "optimise_masks"]
