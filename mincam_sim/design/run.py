"""One design run: gradient check, optimisation, physical held-out evaluation against the paper's ramps, and
the outputs (``design.json``, print-ready PNG masks, a print sheet of all four at their places with its notes,
figures), all written atomically. A finished design of another identity in the same folder is refused."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..atomic import atomic_path, atomic_save_npz, atomic_write_json
from ..errors import StaleResultError
from ..identity import library_versions
from ..masks import export_print_png
from ..masks.sheet import write_print_sheet
from ..store import check_identity
from . import tracking as tr

TASKS = ("tracking",)


def _summary(res: dict) -> dict:
    return {k: v for k, v in res.items() if k != "arrays"}


IDENTITY_FILE = "design_identity.json"


def design_identity(task_name: str, task: tr.TrackingTask, quick: bool, seed: int) -> dict:
    """Everything a design's outputs depend on: task, its sizes (dpi included), seed and library versions."""
    return {"task": task_name, "quick": bool(quick), "seed": int(seed), "setup": task.as_dict(),
            "versions": library_versions()}


def run_design(task_name: str, out_dir: str | Path, quick: bool = False, seed: int = 0, dpi: float = 600.0,
               show_progress: bool = False, overwrite: bool = False) -> dict:
    """Design masks for ``task_name`` and write the outputs in ``out_dir``; return the ``design.json`` dict.

    Parameters
    ----------
    task_name : {"tracking"}
        The task (see :mod:`mincam_sim.design.tracking`).
    out_dir : path
        Output directory (created).
    quick : bool
        Smaller training and evaluation sets (a few minutes on 2 cores).
    seed : int
        Seed of the training and held-out draws, the sensor noise and the Monte Carlo samples.
    dpi : float
        Printer resolution [dots per inch] of the film and of the PNG masks.
    overwrite : bool
        Replace a finished design of another identity (task, sizes, seed, dpi, versions) in ``out_dir``;
        without it that design is refused (StaleResultError naming what changed), as other runs are.
    """
    from dataclasses import asdict, replace

    from .evaluate import HeldOut, measure, score
    from .gradcheck import check_gradients
    from .optimise import design
    from .report import plot_error_vs_depth, plot_loss, plot_masks

    if task_name not in TASKS:
        raise ValueError(f"unknown design task {task_name!r}: choose one of {', '.join(TASKS)}")
    if not (np.isfinite(dpi) and dpi > 0):
        raise ValueError(f"dpi must be a positive number of dots per inch, got {dpi!r}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    task = tr.TrackingTask.quick(seed) if quick else tr.TrackingTask(seed=seed)
    task = replace(task, dpi=float(dpi))
    film = task.film()
    identity = design_identity(task_name, task, quick, seed)
    if (out / "design.json").exists() and not overwrite:
        if not (out / IDENTITY_FILE).exists():
            raise StaleResultError(f"{out} holds a finished design without a record of what it was computed from "
                                   "(an older version); choose another output directory or rerun with --overwrite")
        check_identity(out, identity, name=IDENTITY_FILE)

    grad = check_gradients(seed=seed)
    t_check = time.perf_counter() - start
    result = design(task, show_progress=show_progress)
    t_design = time.perf_counter() - start - t_check

    held_out = HeldOut.draw(task)
    hand = [film.print(m) for m in tr.paper_masks()]
    designed = [film.print(m) for m in result.printer_masks]
    learned = result.decoder if task.decoder == "learned" else None
    swapped = [film.print(m) for m in tr.paper_masks_swapped_x()]
    readings = {label: measure(tr.mincam(masks), task, held_out, show_progress=show_progress)
                for label, masks in (("hand", hand), ("swapped", swapped), ("designed", designed))}
    baseline = score(readings["hand"], task, held_out)
    ours = score(readings["designed"], task, held_out, decoder=learned)
    # references that split the gain between the masks and the decoder
    references = {
        "paper_ramps_with_learned_decoder": score(readings["hand"], task, held_out,
                                                  decoder=result.reference_decoders["paper"]),
        "paper_ramps_x_pair_swapped": score(readings["swapped"], task, held_out),
        "paper_ramps_x_pair_swapped_with_learned_decoder": score(
            readings["swapped"], task, held_out, decoder=result.reference_decoders["x pair swapped"]),
        "designed_masks_with_paper_calibration": score(readings["designed"], task, held_out),
    }
    t_eval = time.perf_counter() - start - t_check - t_design

    for mask, name in zip(result.printer_masks, tr.POSITIONS, strict=True):
        path = out / f"mask_designed_{name}.png"
        with atomic_path(path) as tmp:
            export_print_png(mask, tmp, dpi=dpi, film=film)
    if learned is not None:
        result.decoder.to_json(out / "decoder.json")
    plot_loss(result.histories, result.start, out / "loss.png")
    labels = [f"{p} ({n})" for p, n in zip(tr.POSITIONS, tr.NAMES, strict=True)]
    plot_masks({"paper ramps": hand, "designed": designed}, labels, out / "masks.png")
    plot_error_vs_depth({"paper ramps": baseline, "designed": ours,
                         "ramps, x pair swapped": references["paper_ramps_x_pair_swapped"]},
                        out / "error_vs_depth.png")
    atomic_save_npz(out / "design_data.npz", printer_input=np.stack([m.transmission for m in result.printer_masks]),
                    printed_transmission=np.stack([m.transmission for m in designed]), loss_rms=result.loss_rms,
                    **{f"{who}_{k}": v for who, r in (("baseline", baseline), ("designed", ours))
                       for k, v in r["arrays"].items()})
    ratio = ours["avg_error_pct"] / baseline["avg_error_pct"]
    report = {
        "task": task_name,
        "quick": quick,
        "gradient_check": {"max_rel_error": grad["max_rel_error"], "n_checked": grad["n_checked"],
                           "checks": [{"parameter": c["parameter"], "rel_error": c["rel_error"]}
                                      for c in grad["checks"]],
                           "method": "forward-mode AD vs central differences, same seed"},
        "baseline": {**_summary(baseline), "masks": "paper ramps x, 1-x, y, 1-y as printed on the film"},
        "designed": {**_summary(ours), "masks": "optimised, as printed on the film",
                     "decoder": ("cubic polynomial of the four normalised changes, fitted in the design loop on "
                                 "the training depths (no physical calibration)" if learned is not None else
                                 "Eq. 7 ratios, cubic calibration at 0.5 m")},
        "references": {k: _summary(v) for k, v in references.items()},
        "goal": {"designed_over_baseline_avg": ratio, "met": bool(ratio <= 0.5),
                 "statement": "designed average error <= half the baseline's, held-out scenes, physical form"},
        "training": {"rms_error_start_pct": 100 * result.initial_rms, "rms_error_end_pct": 100 * result.final_rms,
                     "start_kept": result.start,
                     "starts": {k: {kk: 100 * vv for kk, vv in v.items()} for k, v in result.starts.items()},
                     "objects": result.n_train, "iterations": task.iterations,
                     "loss": "mean squared position error, noisy 12-bit read-out, cubic fitted per step"},
        "setup": {"spacing_m": tr.SPACING_M, "d_f_m": tr.D_F_M, "detector_size_m": tr.DETECTOR_SIZE_M,
                  "mask_size_m": tr.MASK_SIZE_M, "field_m": tr.FIELD_M, "depth_range_m": list(tr.DEPTH_RANGE_M),
                  "calibration_depth_m": tr.CALIBRATION_DEPTH_M, "working_radius": tr.WORKING_RADIUS,
                  "held_out_depths_m": held_out.depths_m.tolist(), "film": asdict(film), "task": task.as_dict(),
                  "error_definition": "|predicted - true| in normalised field coordinates, % of the field "
                                      "(50 cm at 0.5 m, scaled with depth)"},
        "runtime_s": {"gradient_check": t_check, "design": t_design, "evaluation": t_eval,
                      "total": time.perf_counter() - start},
    }
    write_print_sheet(list(result.printer_masks), list(tr.OFFSETS_M), dpi, film, out / "print_sheet.png",
                      names=labels, title=f"designed {task_name} masks (seed {seed}), seen from the detectors")
    atomic_write_json(out / "design.json", report, indent=1, default=float)
    check_identity(out, identity, overwrite=True, name=IDENTITY_FILE)  # last: the design is finished
    return report


__all__ = ["TASKS", "run_design"]
