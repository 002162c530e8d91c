"""Render a validated TOML configuration (:class:`~mincam_sim.config.RenderConfig`): the service behind
``mincam-sim render`` and the Python API alike. It locks the output directory, records the run's identity
(content fingerprints of everything its numbers depend on), refuses a different run's directory unless asked to
overwrite, resumes a killed run, and writes measurements (CSV + NPZ) and response maps (OpenEXR) atomically."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .atomic import atomic_path
from .config import RenderConfig, traced_samples
from .errors import ConfigError
from .identity import build_identity, fingerprint, frames_fingerprint, run_key
from .measurements import Measurements
from .render import backend
from .render.response_map import ResponseMaps
from .render.screen_engine import render_frames
from .run import Run


def config_identity(cfg: RenderConfig, variant: str | None = None) -> dict:
    """Everything a config's numbers depend on, as content fingerprints (what ``identity.json`` records).

    Parameters
    ----------
    cfg : RenderConfig
        The validated config.
    variant : str, optional
        The Mitsuba variant that renders (None: recorded as "automatic").

    Returns
    -------
    dict
        form, seed, the requested budget (only the counts the form uses), fingerprints of the mincam, each mask,
        the screen and the frames (of the sweep recipe, or of the frame array for ``npy``), mixel names, the
        variant and the library versions.
    """
    run = cfg.run
    budget: dict[str, Any] = {"target_rel_stderr": run.target_rel_stderr}
    if run.form == "response_map":
        if run.target_rel_stderr == 0:
            budget["samples_per_texel"] = run.samples_per_texel
    else:
        budget["replicates"] = run.replicates
        if run.target_rel_stderr == 0:
            budget["spp"] = run.spp
    if cfg.frame_positions_m is not None:
        frames = cfg.raw["frames"]
        recipe = {k: frames[k] for k in ("square_m", "radiance_w_m2_sr", "background_w_m2_sr")}
        frames_fp = fingerprint({"kind": cfg.frames_kind, "positions_m": np.asarray(cfg.frame_positions_m),
                                 "shape": list(cfg.frames.shape), **recipe})
    else:
        frames_fp = frames_fingerprint(iter(cfg.frames))
    return build_identity("render_config", {
        "form": run.form, "seed": run.seed, "budget": budget, "mincam": fingerprint(cfg.mincam),
        "mixels": cfg.mincam.names, "masks": [fingerprint(m.mask) for m in cfg.mincam],
        "screen": fingerprint(cfg.screen), "frames": frames_fp}, variant=variant or "automatic")


def _finished_results(out: Path, key: str, n_frames: int) -> Any:
    """The measurements a finished run with identity ``key`` wrote to ``out``, or None."""
    path = out / "measurements.npz"
    if not path.is_file():
        return None
    try:
        m = Measurements.load_npz(path)
    except Exception:  # torn or foreign: render again (the file is replaced atomically at the end)
        return None
    if m.meta.get("identity_key") != key or m.n_frames != n_frames:
        return None
    return m


def run_render_config(
    cfg: RenderConfig, show_progress: bool = False, overwrite: bool = False, reuse: bool = False,
    say: Callable[[str], None] | None = None, time_limit_s: float | None = None,
) -> tuple[Measurements, ResponseMaps | None]:
    """Render a validated :class:`~mincam_sim.config.RenderConfig`; write outputs; return (measurements, maps).

    The output directory is locked while this runs (one lock, :class:`~mincam_sim.run.Run`, for the identity
    record and the per-frame store ``run/`` alike). ``identity.json`` there records the content fingerprints
    of everything the numbers depend on (:func:`config_identity`); a rerun with different content is refused
    (StaleResultError naming what changed) unless ``overwrite``, which first removes the previous run's store
    and maps. With ``reuse``, a finished run with the same identity is not rendered again: its
    ``measurements.npz`` is returned (and maps as None), and ``say`` (if given) is told so. With
    ``time_limit_s``, a render estimated to take longer (:func:`check_budget`) is refused before it starts;
    ``say`` is told when the sample count traced differs from the one asked (:func:`~mincam_sim.config.traced_samples`).
    """
    out = Path(cfg.run.out_dir)
    run_dir = out / "run"
    identity = config_identity(cfg, backend.variant())  # the variant in use: CUDA and LLVM differ in the last bits
    key = run_key(identity)
    with Run(out, overwrite=overwrite) as job:
        finished = not overwrite and reuse and _finished_results(out, key, len(cfg.frames)) is not None
        if time_limit_s is not None and not finished:  # before anything is written: a refusal claims nothing
            check_budget(cfg, backend.variant(), time_limit_s)
        if overwrite:
            job.clear("run", extra=("response_maps.npz",))
        same = job.record_identity(identity)
        if same and reuse:
            done = _finished_results(out, key, len(cfg.frames))
            if done is not None:
                if say is not None:
                    say(f"mincam-sim: {out} holds the finished results of this same run; shown again (--overwrite "
                        "renders anew)")
                return done, None
        _, rounding = traced_samples(cfg.run)
        if rounding is not None and say is not None and not (run_dir / "run.json").exists():
            say(f"mincam-sim: {rounding}")  # on a fresh start only: a resumed run said it when it started
        m, maps = render_frames(
            cfg.mincam, cfg.screen, cfg.frames, cfg.run.form, cfg.run.spp, cfg.run.samples_per_texel,
            cfg.run.target_rel_stderr, cfg.run.seed, cfg.run.replicates, show_progress=show_progress,
            sink=job.sink("run"),
        )
        m.meta["config"] = cfg.raw
        m.meta["identity_key"] = key
        if cfg.frame_positions_m is not None:
            m.meta["frame_positions_m"] = cfg.frame_positions_m.tolist()
        if maps is not None:
            maps.save_exr(out / "response_maps")
        with atomic_path(out / "measurements.csv") as tmp:
            m.save_csv(tmp)
        with atomic_path(out / "measurements.npz") as tmp:  # last: it marks the run finished
            m.save_npz(tmp)
    return m, maps


# Samples traced per second per form, measured with llvm_ad_mono on a shared 2-core CPU (a 128 x 72 screen,
# 2 mixels): the estimate is an upper bound of the time on faster machines (a CUDA GPU is far faster).
SAMPLES_PER_S = {"response_map": 2.0e7, "fast": 1.0e7, "reference": 1.0e6}
SCALAR_SLOWDOWN = 10.0  # scalar_rgb traces one ray at a time
DOT_PRODUCTS_PER_S = 5.0e8  # response_map: frame x map products (numpy)
DEFAULT_TIME_LIMIT_S = 4 * 3600.0


def estimate_seconds(cfg: RenderConfig, variant: str | None = None) -> tuple[float, str]:
    """A rough upper estimate of a render's time [s] and what it counts (from :data:`SAMPLES_PER_S`).

    With ``target_rel_stderr > 0`` the sample counts grow until the target is met; the estimate is then that of
    the first pass only (the text says so).
    """
    run = cfg.run
    n_mixels, n_frames = len(cfg.mincam), len(cfg.frames)
    traced, _ = traced_samples(run)
    if run.form == "response_map":
        rows, cols = cfg.screen.shape
        samples = float(rows * cols) * traced * n_mixels
        what = f"{rows * cols} texels x {traced} samples x {n_mixels} mixels"
        seconds = samples / SAMPLES_PER_S["response_map"] + n_frames * rows * cols * n_mixels / DOT_PRODUCTS_PER_S
    else:
        samples = float(n_frames) * traced * n_mixels
        what = f"{n_frames} frames x {traced} samples x {n_mixels} mixels"
        seconds = samples / SAMPLES_PER_S[run.form]
    if variant == "scalar_rgb":
        seconds *= SCALAR_SLOWDOWN
    if run.target_rel_stderr > 0:
        what += " (first pass; target_rel_stderr adds passes)"
    return seconds, what


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    if seconds < 3 * 86400:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.3g} days"


def check_budget(cfg: RenderConfig, variant: str | None, limit_s: float = DEFAULT_TIME_LIMIT_S) -> float:
    """Refuse a render whose estimated time (:func:`estimate_seconds`) exceeds ``limit_s``; return the estimate.

    Raises
    ------
    ConfigError
        Naming the estimate, what it counts, and the two fixes (fewer samples or frames, or a higher limit).
    """
    seconds, what = estimate_seconds(cfg, variant)
    if seconds > limit_s:
        key = "samples_per_texel" if cfg.run.form == "response_map" else "spp"
        raise ConfigError(f"this render would take about {_duration(seconds)} ({what}), over the limit of "
                          f"{_duration(limit_s)}: lower [run] {key} (or the frames), or raise the limit with "
                          f"--time-limit-s {max(limit_s, 1.5 * seconds):.0f}")
    return seconds


def config_summary(cfg: RenderConfig, variant: str | None) -> list[str]:
    """What a validated config will render, one line per part (``mincam-sim render --check``)."""
    run, screen = cfg.run, cfg.screen
    lines = [f"config: {cfg.source or 'text'} is valid"]
    def vec(v) -> str:
        return "[" + ", ".join(f"{float(x):+.4f}" for x in v) + "]"

    for mixel in cfg.mincam:
        mask, pose = mixel.mask, mixel.pose
        _, up, forward = pose.axes()  # orthonormal: up made perpendicular to forward
        lines.append(f"mixel {mixel.name}: mask {mask.name} ({mask.shape[1]}x{mask.shape[0]} texels, "
                     f"{1e3 * mask.width_m:g} x {1e3 * mask.height_m:g} mm) at d_f {1e3 * mixel.d_f_m:g} mm, "
                     f"detector {1e3 * mixel.detector_size_m:g} mm, {mixel.optics} optics, position "
                     f"{vec(pose.position_m)} m, forward {vec(forward)}, up {vec(up)}")
    lines.append(f"screen: {screen.width_m:.4f} x {screen.height_m:.4f} m, {screen.resolution[0]} x "
                 f"{screen.resolution[1]} texels, {-screen.pose.position_m[2]:g} m from the mincam")
    f = cfg.frames
    lo = min(float(x.min()) for x in f)
    hi = max(float(x.max()) for x in f)
    lines.append(f"frames: {len(f)} ({cfg.frames_kind}), {f.shape[2]} x {f.shape[1]} texels, radiance "
                 f"{lo:g} .. {hi:g} W m^-2 sr^-1, {len(f) * f.nbytes_per_frame / 2**20:.1f} MiB if held at once "
                 "(streamed in chunks)")
    if run.form == "response_map":
        budget = (f"target relative stderr {run.target_rel_stderr:g}" if run.target_rel_stderr > 0
                  else f"{run.samples_per_texel} samples per texel")
    else:
        budget = (f"target relative stderr {run.target_rel_stderr:g}" if run.target_rel_stderr > 0
                  else f"{run.spp} samples per mixel per frame") + f", {run.replicates} replicates"
    lines.append(f"form: {run.form}, {budget}, seed {run.seed}, variant {variant or 'automatic'}")
    _, rounding = traced_samples(run)
    if rounding is not None:
        lines.append(f"samples: {rounding}")
    seconds, what = estimate_seconds(cfg, variant)
    lines.append(f"estimate: about {_duration(seconds)} ({what}; limit {_duration(DEFAULT_TIME_LIMIT_S)}, "
                 "--time-limit-s raises it)")
    out = Path(run.out_dir)
    state = "exists" if out.is_dir() else "will be created"
    if (out / "identity.json").exists() or (out / "run" / "run.json").exists():
        state += ", holds an earlier run (resumed if unchanged, refused if different unless --overwrite)"
    lines.append(f"out dir: {out} ({state})")
    return lines
