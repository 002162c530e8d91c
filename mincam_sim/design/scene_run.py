"""One design run of a scene task (:mod:`.scene_tasks`: counting, depth): training, the decoders' gradient
check, the baselines, the held-out suite and the outputs (``design.json``, print-ready PNG masks, ``decoder.json``,
``suite.png``, ``training.zarr``), all written atomically; a finished design of another identity is refused."""

from __future__ import annotations

import time
from dataclasses import fields, replace
from pathlib import Path

import numpy as np

from mincam_sim.design import scene_design as sd
from mincam_sim.design import scene_tasks as st
from mincam_sim.design import tracking as tr
from mincam_sim.errors import ConfigError, StaleResultError
from mincam_sim.masks import export_print_png
from mincam_sim.storage.atomic import atomic_path, atomic_write_json
from mincam_sim.storage.identity import build_identity
from mincam_sim.storage.store import check_identity

IDENTITY_FILE = "design_identity.json"


def make_sizes(spec: st.TaskSpec, quick: bool = False, seed: int = 0, **overrides) -> st.Sizes:
    """The sizes of a run (:meth:`Sizes.quick` or the full ones, training frames per plane and grid from the
    task's ``frames_per_depth``, ``grid`` and ``learning_rate``), with ``overrides`` (fields of ``Sizes``);
    sizes whose arrays would not fit in memory are refused naming the fields (:func:`~.scene_tasks.check_sizes_fit`)."""
    known = {f.name for f in fields(st.Sizes)}
    unknown = sorted(set(overrides) - known)
    if unknown:
        raise ConfigError(f"unknown field(s) {', '.join(unknown)} for design task {spec.name!r}: choose from "
                          f"{', '.join(sorted(known))}")
    base = st.Sizes.quick(seed) if quick else st.Sizes(seed=seed)
    overrides.setdefault("frames_per_depth", spec.frames_per_depth[0 if quick else 1])
    overrides.setdefault("grid", spec.grid)
    overrides.setdefault("learning_rate", spec.learning_rate)
    sizes = replace(base, **overrides)
    st.check_sizes_fit(spec, sizes)
    return sizes


def refuse_another_design(out: Path, identity: dict, overwrite: bool) -> None:
    """A finished design in ``out`` of another identity (or of none recorded) is refused unless ``overwrite``
    (every design task's rule)."""
    if (out / "design.json").exists() and not overwrite:
        if not (out / IDENTITY_FILE).exists():
            raise StaleResultError(f"{out} holds a finished design without a record of what it was computed from "
                                   "(an older version); choose another output directory or rerun with --overwrite")
        check_identity(out, identity, name=IDENTITY_FILE)


def run_scene_task(spec: st.TaskSpec, out_dir: str | Path, quick: bool = False, seed: int = 0,
                   show_progress: bool = False, overwrite: bool = False, baselines: bool = True,
                   **overrides) -> dict:
    """Design masks for ``spec`` and write the outputs in ``out_dir``; return the ``design.json`` dict.

    ``baselines=False`` measures the designed masks (and the hand design where there is one) only.
    ``overrides``: fields of :class:`~mincam_sim.design.scene_tasks.Sizes` (``dpi`` among them).
    """
    start = time.perf_counter()
    sizes = make_sizes(spec, quick, seed, **overrides)
    identity = build_identity("design", {"task": spec.name, "quick": bool(quick), "seed": int(seed),
                                         "setup": {**sizes.as_dict(), "spec": spec.as_dict(),
                                                   "field_baselines": bool(baselines)}})
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    refuse_another_design(out, identity, overwrite)
    frames = st.draw_frames(spec.train, sizes.frames_per_depth * len(spec.train.depths_m), [seed, 11])
    camera = sd.build_problem(spec, sizes, frames, st.traced_rows(sizes, frames, seed))
    grad = sd.check_loss_gradient(camera.problem, sd.initial_logits(spec.starts[0], sizes), seed=seed)
    t_trace = time.perf_counter() - start
    trained = sd.train(spec, sizes, camera, frames, show_progress)
    t_design = time.perf_counter() - start - t_trace
    mask_sets = {sd.DESIGNED: trained.printer_masks}
    ideal = None
    if baselines:
        extra, ideal = sd.baseline_masks(spec, sizes, frames, show_progress)
        mask_sets.update(extra)
    elif sd.hand_masks(spec, sizes) is not None:
        mask_sets[sd.HAND_KEY] = sd.hand_masks(spec, sizes)
    mask_sets.update(sd.reference_masks(spec, sizes))
    t_baselines = time.perf_counter() - start - t_trace - t_design
    transmissions = {k: sd.printed(m, sizes) for k, m in mask_sets.items()}
    decoders = {k: sd.calibrate(spec, camera, frames, t) for k, t in transmissions.items()}
    suite = sd.evaluate_suite(spec, sizes, camera, transmissions, decoders, show_progress)
    t_eval = time.perf_counter() - start - t_trace - t_design - t_baselines
    summary = sd.suite_summary(spec, suite)
    _write_outputs(out, spec, sizes, camera, frames, mask_sets, transmissions, decoders, suite, summary, trained)
    report = {
        "task": spec.name, "quick": quick, "spec": spec.as_dict(), "sizes": sizes.as_dict(),
        "gradient_check": {"max_rel_error": grad["rel_error"], "n_checked": grad["n_checked"],
                           "method": grad["method"]},
        "suite": {"summary": summary, "cases": suite["cases"],
                  "protocol": "fixed cases outside the training set, each traced through the mincam's geometry with "
                              "its own scenes and Monte Carlo samples, 12-bit read-out with noise at the task's fixed "
                              "exposure (the same draws for every mask set); every decoder fitted on the physical "
                              "training model's noiseless read-out"},
        "masks": {sd.DESIGNED: f"optimised through the traced physics, kept: {trained.start}",
                  **({sd.HAND_KEY: sd.HAND[spec.name]} if sd.HAND_KEY in mask_sets else {}),
                  sd.RANDOM: "logits N(0, 2^2) on the design grid, seed [seed, 61]",
                  sd.PCA: "principal components 1-4 of the training images (idealised mapping), single rail",
                  sd.IDEAL: "the same optimiser and starts on the DotProduct (idealised) linear model"
                            + (f", kept: {ideal.start}" if ideal is not None else ""),
                  **({"ramps_current_layout": "a reference row outside the summary: the ramps of the package's "
                                              "cross layout"} if "ramps_current_layout" in mask_sets else {})},
        "decoder": spec.decoder_family,
        "training": {"frames": len(frames), "kept": trained.start,
                     f"{spec.metric}_by_candidate": trained.training_metric,
                     "loss_rms_start_end": {k: [float(h[0]), float(np.mean(h[-10:]))]
                                            for k, h in trained.histories.items()},
                     **({"ideal_trained_on_ideal_model": ideal.training_metric} if ideal is not None else {}),
                     "loss": f"mean squared error of {spec.target} (capped at {spec.error_cap}), noisy 12-bit "
                             "read-out at the fixed exposure, decoder fitted per step on the noiseless read-out"},
        "exposure": {"dn_per_w_m2": camera.gain, "fill": tr.EXPOSURE_FILL},
        "runtime_s": {"trace_and_gradient_check": t_trace, "design": t_design, "baselines": t_baselines,
                      "suite": t_eval, "total": time.perf_counter() - start},
    }
    atomic_write_json(out / "design.json", report, indent=1, default=float)
    check_identity(out, identity, overwrite=True, name=IDENTITY_FILE)  # last: the design is finished
    return report


def _write_outputs(out: Path, spec: st.TaskSpec, sizes: st.Sizes, camera: sd.Camera, frames: st.Frames,
                   mask_sets: dict, transmissions: dict, decoders: dict, suite: dict, summary: dict,
                   trained: sd.Trained) -> None:
    """PNG masks and decoder of the design, the figure, and the training set as a Zarr dataset."""
    from mincam_sim.design.report import plot_scene_task

    film = sizes.film()
    for mask, name in zip(trained.printer_masks, tr.POSITIONS, strict=True):
        with atomic_path(out / f"mask_designed_{name}.png") as tmp:
            export_print_png(mask, tmp, dpi=sizes.dpi, film=film)
    atomic_write_json(out / "decoder.json", {**decoders[sd.DESIGNED].as_dict(), "task": spec.name,
                                             "input": "changes of the left, right, top, bottom mixels [DN] at "
                                                      f"{camera.gain:.6g} DN per W/m^2"}, indent=1)
    plot_scene_task(spec.name, spec.metric, spec.lower_is_better, suite["cases"],
                    {k: [film.print(x) for x in m] for k, m in mask_sets.items()}, out / "suite.png")
    measurements = {k: sd.read_out(camera.problem.matrices, t, camera, None) for k, t in transmissions.items()}
    sd.write_dataset(out / "training.zarr", measurements, frames,
                     {"task": spec.name, "seed": sizes.seed, "target": spec.target,
                      "what": "noiseless background-subtracted changes of the training frames through each mask set "
                              "(traced physics, fixed exposure); add the sensor's noise for a noisy read-out"})


__all__ = ["make_sizes", "refuse_another_design", "run_scene_task"]
