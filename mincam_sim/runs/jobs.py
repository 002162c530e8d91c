"""Jobs: a validated config (display or world) becomes ``(Simulation, frames, solver, budget)`` and goes to
:meth:`mincam_sim.runs.run.Run.measure` or :meth:`~mincam_sim.runs.run.Run.measure_changes`; the service behind
``mincam-sim render`` and the Python API alike.

* :func:`display_job` / :func:`world_job` build the :class:`Job` of a config (no rendering);
* :func:`run_render_config` / :func:`run_world_config` run it in ``[run] out_dir`` through one ``Run`` (its
  lock, its identity, its store: a killed run resumes, a finished one with the same identity is returned
  without rendering, a different one is refused unless ``overwrite``) and add the job's own outputs: each
  frame's position or time and movers' offsets in ``measurements.csv`` / ``.npz``, response maps (OpenEXR), a plot
  of dP and the ground-truth camera's images;
* :func:`estimate_seconds` / :func:`check_budget`: the same estimate-and-refuse rule for displays and worlds,
  before anything is allocated or written; :func:`config_summary` / :func:`world_summary`: ``--check``.

A job builds no identity of its own: the run's one identity is ``Run``'s.

World outputs in ``[run] out_dir``: ``measurements.npz`` (``irradiance_w_m2`` / ``stderr_w_m2``: P;
``delta_irradiance_w_m2`` / ``delta_stderr_w_m2``: dP; (n_frames, n_mixels) each), ``measurements.csv`` (frame,
time, each mover's offset and centre, dP and P per mixel with their standard errors), ``dP.png``, and with a
camera ``camera.npz`` (every frame's image and the background's, the change centroids, and the key of what made
them: a rerun of a finished run reads it back when the key is the same) plus the change centroid per frame in the
CSV.
"""

from __future__ import annotations

import contextlib
import os
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mincam_sim.budget import Budget
from mincam_sim.changes import Changes
from mincam_sim.configuration.config import RenderConfig, solver_name, traced_samples
from mincam_sim.configuration.world_config import CameraSpec, WorldConfig, is_gltf
from mincam_sim.errors import ConfigError
from mincam_sim.measurements import Measurements
from mincam_sim.model.optics import mixel_file_stem
from mincam_sim.render import backend
from mincam_sim.render.scene import scene_dicts as sd
from mincam_sim.render.scene.gltf_files import GltfFile
from mincam_sim.render.scene.scene_files import SceneFile, read_mesh
from mincam_sim.render.scene.world_checks import light_pixels
from mincam_sim.render.simulation import Simulation
from mincam_sim.render.solvers import (
    Aperture,
    DotProduct,
    PlainChange,
    Reference,
    ResponseMap,
    Solver,
    StratifiedChange,
)
from mincam_sim.runs.run import UNREADABLE_NPZ, Run
from mincam_sim.storage.atomic import atomic_path, atomic_save_npz, remove_files
from mincam_sim.storage.identity import fingerprint

#: The store and result name of a job in its output directory: ``OUT/measurements/`` (per-frame rows, resume),
#: ``OUT/measurements.npz`` / ``.csv`` (the finished result).
RESULT = "measurements"
#: The ground-truth camera's method (windows, samples, threshold rule): part of the key ``camera.npz`` is kept
#: under, so images rendered by an earlier method are never shown again as this one's.
GROUND_TRUTH_METHOD = "2026-12-06: change windows per mover and per delta surface's image; lit-pixel threshold"


@dataclass(frozen=True)
class Job:
    """What a config measures: the simulation, its frames, the solver and the budget; ``background`` (world
    change runs; None for absolute measurements) and per-frame ``columns`` for the outputs (name -> array)."""

    sim: Simulation
    frames: Any
    solver: Solver
    budget: Budget
    background: dict | None = None
    columns: dict[str, np.ndarray] = field(default_factory=dict)


# ------------------------------------------------------------------------------------------------- displays
def display_job(cfg: RenderConfig) -> Job:
    """The job of a validated display config (nothing is rendered)."""
    columns = {} if cfg.frame_positions_m is None else {"positions_m": np.asarray(cfg.frame_positions_m)}
    return Job(Simulation(cfg.mincam, screen=cfg.screen), cfg.frames, cfg.run.solver, cfg.run.budget,
               columns=columns)


def run_render_config(cfg: RenderConfig, show_progress: bool = False, overwrite: bool = False,
                      say: Callable[[str], None] | None = None,
                      time_limit_s: float | None = None) -> tuple[Measurements, Any]:
    """Render a validated :class:`~mincam_sim.configuration.config.RenderConfig`; write outputs; return (measurements,
    maps).

    With ``time_limit_s``, a render estimated to take longer (:func:`check_budget`) is refused before anything is
    written. The output directory is one :class:`~mincam_sim.runs.run.Run`: a rerun resumes or returns the finished
    result, a different run is refused unless ``overwrite`` (which first deletes the outputs this package wrote
    there, :func:`remove_outputs`). ``say`` is told when the sample count traced differs from the one asked
    (:func:`~mincam_sim.configuration.config.traced_samples`), when a finished result is shown again or was
    damaged, and when missing response maps are written again. ``maps`` are the response maps the measurements
    used (the ``response_map`` and ``dot_product`` solvers; also written as ``response_maps/*.exr``), else None;
    after a rerun of a finished run they are None unless one of their outputs (:func:`maps_outputs`) was
    missing: then they are made again (the run's map cache holds the traced ones) and returned.
    """
    if time_limit_s is not None:
        check_budget(cfg, backend.variant(), time_limit_s)
    out = Path(cfg.run.out_dir)
    job = display_job(cfg)
    _, rounding = traced_samples(cfg.run)
    if rounding is not None and say is not None and (overwrite or not (out / RESULT).is_dir()):
        say(f"mincam-sim: {rounding}")  # on a fresh start only: a resumed run said it when it started
    with Run(out, overwrite=overwrite, show_progress=show_progress) as run:
        if overwrite:
            remove_outputs(out)
        m = run.measure(job.sim, job.frames, job.solver, job.budget, name=RESULT)
        _say_if_reused(run, out, say)
        # the map solvers' result carries the maps it used; a finished run shown again has none: they are made
        # again only if an output of theirs is missing (a run killed, or a disk full, after measurements.npz)
        maps = getattr(m, "maps", None)
        if maps is None and isinstance(job.solver, MAP_SOLVERS):
            missing = [p for p in maps_outputs(out, m.mixel_names) if not p.is_file()]
            if missing:
                if say is not None:
                    say(f"mincam-sim: {out} lacks this run's {', '.join(_rel(p, out) for p in missing)}: making "
                        "the response maps again (from the run's map cache, tracing what it lacks)")
                maps = _maps_again(job, run, show_progress)
        if maps is not None:
            maps.save_exr(out / "response_maps")
        if "positions_m" in job.columns:
            # Run wrote OUT/measurements.npz/.csv; the job writes them again with each frame's position (CSV
            # columns position_x_m, position_y_m), keeping Run's meta (its identity key) as it is.
            m.meta["frame_positions_m"] = job.columns["positions_m"].tolist()
            with atomic_path(out / f"{RESULT}.csv") as tmp:
                m.save_csv(tmp)
            with atomic_path(out / f"{RESULT}.npz") as tmp:
                m.save_npz(tmp)
    return m, maps


#: The solvers whose result carries response maps (``m.maps``): written as ``response_maps/*.exr`` (and by
#: ``render`` as ``response_maps.png``).
MAP_SOLVERS = (ResponseMap, DotProduct)
#: The files a render writes into its output directory besides its store (``OUT/measurements/``):
#: :func:`remove_outputs` deletes these (and ``response_maps/response_*.exr``) before an overwrite.
OUTPUT_FILES = (f"{RESULT}.npz", f"{RESULT}.csv", f"{RESULT}.png", "response_maps.png", "dP.png", "camera.npz")


def maps_outputs(out: Path, mixel_names) -> list[Path]:
    """The response maps' outputs of a display run in ``out``: one OpenEXR per mixel, named as
    ``ResponseMaps.save_exr`` names it (``response_<mixel>.exr``, characters other than letters, digits, ``-`` and
    ``_`` replaced by ``_``), and ``response_maps.png``."""
    return [*(out / "response_maps" / f"response_{mixel_file_stem(name)}.exr" for name in mixel_names),
            out / "response_maps.png"]


def remove_outputs(out: Path) -> list[Path]:
    """Delete the outputs an earlier run wrote in ``out`` (:data:`OUTPUT_FILES` and ``response_maps/
    response_*.exr``; ``response_maps/`` itself once empty) before an overwrite replaces the run, so none of
    them is left beside the new run's; return what was deleted. Other files are left alone; the store is
    replaced by the run itself (:class:`~mincam_sim.storage.store.ResultStore`).

    Raises
    ------
    StoreError
        A file cannot be deleted (naming it).
    """
    maps_dir = out / "response_maps"
    paths = [out / name for name in OUTPUT_FILES]
    if maps_dir.is_dir():
        paths += sorted(maps_dir.glob("response_*.exr"))
    removed = remove_files(paths, "an output of the run --overwrite replaces",
                           "delete it by hand or choose another output directory")
    if maps_dir.is_dir() and not any(maps_dir.iterdir()):
        with contextlib.suppress(OSError):  # left in place: empty, nothing stale in it
            maps_dir.rmdir()
    return removed


def _maps_again(job: Job, run: Run, show_progress: bool) -> Any:
    """The response maps a finished run of ``job`` used, made again as its solver made them: the response map
    solver's from the run's map cache (``OUT/measurements/cache``; traced again where it lacks them, to the same
    numbers), the dot-product model's computed again (exact)."""
    if isinstance(job.solver, ResponseMap):
        maps, _ = job.solver.maps(job.sim, job.budget, job.frames, run.sink(RESULT).cache, show_progress)
        return maps
    return job.solver.maps(job.sim.mincam, job.sim.screen, show_progress)


def _rel(path: Path, out: Path) -> str:
    return path.relative_to(out).as_posix()


def _say_if_reused(run: Run, out: Path, say: Callable[[str], None] | None) -> None:
    if say is None:
        return
    if RESULT in run.unreadable:
        say(f"mincam-sim: {out / RESULT}.npz is damaged or unreadable ({run.unreadable[RESULT]}): it was computed "
            "again (from the run's per-frame store where it holds the frames) and replaced")
    if RESULT in run.reused:
        say(f"mincam-sim: {out} holds this same run, finished: its results are shown again without rendering "
            "(--overwrite recomputes)")


# --------------------------------------------------------------------------------------------------- worlds
def world_job(cfg: WorldConfig) -> Job:
    """The job of a validated world config: the scene is built (Mitsuba), nothing is rendered."""
    sim = Simulation(cfg.mincam, world=build_elements(cfg), max_depth=cfg.run.max_depth,
                     camera=_camera_dict(cfg.camera) if cfg.camera else None)
    frames, background, centres = mover_updates(sim, cfg)
    columns = {"time_s": np.arange(cfg.n_frames) / cfg.frame_rate_hz}
    for mover in cfg.movers:
        for k, axis in enumerate("xyz"):
            columns[f"{mover.id}_offset_{axis}_m"] = mover.offsets_m[:, k]
        for k, axis in enumerate("xyz"):
            columns[f"{mover.id}_centre_{axis}_m"] = centres[mover.id][:, k]
    return Job(sim, frames, cfg.run.solver, cfg.run.budget, background, columns)


def run_world_config(cfg: WorldConfig, show_progress: bool = False, overwrite: bool = False,
                     say: Callable[[str], None] | None = None, time_limit_s: float | None = None) -> Changes:
    """Render a validated :class:`~mincam_sim.configuration.world_config.WorldConfig`; write its outputs; return the
    changes.

    With ``time_limit_s``, a render estimated to take longer (:func:`check_budget`) is refused before the scene is
    built. One :class:`~mincam_sim.runs.run.Run` holds the output directory (resume, reuse, refusal as for displays).
    """
    if time_limit_s is not None:
        check_budget(cfg, backend.variant(), time_limit_s)
    out = Path(cfg.run.out_dir)
    with Run(out, overwrite=overwrite, show_progress=show_progress) as run:
        job = world_job(cfg)
        if overwrite:  # once the scene is built: a scene that fails leaves the earlier run's outputs as they were
            remove_outputs(out)
        ch = run.measure_changes(job.sim, job.frames, job.background, job.solver, job.budget, name=RESULT)
        _say_if_reused(run, out, say)
        columns = dict(job.columns)
        if cfg.camera is not None:
            key = fingerprint({"run": ch.dp.meta["identity_key"], "camera": cfg.camera, "method": GROUND_TRUTH_METHOD})
            rows, cols = _ground_truth(job.sim, cfg.camera, job.frames, job.background, out, key, not overwrite, say)
            columns["change_centroid_row_px"], columns["change_centroid_col_px"] = rows, cols
        ch.frame_columns = columns
        plot_changes(ch, out / "dP.png")
        # Run wrote OUT/measurements.npz/.csv; the job writes them again with its frame columns (time,
        # movers, centroid), keeping Run's meta (its identity key) as it is.
        ch.save_csv(out / f"{RESULT}.csv")
        ch.save_npz(out / f"{RESULT}.npz")
    return ch


def rotation_deg(angles_deg) -> np.ndarray:
    """3 x 3 rotation: about x, then y, then z, by ``angles_deg`` [deg]."""
    ax, ay, az = np.radians(np.asarray(angles_deg, dtype=float))
    rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
    ry = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
    rz = np.array([[np.cos(az), -np.sin(az), 0], [np.sin(az), np.cos(az), 0], [0, 0, 1]])
    return rz @ ry @ rx


def build_elements(cfg: WorldConfig) -> dict:
    """The world's elements: the XML scene with its parameters, or the glTF file (turned z-up if authored y-up, in
    metres), and the config's objects and lights."""
    elements: dict = {}
    if cfg.scene_file is not None and is_gltf(cfg.scene_file):  # its nodes come in under their own names
        elements["scene"] = GltfFile(cfg.scene_file, cfg.up, cfg.unit_m, cfg.emission_w_m2_sr)
    elif cfg.scene_file is not None:
        elements["scene"] = SceneFile(cfg.scene_file, cfg.parameters, cfg.up, cfg.unit_m)  # in metres once loaded
    for obj in cfg.objects:
        vertices, faces = read_mesh(obj.mesh)
        placed = (vertices * obj.scale) @ rotation_deg(obj.rotation_deg).T + np.asarray(obj.position_m)
        elements[obj.id] = sd.mesh_object(obj.id, placed, faces, obj.albedo)
    for light in cfg.lights:
        elements[light.id] = _light_dict(light)
    return elements


def _light_dict(light) -> dict:
    from mincam_sim.model.geometry import Pose

    if light.kind == "sky":
        return sd.sky(light.radiance_w_m2_sr)
    if light.kind == "point":
        return sd.point_light(light.position_m, light.intensity_w_sr)
    forward = np.asarray(light.forward, dtype=float)
    up = (1.0, 0.0, 0.0) if abs(forward[0]) < 0.9 * np.linalg.norm(forward) else (0.0, 1.0, 0.0)
    matrix = Pose(tuple(light.position_m), tuple(forward), up).matrix()
    if light.kind == "area":
        return sd.area_light(light.size_m[0], light.size_m[1], matrix, light.radiance_w_m2_sr)
    return sd.spot_light(matrix, light.intensity_w_sr, light.cutoff_deg)


def mover_updates(sim: Simulation, cfg: WorldConfig) -> tuple[list[dict], dict, dict[str, np.ndarray]]:
    """(frames, background, centres): each frame's parameter updates (world coordinates), the background's,
    and each mover's centre per frame [m] (its as-built bounding-box centre moved with it). A mover is a mesh
    (its vertices), a shape or spot light with a ``to_world``, or a point light (its position); the background
    without movers takes them out (:meth:`~mincam_sim.render.simulation.Simulation.without`)."""
    params = sim.params
    movable = sim.movable()
    n = cfg.n_frames
    _check_update_memory(params, cfg)
    frames: list[dict] = [{} for _ in range(n)]
    centres: dict[str, np.ndarray] = {}
    for mover in cfg.movers:
        if mover.id not in movable:
            raise ConfigError(f"[[world.mover]] id {mover.id!r} is not a shape or light of the scene that can move; "
                              f"movable: {', '.join(movable) or 'none'}")
        rotations = [np.eye(3) if mover.rotations_deg is None else rotation_deg(mover.rotations_deg[i])
                     for i in range(n)]
        vkey, tkey, pkey = (f"{mover.id}.{part}" for part in ("vertex_positions", "to_world", "position"))
        if vkey in params:
            v0 = params[vkey].reshape(-1, 3)
            centre = 0.5 * (v0.min(axis=0) + v0.max(axis=0))
            for i in range(n):
                frames[i][vkey] = ((v0 - centre) @ rotations[i].T + centre + mover.offsets_m[i]).ravel()
        elif tkey in params:
            m0 = params[tkey]
            centre = m0[:3, 3].copy()
            for i in range(n):
                m = m0.copy()
                m[:3, :3] = rotations[i] @ m0[:3, :3]
                m[:3, 3] = centre + mover.offsets_m[i]
                frames[i][tkey] = m
        else:  # a point light: its position (a rotation turns nothing)
            centre = np.asarray(params[pkey], dtype=np.float64).ravel()[:3]
            for i in range(n):
                frames[i][pkey] = centre + mover.offsets_m[i]
        centres[mover.id] = centre + mover.offsets_m
    if cfg.background == "first_frame":
        background = dict(frames[0])
    elif cfg.background == "without_movers":
        background = sim.without(*(mover.id for mover in cfg.movers))
        for key in background:  # a light the background switches off shines in every frame as built
            for frame in frames:
                frame.setdefault(key, params[key])
    else:
        background = {}
    return frames, background, centres


def _check_update_memory(params, cfg: WorldConfig) -> None:
    """Refuse, before they are made, per-frame updates that would not fit in memory: every frame holds each
    moving mesh's vertices (3 float64 each) or each moving shape's 4 x 4 transform."""
    floats = 0
    for mover in cfg.movers:
        vkey = f"{mover.id}.vertex_positions"
        floats += int(np.size(params[vkey])) if vkey in params else 16
    n_bytes = float(cfg.n_frames) * floats * 8
    check_memory(n_bytes, f"{cfg.n_frames} frames x {floats} floats of the movers' vertices and transforms",
                 "fewer frames (a lower [world] frame_rate_hz or shorter trajectories) or simpler moving meshes")


def _camera_dict(camera: CameraSpec) -> dict:
    from mincam_sim.model.geometry import look_at

    pose = look_at(camera.position_m, camera.look_at_m, camera.up)
    return sd.pinhole_camera(pose.matrix(), camera.fov_deg, camera.width_px, camera.height_px, spp=camera.spp)


def _ground_truth(sim: Simulation, camera: CameraSpec, frames, background, out: Path, key: str = "",
                  reuse: bool = False, say: Callable[[str], None] | None = None):
    """Images of the background and every frame, and the centroid (row, col) [px] of each frame's change:
    background subtraction, |change| > threshold x the background's brightest pixel that is no light seen
    directly (:func:`~mincam_sim.render.scene.world_checks.light_pixels`: a lamp or a sky in view would set the
    threshold above every change it lights), counted in the window where the frame's movers and their shadows
    can be seen (:meth:`Simulation.camera_changes`: noise elsewhere detected no pixel); the images are whole
    films with the window's change, both at the camera's samples a pixel.

    ``OUT/camera.npz`` holds them with ``key`` (what determines them: the run's identity, the camera's settings
    and :data:`GROUND_TRUTH_METHOD`); with ``reuse``, a file that holds the same ``key`` is read back instead of
    rendering."""
    path = out / "camera.npz"
    kept, why = _kept_ground_truth(path, key) if reuse and key else (None, "")
    if kept is None:
        if why and say is not None:
            say(f"mincam-sim: {path} {why}: rendering it again")
        kept = _render_ground_truth(sim, camera, frames, background)
        atomic_save_npz(path, background=kept["background"], frames=kept["frames"],
                        change_centroid_row_px=kept["rows"], change_centroid_col_px=kept["cols"],
                        threshold_scale_w_m2_sr=np.float64(kept["scale"]), identity_key=np.array(key))
    _warn_undefined_centroids(list(kept["frames"]), kept["background"], kept["rows"], camera.threshold,
                              kept["scale"])
    return kept["rows"], kept["cols"]


def _kept_ground_truth(path: Path, key: str) -> tuple[dict | None, str]:
    """(the ground truth in ``path`` if it was written with ``key``, else None; why not, for the user: ``""``
    when there is no file, else that it was rendered for other settings or is damaged or unreadable)."""
    if not path.is_file():
        return None, ""
    try:
        with np.load(path) as data:
            if str(data["identity_key"]) != key:
                return None, "was rendered for other settings (camera, scene or method)"
            return {"background": data["background"], "frames": data["frames"],
                    "rows": data["change_centroid_row_px"], "cols": data["change_centroid_col_px"],
                    "scale": float(data["threshold_scale_w_m2_sr"])}, ""
    except KeyError as err:  # an npz without an array this one has: another program's, or older code's
        return None, f"is not a camera file of this version ({err.args[0] if err.args else 'an array is missing'})"
    except UNREADABLE_NPZ as err:  # damaged: torn, empty, not an npz
        return None, f"is damaged or unreadable ({type(err).__name__}: {err})".replace(": )", ")")


def _render_ground_truth(sim: Simulation, camera: CameraSpec, frames, background) -> dict:
    sim.update(background)
    bg = sim.camera_image(camera.spp, seed=0)
    lit = ~light_pixels(sim.scene, sim.camera)
    scale = float(bg[lit].max()) if lit.any() else float(bg.max())
    images, rows, cols = [], [], []
    for change in sim.camera_changes(frames, background, spp=camera.spp, seed=0, elsewhere_spp=camera.spp):
        images.append(bg + change.change_image(bg.shape, elsewhere=True))
        r, c = np.nonzero(np.abs(change.change_image(bg.shape)) > camera.threshold * scale)
        rows.append(r.mean() if r.size else np.nan)
        cols.append(c.mean() if c.size else np.nan)
    return {"background": bg, "frames": np.array(images), "rows": np.array(rows), "cols": np.array(cols),
            "scale": scale}


def _warn_undefined_centroids(images: list, bg: np.ndarray, rows: np.ndarray, threshold: float,
                              scale: float) -> None:
    """One warning when frames that change the image have no pixel above the threshold (their centroid NaN)."""
    changed = np.array([float(np.abs(image - bg).max()) > 0 for image in images], dtype=bool)
    undefined = np.isnan(rows) & changed
    if undefined.any():
        warnings.warn(f"the camera's change centroid is undefined (NaN) in {int(undefined.sum())} of {len(rows)} "
                      f"frames that change the image: no pixel changed by more than threshold {threshold:g} x the "
                      f"background's brightest pixel that is no light in view ({scale:.4g} W m^-2 sr^-1); lower "
                      "[world.camera] threshold", UserWarning, stacklevel=3)


def plot_changes(ch: Changes, path: Path) -> Path:
    """dP per mixel against frame, with 1-sigma error bars."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.6), constrained_layout=True)
    x = ch.frame_columns.get("time_s", np.arange(ch.n_frames))
    for k, name in enumerate(ch.mixel_names):
        ax.errorbar(x, ch.dp.irradiance_w_m2[:, k], yerr=ch.dp.stderr_w_m2[:, k], marker="o", ms=3, capsize=2,
                    label=name)
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.set_xlabel("time [s]" if "time_s" in ch.frame_columns else "frame")
    ax.set_ylabel("ΔP [W/m²] (± 1σ)")
    ax.set_title(f"change per mixel ({ch.info.solver}, {ch.info.rays_per_mixel_per_frame} rays/mixel/frame)")
    ax.legend(fontsize=8, ncol=min(4, len(ch.mixel_names)))
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)
    return path


# --------------------------------------------------------------------------------------- size and time guard
# The cost model of a render, measured with llvm_ad_mono on the project's shared 2-core CPU as CPU seconds (one
# core's work; on an idle 2-core machine the wall time is between half of it, where the tracing runs on both
# cores, and all of it, for the per-frame work in Python). ``tests/core/test_estimates.py`` times real runs
# against it.
STARTUP_S = 2.5  # a tiny render: imports, the backend, the scene, the result files and figures (3.5 until the
# Xeon: its tiny world render took 2.1 s wall, 2.8 s CPU in all, and read 0.32-0.36 of a 6 s estimate)
#: Samples traced per CPU second per solver (response maps: texel samples; the others: rays; worlds: paths of
#: max_depth 3 in the room of scenes/world).
SAMPLES_PER_S: dict[type[Solver], float] = {ResponseMap: 3.0e7, Aperture: 5.0e6, Reference: 2.0e6,
                                             PlainChange: 2.5e6, StratifiedChange: 1.5e6}
#: Seconds per frame besides tracing: making or reading the frame, its row in the store, its lines in the CSV, the
#: printed table and the figure (the ray solvers and worlds add a scene update and kernel launches per frame).
FRAME_S: dict[type[Solver], float] = {ResponseMap: 2.0e-4, Aperture: 7.0e-3, Reference: 7.0e-3,
                                       PlainChange: 1.2e-2, StratifiedChange: 1.2e-2, DotProduct: 2.0e-4}
#: Quadrature points per CPU second of the idealised model's maps (``DotProduct``: texels x mixels x nodes^2, x
#: nodes^2 again with ``detector_blur``; 3.3-4 M/s measured for the cross over 160 x 160 texels).
QUADRATURE_POINTS_PER_S = 3.0e6
TEXEL_S = 6.0e-9  # per display texel and frame: making the frame, checking its radiance
TEXEL_MIXEL_S = 3.0e-9  # per display texel, mixel and frame: the products with the response maps
CAMERA_IMAGE_S = 0.05  # per ground-truth camera image, besides its samples
SCALAR_SLOWDOWN = 10.0  # scalar_rgb traces one ray at a time
DEFAULT_TIME_LIMIT_S = 4 * 3600.0
RESULT_BYTES_PER_VALUE = 64  # per frame and mixel: values and errors in the store, the result, the CSV, the figure


def estimate_seconds(cfg: RenderConfig | WorldConfig, variant: str | None = None) -> tuple[float, str]:
    """A rough estimate of a render's time [s] and what it counts, for display and world configs alike
    (``STARTUP_S`` + samples / :data:`SAMPLES_PER_S` + frames x (:data:`FRAME_S` + texel terms)); nothing is
    built.

    With ``target_rel_stderr > 0`` the sample counts grow until the target is met; the estimate is then that of
    the first pass only (the text says so).
    """
    solver, budget = cfg.run.solver, cfg.run.budget
    n_mixels = len(cfg.mincam)
    kind = type(solver)
    if isinstance(cfg, WorldConfig):
        n_frames, traced = cfg.n_frames, budget.rays()
        depth = (cfg.run.max_depth or 3) / 3.0  # segments per path, relative to the measured max_depth 3
        samples = float(n_frames) * traced * n_mixels * depth
        what = f"{n_frames} frames x {traced} rays x {n_mixels} mixels"
        seconds = samples / SAMPLES_PER_S[kind] + n_frames * FRAME_S[kind]
        if cfg.camera is not None:
            # a film a frame, and the frame's and the background's change windows (a few percent of a film for a
            # small mover, the whole film for a moving light): half a film a frame, within 2x either way
            films = 1.5 * n_frames + 2
            pixels = films * cfg.camera.width_px * cfg.camera.height_px * cfg.camera.spp
            seconds += pixels / SAMPLES_PER_S[Aperture] + (3 * n_frames + 2) * CAMERA_IMAGE_S
            what += f" + camera {n_frames + 1} images and their change windows"
    else:
        n_frames, (traced, _) = len(cfg.frames), traced_samples(cfg.run)
        rows, cols = cfg.screen.shape
        texels = rows * cols
        per_frame = FRAME_S[kind] + texels * TEXEL_S
        if isinstance(solver, DotProduct):
            points = solver.nodes ** (4 if solver.detector_blur else 2)
            what = f"{texels} texels x {points} quadrature points x {n_mixels} mixels, then {n_frames} frames"
            per_frame += texels * n_mixels * TEXEL_MIXEL_S
            seconds = float(texels) * points * n_mixels / QUADRATURE_POINTS_PER_S + n_frames * per_frame
            return STARTUP_S + seconds, what
        if isinstance(solver, ResponseMap):
            samples = float(texels) * traced * n_mixels
            what = f"{texels} texels x {traced} samples x {n_mixels} mixels, then {n_frames} frames"
            per_frame += texels * n_mixels * TEXEL_MIXEL_S
        else:
            samples = float(n_frames) * traced * n_mixels
            what = f"{n_frames} frames x {traced} samples x {n_mixels} mixels"
        seconds = samples / SAMPLES_PER_S[kind] + n_frames * per_frame
    if variant == "scalar_rgb":
        seconds *= SCALAR_SLOWDOWN
    if budget.target_rel_stderr > 0:
        what += " (first pass; target_rel_stderr adds passes)"
    return STARTUP_S + seconds, what


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    if seconds < 3 * 86400:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.3g} days"


def _gib(n_bytes: float) -> str:
    return f"{n_bytes / 2**30:.3g} GiB"


def check_budget(cfg: RenderConfig | WorldConfig, variant: str | None,
                 limit_s: float = DEFAULT_TIME_LIMIT_S) -> float:
    """Refuse a render whose estimated time (:func:`estimate_seconds`) exceeds ``limit_s``, or whose arrays
    (:func:`estimate_bytes`) would not fit in the memory free now; return the time estimate [s].

    Raises
    ------
    ConfigError
        Naming the estimate, what it counts, and the fixes (fewer samples or frames, or a higher limit; for
        memory: the GiB needed and free).
    """
    seconds, what = estimate_seconds(cfg, variant)
    world = isinstance(cfg, WorldConfig)
    if seconds > limit_s:
        key = {ResponseMap: "[run] samples_per_texel", DotProduct: "[run.dot_product] nodes"}.get(
            type(cfg.run.solver), "[run] spp")
        frames = "the movers' frames" if world else "the frames"
        raise ConfigError(f"this render would take about {_duration(seconds)} ({what}), over the limit of "
                          f"{_duration(limit_s)}: lower {key} (or {frames}), or raise the limit with "
                          f"--time-limit-s {max(limit_s, 1.5 * seconds):.0f}")
    n_bytes, held = estimate_bytes(cfg)
    check_memory(n_bytes, held, "fewer frames or a smaller [world.camera]" if world else
                 "fewer frames, fewer mixels or a lower [screen] resolution")
    return seconds


# Memory: what a render holds at once besides the scene (frames stream in chunks; tracing launches are bounded).
def estimate_bytes(cfg: RenderConfig | WorldConfig) -> tuple[float, str]:
    """The bytes a render's arrays hold at once, roughly, and what they are (nothing is built).

    Per frame and mixel the results (``RESULT_BYTES_PER_VALUE``); displays: the response maps (weights and
    variances per texel and mixel, and their copies) and the chunk of frames in memory; worlds: each frame's
    parameter updates (one 4 x 4 transform per mover here; the vertices of moving meshes are counted by
    :func:`mover_updates` once the scene is built) and the camera's images.
    """
    n_mixels = len(cfg.mincam)
    if isinstance(cfg, WorldConfig):
        n = cfg.n_frames
        n_bytes = float(n) * n_mixels * RESULT_BYTES_PER_VALUE + float(n) * len(cfg.movers) * (16 + 6) * 8 * 2
        what = f"{n} frames x {len(cfg.movers)} movers"
        if cfg.camera is not None:
            # the images, their stack for camera.npz and each frame's whole-film difference (camera_changes)
            n_bytes += 3.0 * (n + 1) * cfg.camera.width_px * cfg.camera.height_px * 8
            what += f" + {n + 1} camera images of {cfg.camera.width_px} x {cfg.camera.height_px} px"
        return n_bytes, what
    n = len(cfg.frames)
    rows, cols = cfg.screen.shape
    maps = float(rows * cols) * n_mixels * 8 * 4 if isinstance(cfg.run.solver, ResponseMap) else 0.0  # W, var, copies
    chunk = float(min(n, cfg.frames.chunk_size())) * cfg.frames.nbytes_per_frame * 3
    n_bytes = float(n) * n_mixels * RESULT_BYTES_PER_VALUE + maps + chunk
    return n_bytes, f"{n} frames x {n_mixels} mixels, {rows} x {cols} texels"


def available_bytes() -> float:
    """Memory free for a new allocation now [bytes]: the kernel's MemAvailable (Linux), else the physical
    memory."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, OSError, ValueError):
        return float("inf")


def check_memory(n_bytes: float, what: str, fix: str) -> None:
    """Refuse, before allocating, arrays of ``n_bytes`` that do not fit in the memory free now.

    Raises
    ------
    ConfigError
        Naming the GiB needed (and what they hold), the GiB free, and ``fix``.
    """
    free = available_bytes()
    if n_bytes > free:
        raise ConfigError(f"this render would hold about {_gib(n_bytes)} in memory ({what}), more than the "
                          f"{_gib(free)} free on this machine: {fix}")


# ----------------------------------------------------------------------------------------------- --check
def _budget_text(cfg: RenderConfig | WorldConfig) -> str:
    b, solver = cfg.run.budget, cfg.run.solver
    if isinstance(solver, DotProduct):
        effects = ", ".join(solver.effects()) or "the bare model"
        n, c = solver.nodes, solver.detector_nodes_per_axis()
        points = f"{n} x {n} points per texel" + (f" x {c} x {c} on the detector" if solver.detector_blur else "")
        return f"{effects}, deterministic quadrature ({points}, no samples; an error estimate as stderr)"
    if b.target_rel_stderr > 0:
        text = f"target relative stderr {b.target_rel_stderr:g}"
    elif isinstance(cfg.run.solver, ResponseMap):
        text = f"{b.samples_per_texel} samples per texel"
    else:
        text = f"{b.rays()} samples per mixel per frame"
    if not isinstance(cfg.run.solver, ResponseMap):
        text += f", {b.replicates} replicates"
    return f"{text}, seed {b.seed}"


def config_summary(cfg: RenderConfig, variant: str | None, limit_s: float = DEFAULT_TIME_LIMIT_S) -> list[str]:
    """What a validated config will render, one line per part (``mincam-sim render --check``); the estimate
    against ``limit_s`` [s]."""
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
    lo, hi, seen = _radiance_range(f)
    lines.append(f"frames: {len(f)} ({cfg.frames_kind}), {f.shape[2]} x {f.shape[1]} texels, radiance "
                 f"{lo:g} .. {hi:g} W m^-2 sr^-1{seen}, {len(f) * f.nbytes_per_frame / 2**20:.1f} MiB if held at "
                 "once (streamed in chunks)")
    lines.append(f"solver: {solver_name(run.solver)}, {_budget_text(cfg)}, variant {variant or 'automatic'}")
    _, rounding = traced_samples(run)
    if rounding is not None:
        lines.append(f"samples: {rounding}")
    lines.append(_estimate_line(cfg, variant, limit_s))
    out = Path(run.out_dir)
    state = "exists" if out.is_dir() else "will be created"
    if (out / RESULT).exists() or (out / f"{RESULT}.npz").exists():
        state += ", holds an earlier run (resumed if unchanged, refused if different unless --overwrite)"
    lines.append(f"out dir: {out} ({state})")
    return lines


SUMMARY_FRAMES = 64  # --check reads at most this many frames (evenly spread) for the radiance range


def _radiance_range(frames) -> tuple[float, float, str]:
    """(lowest, highest radiance, a note) over the frames, or over :data:`SUMMARY_FRAMES` of them spread evenly
    (a million-frame sweep is summarised in a moment; the note says so)."""
    n = len(frames)
    picked = np.unique(np.linspace(0, n - 1, min(n, SUMMARY_FRAMES)).round().astype(int))
    sample = [frames[int(i)] for i in picked]
    note = "" if len(picked) == n else f" (in {len(picked)} frames spread over the {n})"
    return min(float(x.min()) for x in sample), max(float(x.max()) for x in sample), note


def _estimate_line(cfg: RenderConfig | WorldConfig, variant: str | None, limit_s: float) -> str:
    """``estimate: ...``: the time and memory :func:`check_budget` weighs, and whether it would refuse them."""
    seconds, what = estimate_seconds(cfg, variant)
    n_bytes, _ = estimate_bytes(cfg)
    free = available_bytes()
    line = (f"estimate: about {_duration(seconds)} ({what}; limit {_duration(limit_s)}, --time-limit-s raises it), "
            f"about {_gib(n_bytes)} of arrays in memory ({_gib(free)} free)")
    if seconds > limit_s:
        line += f"; OVER THE TIME LIMIT: render refuses it unless --time-limit-s {1.5 * seconds:.0f}"
    if n_bytes > free:
        line += "; MORE THAN THE FREE MEMORY: render refuses it"
    return line


def world_summary(cfg: WorldConfig, variant: str | None, limit_s: float = DEFAULT_TIME_LIMIT_S) -> list[str]:
    """What a validated world config will render, one line per part (``mincam-sim render --check``); the estimate
    against ``limit_s`` [s]."""
    lines = [f"config: {cfg.source or 'text'} is valid (world scene)"]
    for mixel in cfg.mincam:
        p = ", ".join(f"{v:+.4f}" for v in mixel.pose.position_m)
        f = ", ".join(f"{v:+.3f}" for v in mixel.pose.forward)
        u = ", ".join(f"{v:+.3f}" for v in mixel.pose.up)
        lines.append(f"mixel {mixel.name}: mask {mixel.mask.name} at d_f {1e3 * mixel.d_f_m:g} mm, position [{p}] m, "
                     f"forward [{f}], up [{u}]")
    if cfg.scene_file is not None:
        lines.append(f"scene: {cfg.scene_file} ({cfg.up}-up)")
    for obj in cfg.objects:
        lines.append(f"object {obj.id}: {obj.mesh.name}, albedo {obj.albedo:g}, at {list(obj.position_m)} m")
    for light in cfg.lights:
        lines.append(f"light {light.id}: {light.kind}")
    for mover in cfg.movers:
        span = np.ptp(mover.offsets_m, axis=0)
        lines.append(f"mover {mover.id}: {len(mover.offsets_m)} frames, travel {np.round(span, 4).tolist()} m")
    depth = cfg.run.max_depth or "from the scene file's <integrator>, else 3"
    lines.append(f"solver: {solver_name(cfg.run.solver)}, {_budget_text(cfg)}, max_depth {depth}, "
                 f"background {cfg.background}, variant {variant or 'automatic'}")
    lines.append(_estimate_line(cfg, variant, limit_s))
    lines.append(f"out dir: {cfg.run.out_dir}")
    return lines
