"""One design run: gradient check, optimisation, physical held-out evaluation against the paper's ramps, and
the outputs (``design.json``, print-ready PNG masks, a print sheet of all four at their places with its notes,
figures), all written atomically. A finished design of another identity in the same folder is refused."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mincam_sim.design import tracking as tr
from mincam_sim.design.scene_run import refuse_another_design as _refuse_another_design
from mincam_sim.design.tasks import TASK_NAMES
from mincam_sim.masks import export_print_png
from mincam_sim.masks.sheet import check_print_sheet, write_print_sheet
from mincam_sim.storage.atomic import atomic_path, atomic_save_npz, atomic_write_json
from mincam_sim.storage.identity import build_identity
from mincam_sim.storage.store import check_identity

TASKS = TASK_NAMES  # every registered task


def _summary(res: dict) -> dict:
    return {k: v for k, v in res.items() if k != "arrays"}


IDENTITY_FILE = "design_identity.json"


def design_identity(task_name: str, task: tr.TrackingTask, quick: bool, seed: int, baselines: bool = True) -> dict:
    """Everything a design's outputs depend on: task, its sizes (dpi included), seed and library versions; a
    design without the field's baselines says so in its setup (the default's identity is the task's alone)."""
    setup = task.as_dict() if baselines else {**task.as_dict(), "field_baselines": False}
    return build_identity("design", {"task": task_name, "quick": bool(quick), "seed": int(seed), "setup": setup})


BASELINE = "current ramps, Eq. 7"
DESIGNED = "designed, learned decoder"
RAMPS_LEARNED = "current ramps, learned decoder"
MIRRORED = "mirrored ramps (old layout), Eq. 7"
RANDOM = "random masks, learned decoder"
PCA = "PCA masks, learned decoder"
IDEAL_TRAINED = "ideal-trained masks, learned decoder"
# the summary's keys (design.json ``suite.summary``) and the suite's labels they stand for
SUMMARY_BASELINES = {"hand": BASELINE, "random": RANDOM, "pca": PCA, "ideal_trained": IDEAL_TRAINED}


def _sheet_offsets_m(task: tr.TrackingTask) -> list[tuple[float, float]]:
    """Where each mask sits on the print sheet [m]: the cross's offsets at the task's spacing."""
    return [(dx / tr.SPACING_M * task.spacing_m, dy / tr.SPACING_M * task.spacing_m) for dx, dy in tr.OFFSETS_M]


def _sheet_names(task: tr.TrackingTask) -> tuple[list[str], str]:
    """The labels of the four masks on the print sheet and its title (what :func:`run_design` writes)."""
    return ([f"{p} mixel" for p in tr.POSITIONS],
            f"designed tracking masks (seed {task.seed}), seen from the detectors")


def check_printable(task: tr.TrackingTask) -> None:
    """Refuse a task whose print sheet (the four masks at their places, at its spacing and dpi) cannot be written:
    what the run writes last, refused before any work (:func:`~mincam_sim.masks.sheet.check_print_sheet`).

    Raises
    ------
    checks.FieldError
        ``spacing_m`` and ``dpi`` whose sheet holds more than ``MAX_TEXELS`` dots (naming the largest spacing at
        this dpi and the dpis that work at this spacing), each inside the ranges of :data:`~.checks.SHARED` (a dpi
        too low for the masks' dots is refused by the task itself, :func:`~.checks.check_shared`).
    """
    from mincam_sim.design import checks
    from mincam_sim.masks.mask import MAX_TEXELS
    from mincam_sim.masks.sheet import print_sheet_dots

    masks = task.baseline_masks(16)  # the sheet depends on the masks' sizes and places, not on their texels
    names, title = _sheet_names(task)

    def dots(spacing_m: float, dpi: float) -> tuple[int, int]:
        offsets = [(dx / tr.SPACING_M * spacing_m, dy / tr.SPACING_M * spacing_m) for dx, dy in tr.OFFSETS_M]
        return print_sheet_dots(masks, offsets, dpi, task.film(), names, title)

    def fits(spacing_m: float, dpi: float) -> bool:
        width, height = dots(spacing_m, dpi)
        return width * height <= MAX_TEXELS

    lowest_dpi = float(checks.lowest_printable_dpi(tr.MASK_SIZE_M))  # a lower one is refused with the task
    if fits(task.spacing_m, task.dpi):
        check_print_sheet(masks, _sheet_offsets_m(task), task.dpi, task.film(), names, title)
        return
    dpi_range, spacing_range = checks.SHARED["dpi"], checks.SHARED["spacing_m"]
    width, height = dots(task.spacing_m, task.dpi)
    at_dpi = (f"at {task.dpi:g} dpi the spacing can be at most "
              f"{np.floor(_largest(lambda s: fits(s, task.dpi), spacing_range.low, spacing_range.high) * 1e4) / 1e4:g}"
              " m" if fits(spacing_range.low, task.dpi) else f"no spacing fits at {task.dpi:g} dpi")
    at_spacing = (f"at spacing {task.spacing_m:g} m the dpi can be {lowest_dpi:g} to "
                  f"{np.floor(_largest(lambda d: fits(task.spacing_m, d), lowest_dpi, dpi_range.high)):g}"
                  if fits(task.spacing_m, lowest_dpi) else f"no dpi fits at spacing {task.spacing_m:g} m")
    checks.refuse(task, ("spacing_m", "dpi"),
                  f"must give a print sheet of at most {MAX_TEXELS} dots (the four masks at their places with "
                  f"margins, marks and notes; this one is {width} x {height}): {at_dpi}; {at_spacing}")


def _largest(fits: Callable[[float], bool], low: float, high: float, rel_tol: float = 1e-4) -> float:
    """The largest ``x`` in ``[low, high]`` with ``fits(x)``, given ``fits(low)`` and that ``fits`` holds on an
    interval starting at ``low`` (bisection to ``rel_tol`` of ``high``; the result itself fits)."""
    if fits(high):
        return high
    lo, hi = low, high
    while hi - lo > rel_tol * high:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    return lo


#: The sequence fields of :class:`~.tracking.TrackingTask`: field -> (length, None for any; its form and unit).
SEQUENCE_FIELDS: dict[str, tuple[int | None, str]] = {
    "train_depths_m": (None, "plane depths [m], like (0.35, 0.5, 0.7)"),
    "background_radiances": (None, "radiances [W m^-2 sr^-1], like (0.0, 0.2)"),
    "object_size_range_m": (2, "(min, max) sizes [m], like (0.01, 0.15)"),
    "bar_width_range_m": (2, "(min, max) widths [m], like (0.008, 0.02)"),
    "contrast_range": (2, "(min, max) radiances [W m^-2 sr^-1], like (0.05, 1.0)"),
    "background_contrast_range": (2, "(min, max) radiances [W m^-2 sr^-1], like (0.3, 1.0)"),
    "depth_range_m": (2, "(min, max) depths [m], like (0.3, 0.8)"),
}


def _check_sequences(overrides: dict) -> None:
    """Refuse a sequence field of ``overrides`` that is not a list or tuple of real numbers (of the right length):
    one :class:`~mincam_sim.errors.InputError` naming it and its form, before it is unpacked or converted."""
    from numbers import Real

    from mincam_sim.errors import InputError

    for key, (length, form) in SEQUENCE_FIELDS.items():
        if key not in overrides:
            continue
        value = overrides[key]
        items = list(value) if isinstance(value, list | tuple | np.ndarray) and np.ndim(value) == 1 else None
        if (items is None or not all(isinstance(v, Real) and not isinstance(v, bool | np.bool_) for v in items)
                or (length is not None and len(items) != length) or not items):
            count = f"{length} numbers" if length is not None else "a non-empty list or tuple of numbers"
            raise InputError(f"{key} must be {count}: {form}; got {value!r}")


def make_task(quick: bool = False, seed: int = 0, **overrides) -> tr.TrackingTask:
    """The task of a run: :meth:`TrackingTask.quick` or the full one, with ``overrides`` (task fields; a
    ``depth_range_m`` alone spreads the training planes evenly over it).

    A sequence field (:data:`SEQUENCE_FIELDS`) that is not a list or tuple of numbers is an
    :class:`~mincam_sim.errors.InputError`; the values themselves are the task's checks (a
    ``checks.FieldError``).
    """
    from dataclasses import fields

    from mincam_sim.errors import ConfigError

    known = {f.name for f in fields(tr.TrackingTask)}
    unknown = sorted(set(overrides) - known)
    if unknown:
        raise ConfigError(f"unknown design task field(s) {', '.join(unknown)}: choose from {', '.join(sorted(known))}")
    _check_sequences(overrides)
    base = tr.TrackingTask.quick(seed) if quick else tr.TrackingTask(seed=seed)
    if "depth_range_m" in overrides and "train_depths_m" not in overrides:
        lo, hi = overrides["depth_range_m"]
        overrides["train_depths_m"] = tuple(np.linspace(lo, hi, len(base.train_depths_m)).tolist())
    for key in SEQUENCE_FIELDS:
        if key in overrides:
            overrides[key] = tuple(float(v) for v in overrides[key])
    from dataclasses import replace

    return replace(base, **overrides)


def suite_entries(task: tr.TrackingTask, designed: list, decoder, ramps_decoder=None,
                  baselines: dict | None = None) -> list:
    """The mincams of the held-out suite: the baseline (the ramps of the layout the package builds, as printed,
    with the experiments' Eq. 7 and cubic calibration), the designed masks as printed with ``decoder``, the
    baseline's masks with the same kind of learned decoder (``ramps_decoder``, where given), the mirrored
    layout the package built before (a labelled extra row), and ``baselines`` (label -> (printed masks,
    decoder)): the random, PCA and ideal-trained masks."""
    from mincam_sim.design.suite import Entry

    film = task.film()
    current = [film.print(m) for m in task.baseline_masks()]
    entries = [Entry(BASELINE, task.mincam(current)), Entry(DESIGNED, task.mincam(designed), decoder)]
    if ramps_decoder is not None:
        entries.append(Entry(RAMPS_LEARNED, task.mincam(current), ramps_decoder, readings=BASELINE))
    entries.append(Entry(MIRRORED, task.mincam([film.print(m) for m in tr.paper_masks()])))
    for label, (masks, dec) in (baselines or {}).items():
        entries.append(Entry(label, task.mincam(masks), dec))
    return entries


@dataclass
class FieldBaselines:
    """The baselines the field uses (:mod:`mincam_sim.design.baselines`), each as printer input and with its
    decoder refitted on the physical model (as the designed masks' decoder is).

    Attributes
    ----------
    printer_masks : dict
        Suite label -> four masks (printer input, :data:`~.tracking.POSITIONS` order).
    decoders : dict
        Suite label -> :class:`~.decoder.Decoder` fitted on the physical training model (None with Eq. 7).
    ideal : Design
        The optimisation through the idealised model (its training history, kept start).
    """

    printer_masks: dict
    decoders: dict
    ideal: object


def field_baselines(task: tr.TrackingTask, result, show_progress: bool = False) -> FieldBaselines:
    """Random, PCA and ideal-trained masks for ``task``; each decoder refitted on ``result.problem`` (the
    physical training model) as ``result``'s was."""
    from mincam_sim.design import baselines as bl
    from mincam_sim.design.optimise import build_problem, design, fit_decoder, training_set

    ideal = design(task, show_progress=show_progress, problem=build_problem(task, show_progress, model="ideal"))
    frames, _ = training_set(task)
    _, _, images = bl.ideal_rows(task, frames)
    masks = {RANDOM: bl.random_masks(task), PCA: bl.pca_masks(task, images), IDEAL_TRAINED: ideal.printer_masks}
    film = task.film()
    draws = 0 if task.decoder_fit == "noiseless" else 4
    decoders = {label: (fit_decoder(result.problem, [film.print(m).transmission.ravel() for m in ms], task, draws)
                        if task.decoder == "learned" else None) for label, ms in masks.items()}
    return FieldBaselines(masks, decoders, ideal)


def run_design(task_name: str, out_dir: str | Path, quick: bool = False, seed: int = 0, dpi: float | None = None,
               show_progress: bool = False, overwrite: bool = False, baselines: bool = True, **overrides) -> dict:
    """Design masks for ``task_name`` and write the outputs in ``out_dir``; return the ``design.json`` dict.

    Parameters
    ----------
    task_name : str
        A registered task (``mincam_sim.design.tasks.REGISTRY``): ``tracking`` (:mod:`.tracking`) runs
        here; ``counting`` and ``depth`` run through ``mincam_sim.design.scene_run.run_scene_task``.
    out_dir : path
        Output directory (created).
    quick : bool
        Smaller training and evaluation sets (a few minutes on 2 cores).
    seed : int
        Seed of the training and held-out draws, the sensor noise and the Monte Carlo samples.
    dpi : float, optional
        Printer resolution [dots per inch] of the film and of the PNG masks (default: the task's, 600).
    overwrite : bool
        Replace a finished design of another identity (task, sizes, seed, dpi, versions) in ``out_dir``;
        without it that design is refused (StaleResultError naming what changed), as other runs are.
    baselines : bool
        Also make and measure the random, PCA and ideal-trained baselines (``field_baselines``; the
        ideal-trained one doubles the optimisation time); without them ``suite.summary`` has ``hand`` only.
    overrides
        Fields of ``TrackingTask`` (training distribution, geometry, film; ``make_task``), or of
        ``mincam_sim.design.scene_tasks.Sizes`` for the scene tasks.

    Raises
    ------
    InputError
        Before any work, for an argument of the wrong type or form (an unknown task, a non-path ``out_dir``, a
        ``seed`` or ``dpi`` out of range, a flag that is not a bool, a sequence field that is not a list of
        numbers), naming it and the expected form.
    ConfigError
        Before any work, for an unknown or out-of-range task field (``checks.FieldError``).
    """
    from mincam_sim.design.gradcheck import check_gradients
    from mincam_sim.design.optimise import design

    _check_request(task_name, out_dir, dpi, overrides, quick=quick, seed=seed, show_progress=show_progress,
                   overwrite=overwrite, baselines=baselines)
    if task_name != "tracking":
        from mincam_sim.design.tasks import get_task

        return get_task(task_name).run(out_dir, quick=quick, seed=seed, show_progress=show_progress,
                                       overwrite=overwrite, baselines=baselines, **overrides)
    start = time.perf_counter()
    task = make_task(quick, seed, **overrides)
    offsets_m = _sheet_offsets_m(task)
    check_printable(task)  # the sheet is written last: what it would refuse is refused before any work
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    identity = design_identity(task_name, task, quick, seed, baselines)
    _refuse_another_design(out, identity, overwrite)
    grad = check_gradients(seed=seed)
    t_check = time.perf_counter() - start
    result = design(task, show_progress=show_progress)
    t_design = time.perf_counter() - start - t_check
    field = field_baselines(task, result, show_progress) if baselines else None
    t_baselines = time.perf_counter() - start - t_check - t_design
    ev = _evaluate(task, result, show_progress, field)
    t_eval = time.perf_counter() - start - t_check - t_design - t_baselines
    labels = _write_figures_and_data(out, task, result, ev, field)
    report = {
        "task": task_name,
        "quick": quick,
        "gradient_check": {"max_rel_error": grad["max_rel_error"], "n_checked": grad["n_checked"],
                           "checks": [{"parameter": c["parameter"], "rel_error": c["rel_error"]}
                                      for c in grad["checks"]],
                           "method": "forward-mode AD vs central differences, same seed"},
        **_results_report(result, ev),
        "training": _training_report(result, task),
        **({"field_baselines": _field_baselines_report(field, task)} if field is not None else {}),
        "setup": _setup_report(task, ev.held_out),
        "runtime_s": {"gradient_check": t_check, "design": t_design, "baselines": t_baselines, "evaluation": t_eval,
                      "total": time.perf_counter() - start},
    }
    write_print_sheet(list(result.printer_masks), offsets_m, task.dpi, task.film(), out / "print_sheet.png",
                      names=labels, title=_sheet_names(task)[1])  # what check_printable measured
    atomic_write_json(out / "design.json", report, indent=1, default=float)
    check_identity(out, identity, overwrite=True, name=IDENTITY_FILE)  # last: the design is finished
    return report


def _check_request(task_name: str, out_dir: str | Path, dpi: float | None, overrides: dict, **flags) -> None:
    """Refuse a bad argument of :func:`run_design` before any work, with one
    :class:`~mincam_sim.errors.InputError` naming it and its form: an unknown task, an ``out_dir`` that is not a
    path, a ``seed`` or ``dpi`` out of range (:data:`~.checks.SHARED`), a flag (``flags``: ``quick``,
    ``show_progress``, ``overwrite``, ``baselines``) that is not a bool, a tracking task's sequence field
    that is not a list of numbers. A given ``dpi`` becomes the task's (in ``overrides``)."""
    import os

    from mincam_sim.design.checks import SHARED
    from mincam_sim.errors import InputError

    if not isinstance(task_name, str) or task_name not in TASKS:
        raise InputError(f"unknown design task {task_name!r}: choose one of {', '.join(TASKS)}")
    if not isinstance(out_dir, str | os.PathLike) or not str(out_dir):
        raise InputError(f"out_dir must be a folder path (a str or pathlib.Path), got {out_dir!r}")
    for name, value in flags.items():
        if name == "seed":
            if not SHARED["seed"].accepts(value):
                raise InputError(f"seed {SHARED['seed'].rule()}, got {value!r}")
        elif not isinstance(value, bool | np.bool_):
            raise InputError(f"{name} must be True or False, got {value!r}")
    if dpi is not None:
        if not SHARED["dpi"].accepts(dpi):
            raise InputError(f"dpi {SHARED['dpi'].rule()}, or None for the task's default, got {dpi!r}")
        overrides["dpi"] = float(dpi)
    if task_name == "tracking":
        _check_sequences(overrides)


@dataclass
class _Evaluation:
    """The physical held-out evaluation of a design: printed masks, scores, references and the suite."""

    held_out: object
    current: list
    designed: list
    learned: object
    baseline: dict
    ours: dict
    references: dict
    suite: dict


def _evaluate(task: tr.TrackingTask, result, show_progress: bool, field: FieldBaselines | None = None) -> _Evaluation:
    """Measure the printed current, mirrored and designed masks on the held-out draw (response maps), score
    them (with the references that split the gain between masks and decoder) and run the held-out suite."""
    from mincam_sim.design.evaluate import HeldOut, measure, score
    from mincam_sim.design.suite import evaluate_suite

    film = task.film()
    held_out = HeldOut.draw(task)
    current = [film.print(m) for m in task.baseline_masks()]
    mirrored = [film.print(m) for m in tr.paper_masks()]
    designed = [film.print(m) for m in result.printer_masks]
    learned = result.decoder if task.decoder == "learned" else None
    readings = {label: measure(task.mincam(masks), task, held_out, show_progress=show_progress)
                for label, masks in (("current", current), ("mirrored", mirrored), ("designed", designed))}
    baseline = score(readings["current"], task, held_out)
    ours = score(readings["designed"], task, held_out, decoder=learned)
    # references that split the gain between the masks and the decoder, and the old layout (labelled)
    references = {
        "current_ramps_with_learned_decoder": score(readings["current"], task, held_out,
                                                    decoder=result.reference_decoders["x pair swapped"]),
        "designed_masks_with_paper_calibration": score(readings["designed"], task, held_out),
        "mirrored_ramps_old_layout": score(readings["mirrored"], task, held_out),
    }
    baselines = ({label: ([film.print(m) for m in masks], field.decoders[label])
                  for label, masks in field.printer_masks.items()} if field is not None else None)
    entries = suite_entries(task, designed, learned, result.reference_decoders["x pair swapped"], baselines)
    suite = evaluate_suite(entries, task, task.suite_frames, task.suite_texels, task.suite_samples_per_texel,
                           baseline=BASELINE, show_progress=show_progress)
    return _Evaluation(held_out, current, designed, learned, baseline, ours, references, suite)


SUITE_KEYS = {BASELINE: "baseline", DESIGNED: "designed", RANDOM: "random", PCA: "pca",
              IDEAL_TRAINED: "ideal_trained"}  # short names of the suite's labels in design_data.npz


def _write_figures_and_data(out: Path, task: tr.TrackingTask, result, ev: _Evaluation,
                            field: FieldBaselines | None) -> list[str]:
    """The print-ready PNG masks, the decoder, the figures and ``design_data.npz``; returns the mixels' labels."""
    from mincam_sim.design.report import plot_error_vs_depth, plot_loss, plot_masks, plot_suite, plot_summary

    film = task.film()
    for mask, name in zip(result.printer_masks, tr.POSITIONS, strict=True):
        path = out / f"mask_designed_{name}.png"
        with atomic_path(path) as tmp:
            export_print_png(mask, tmp, dpi=task.dpi, film=film)
    if ev.learned is not None:
        result.decoder.to_json(out / "decoder.json")
    plot_loss(result.histories, result.start, out / "loss.png")
    labels = _sheet_names(task)[0]
    extra = field.printer_masks if field is not None else {}
    printed = {short: [film.print(m) for m in extra[label]] for label, short in SUITE_KEYS.items() if label in extra}
    plot_masks({"current ramps (baseline)": ev.current, "designed": ev.designed, **printed}, labels,
               out / "masks.png")
    plot_error_vs_depth({"current ramps, Eq. 7 (baseline)": ev.baseline, "designed": ev.ours,
                         "mirrored ramps (old layout)": ev.references["mirrored_ramps_old_layout"]},
                        out / "error_vs_depth.png")
    plot_suite(ev.suite, out / "suite.png")
    plot_summary(suite_summary(ev.suite), out / "baselines.png")
    atomic_save_npz(out / "design_data.npz", printer_input=np.stack([m.transmission for m in result.printer_masks]),
                    printed_transmission=np.stack([m.transmission for m in ev.designed]), loss_rms=result.loss_rms,
                    **{f"{who}_{k}": v for who, r in (("baseline", ev.baseline), ("designed", ev.ours))
                       for k, v in r["arrays"].items()},
                    **{f"{short}_printer_input": np.stack([m.transmission for m in extra[label]])
                       for label, short in SUITE_KEYS.items() if label in extra},
                    **{f"suite_{case}_{SUITE_KEYS[lab]}_error_pct": err
                       for case, rows in ev.suite["errors"].items() for lab, err in rows.items()
                       if lab in SUITE_KEYS})
    return labels


def _results_report(result, ev: _Evaluation) -> dict:
    """``baseline``, ``designed``, ``references``, ``suite`` and ``goal`` of ``design.json``."""
    suite = ev.suite
    ratio = ev.ours["avg_error_pct"] / ev.baseline["avg_error_pct"]
    suite_ratios = {c["name"]: c["ratio_to_baseline"][DESIGNED] for c in suite["cases"]}
    return {
        "baseline": {**_summary(ev.baseline), "label": BASELINE,
                     "masks": "ramps of the layout the package builds (optics.cross_layout: 1 - x left, x right, "
                              "y top, 1 - y bottom) as printed on the film",
                     "decoder": "Eq. 7 ratios, cubic calibration on 3 cm squares at 0.5 m (the experiments')"},
        "designed": {**_summary(ev.ours), "masks": "optimised, as printed on the film",
                     "decoder": ("cubic polynomial of the four normalised changes, fitted in the design loop on "
                                 "the training set (no physical calibration)" if ev.learned is not None else
                                 "Eq. 7 ratios, cubic calibration at 0.5 m")},
        "references": {k: _summary(v) for k, v in ev.references.items()},
        "suite": {"summary": suite_summary(suite),
                  "cases": suite["cases"], "baseline": BASELINE, "designed": DESIGNED,
                  "calibration_squares": suite["calibration_squares"],
                  "designed_over_baseline": suite_ratios,
                  "n_cases": len(suite_ratios),
                  "n_at_most_half": int(sum(r <= 0.5 for r in suite_ratios.values())),
                  "n_better": int(sum(r < 1 for r in suite_ratios.values())),
                  "n_worse": int(sum(r > 1 for r in suite_ratios.values())),
                  "protocol": "fixed cases outside the training set, response maps of the printed masks, 12-bit "
                              "sensor with noise; each case's exposure fills 0.7 of the range with its brightest "
                              "reading; target: centroid of the change; avg/max |error| in % of the field"},
        "goal": {"designed_over_baseline_avg": ratio, "met": bool(ratio <= 0.5),
                 "statement": "designed average error <= half the baseline's (current ramps, Eq. 7), old "
                              "held-out draw (squares 2-5 cm, black plane); the suite says where it holds"},
    }


def suite_summary(suite: dict) -> dict:
    """``suite.summary`` of ``design.json``: the mean over the suite's cases of each mincam's average error
    (lower is better), the designed masks' and every baseline's present in the suite (``hand``: the ramps with
    Eq. 7), and in how many cases the designed masks beat each."""
    cases = suite["cases"]

    def mean(label: str) -> float:
        return float(np.mean([c["rows"][label]["avg_error_pct"] for c in cases]))

    present = {key: label for key, label in SUMMARY_BASELINES.items() if label in cases[0]["rows"]}
    return {"metric": "avg_error_pct", "lower_is_better": True, "designed": mean(DESIGNED),
            "baselines": {key: mean(label) for key, label in present.items()},
            "n_cases": len(cases),
            "n_cases_designed_better": {key: int(sum(c["rows"][DESIGNED]["avg_error_pct"]
                                                     < c["rows"][label]["avg_error_pct"] for c in cases))
                                        for key, label in present.items()},
            "labels": {"designed": DESIGNED, **present},
            "definition": "mean over the suite's cases of each case's average |error| [% of the field]; every "
                          "learned decoder fitted on the physical (traced) training model, noiseless read-out"}


def _field_baselines_report(field: FieldBaselines, task: tr.TrackingTask) -> dict:
    """``field_baselines`` of ``design.json``: how the random, PCA and ideal-trained masks were made."""
    from mincam_sim.design.baselines import RANDOM_LOGIT_STD

    ideal = field.ideal
    return {
        "random": {"label": RANDOM, "masks": f"logits N(0, {RANDOM_LOGIT_STD}^2) on the {task.grid}x{task.grid} "
                                             f"grid, seed [{task.seed}, 61], the design's parameterisation"},
        "pca": {"label": PCA, "masks": "principal components 1-4 (left, right, top, bottom) of the training frames' "
                                       "changes on the dot grid (idealised mapping), mean removed; sign: largest "
                                       "|entry| positive; printer grey 0.5 + 0.5 p / max|p| (single rail, offset)"},
        "ideal_trained": {"label": IDEAL_TRAINED,
                          "masks": "the same optimiser and multi-start on the linear model built from DotProduct "
                                   "response maps (bare idealised model), then printed and measured physically",
                          "training_rms_end_pct_ideal_model": 100 * ideal.final_rms, "start_kept": ideal.start,
                          "candidates_rms_pct_ideal_model": {k: 100 * v for k, v in (ideal.candidates or {}).items()}},
        "decoder": "each refitted on the physical training model (noiseless read-out), as the designed masks' is",
    }


def _training_report(result, task: tr.TrackingTask) -> dict:
    """``training`` of ``design.json``: the optimisation's start, end, candidates and loss."""
    return {"rms_error_start_pct": 100 * result.initial_rms, "rms_error_end_pct": 100 * result.final_rms,
            "start_kept": result.start,
            "candidates_rms_pct": {k: 100 * v for k, v in (result.candidates or {}).items()},
            "starts": {k: {kk: 100 * vv for kk, vv in v.items()} for k, v in result.starts.items()},
            "objects": result.n_train, "iterations": task.iterations,
            "loss": "mean squared position error of the centroid of the change, noisy 12-bit read-out "
                    "at each frame's exposure (background included), cubic fitted per step"}


def _setup_report(task: tr.TrackingTask, held_out) -> dict:
    """``setup`` of ``design.json``: the geometry, the field, the held-out depths, the film and the task."""
    from dataclasses import asdict

    return {"spacing_m": task.spacing_m, "d_f_m": task.d_f_m, "detector_size_m": tr.DETECTOR_SIZE_M,
            "mask_size_m": tr.MASK_SIZE_M, "field_m": tr.FIELD_M, "depth_range_m": list(task.depth_range_m),
            "calibration_depth_m": tr.CALIBRATION_DEPTH_M, "working_radius": tr.WORKING_RADIUS,
            "held_out_depths_m": held_out.depths_m.tolist(), "film": asdict(task.film()), "task": task.as_dict(),
            "error_definition": "|predicted - true| in normalised field coordinates, % of the field "
                                "(50 cm at 0.5 m, scaled with depth)"}


__all__ = ["BASELINE", "DESIGNED", "IDEAL_TRAINED", "MIRRORED", "PCA", "RAMPS_LEARNED", "RANDOM", "SUMMARY_BASELINES",
           "SEQUENCE_FIELDS", "TASKS", "FieldBaselines", "field_baselines", "make_task", "run_design", "suite_entries",
           "suite_summary"]
