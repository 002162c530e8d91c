"""Your own scene from a file: a validated world config -> the scene (XML + meshes + lights), the movers'
per-frame updates, dP and P per frame on disk with a plot, and the optional ground-truth camera.

Outputs in ``[run] out_dir``: ``measurements.npz`` (``irradiance_w_m2`` / ``stderr_w_m2``: P;
``delta_irradiance_w_m2`` / ``delta_stderr_w_m2``: dP; (n_frames, n_mixels) each), ``measurements.csv`` (frame,
time, each mover's offset and centre, dP and P per mixel with their standard errors), ``dP.png``, and with a
camera ``camera.npz`` (every frame's image and the background's) plus the change centroid per frame in the CSV.
The directory is locked while a run writes it; ``identity.json`` records everything the numbers depend on (the
config, the content of every file it names, the library versions), so a rerun resumes or reuses, and a changed
XML, mesh or trajectory is refused unless ``overwrite``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from .atomic import atomic_path, atomic_save_npz
from .changes import Changes
from .identity import build_identity, run_key
from .render import backend
from .render import scene_dicts as sd
from .render.scene_files import load_scene_file, read_mesh
from .render.simulation import Simulation
from .render.solvers import PlainChange, StratifiedChange
from .run import Run
from .world_config import CameraSpec, WorldConfig

Y_UP_TO_Z_UP = np.array([[1.0, 0, 0, 0], [0, 0, -1.0, 0], [0, 1.0, 0, 0], [0, 0, 0, 1.0]])  # +y -> +z, +z -> -y


def rotation_deg(angles_deg) -> np.ndarray:
    """3 x 3 rotation: about x, then y, then z, by ``angles_deg`` [deg]."""
    ax, ay, az = np.radians(np.asarray(angles_deg, dtype=float))
    rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
    ry = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
    rz = np.array([[np.cos(az), -np.sin(az), 0], [np.sin(az), np.cos(az), 0], [0, 0, 1]])
    return rz @ ry @ rx


def _turn_scene(scene, matrix: np.ndarray) -> None:
    """Apply a rigid ``matrix`` (4 x 4) to every position-carrying parameter of a loaded scene, in place:
    transforms, vertex positions and normals, point lights' positions."""
    from .render.mincam_scene import _as_param

    mi = backend.mitsuba()
    params = mi.traverse(scene)
    rot = matrix[:3, :3]
    for key in list(params.keys()):
        rest = key.rpartition(".")[2]
        value = params[key]
        if rest == "to_world" and "Transform4" in type(value).__name__:
            turned = matrix @ np.array(value.matrix, dtype=np.float64).reshape(4, 4)
        elif rest in ("vertex_positions", "vertex_normals", "position"):
            turned = np.array(value, dtype=np.float64).reshape(-1, 3) @ rot.T
            if rest != "vertex_normals":
                turned = turned + matrix[:3, 3]
            turned = turned.ravel()
        else:
            continue
        params[key] = _as_param(mi, value, turned, key)
    params.update()


def build_elements(cfg: WorldConfig) -> dict:
    """The world's elements: the XML scene (turned z-up if authored y-up) and the config's objects and lights."""
    elements: dict = {}
    if cfg.scene_file is not None:
        scene = load_scene_file(cfg.scene_file)
        if cfg.up == "y":
            _turn_scene(scene, Y_UP_TO_Z_UP)
        elements["scene"] = scene
    for obj in cfg.objects:
        vertices, faces = read_mesh(obj.mesh)
        placed = (vertices * obj.scale) @ rotation_deg(obj.rotation_deg).T + np.asarray(obj.position_m)
        elements[obj.id] = sd.mesh_object(obj.id, placed, faces, obj.albedo)
    for light in cfg.lights:
        elements[light.id] = _light_dict(light)
    return elements


def _light_dict(light) -> dict:
    from .geometry import Pose

    if light.kind == "sky":
        return sd.sky(light.radiance_w_m2_sr)
    if light.kind == "point":
        return {"type": "point", "position": list(light.position_m),
                "intensity": {"type": "spectrum", "value": float(light.intensity_w_sr)}}
    forward = np.asarray(light.forward, dtype=float)
    up = (1.0, 0.0, 0.0) if abs(forward[0]) < 0.9 * np.linalg.norm(forward) else (0.0, 1.0, 0.0)
    matrix = Pose(tuple(light.position_m), tuple(forward), up).matrix()
    if light.kind == "area":
        return sd.area_light(light.size_m[0], light.size_m[1], matrix, light.radiance_w_m2_sr)
    mi = backend.mitsuba()
    return {"type": "spot", "to_world": mi.ScalarTransform4f(matrix.tolist()),
            "intensity": {"type": "spectrum", "value": float(light.intensity_w_sr)},
            "cutoff_angle": float(light.cutoff_deg), "beam_width": 0.75 * float(light.cutoff_deg)}


def mover_updates(sim: Simulation, cfg: WorldConfig) -> tuple[list[dict], dict, dict[str, np.ndarray]]:
    """(frames, background, centres): each frame's parameter updates (world coordinates), the background's,
    and each mover's centre per frame [m] (its as-built bounding-box centre moved with it)."""
    from .errors import ConfigError

    params = sim.params
    n = cfg.n_frames
    frames: list[dict] = [{} for _ in range(n)]
    background: dict = {}
    centres: dict[str, np.ndarray] = {}
    for mover in cfg.movers:
        vkey, tkey = f"{mover.id}.vertex_positions", f"{mover.id}.to_world"
        if vkey in params:
            v0 = params[vkey].reshape(-1, 3)
            centre = 0.5 * (v0.min(axis=0) + v0.max(axis=0))
            for i in range(n):
                rot = np.eye(3) if mover.rotations_deg is None else rotation_deg(mover.rotations_deg[i])
                frames[i][vkey] = ((v0 - centre) @ rot.T + centre + mover.offsets_m[i]).ravel()
            if cfg.background == "without_movers":  # every vertex at one point: no area, nothing to hit
                background[vkey] = np.repeat(centre[None], len(v0), axis=0).ravel()
        elif tkey in params:
            m0 = params[tkey]
            centre = m0[:3, 3].copy()
            for i in range(n):
                rot = np.eye(3) if mover.rotations_deg is None else rotation_deg(mover.rotations_deg[i])
                m = m0.copy()
                m[:3, :3] = rot @ m0[:3, :3]
                m[:3, 3] = centre + mover.offsets_m[i]
                frames[i][tkey] = m
            if cfg.background == "without_movers":  # shrunk to a micrometre speck where it stands
                m = m0.copy()
                m[:3, :3] *= 1e-6 / max(float(np.abs(m0[:3, :3]).max()), 1e-300)
                background[tkey] = m
        else:
            known = sorted({k.split(".", 1)[0] for k in params})
            raise ConfigError(f"[[world.mover]] id {mover.id!r} is not a shape of the scene; shapes: "
                              f"{', '.join(known)}")
        centres[mover.id] = centre + mover.offsets_m
    if cfg.background == "first_frame":
        background = dict(frames[0])
    return frames, background, centres


def world_identity(cfg: WorldConfig, variant: str) -> dict:
    """Everything a world render's numbers depend on: the config as parsed and the content of every file it
    names (XML, meshes, trajectories), the variant and the library versions."""
    import hashlib

    files = {}
    for path in cfg.files:
        files[str(path)] = hashlib.sha256(path.read_bytes()).hexdigest()
    raw = {k: v for k, v in cfg.raw.items()}
    raw["run"] = {k: v for k, v in raw.get("run", {}).items() if k != "out_dir"}
    return build_identity("world_config", {"config": raw, "files": files}, variant=variant)


def run_world_config(cfg: WorldConfig, show_progress: bool = False, overwrite: bool = False,
                     say: Callable[[str], None] | None = None) -> Changes:
    """Render a validated :class:`~mincam_sim.world_config.WorldConfig`; write its outputs; return the changes."""
    out = Path(cfg.run.out_dir)
    identity = world_identity(cfg, backend.variant())
    key = run_key(identity)
    with Run(out, overwrite=overwrite) as job:  # one lock for the identity record and the store run/
        if overwrite:
            job.clear("run")
        same = job.record_identity(identity)
        if same and (out / "measurements.npz").is_file():
            try:
                done = Changes.load_npz(out / "measurements.npz")
                if done.dp.meta.get("identity_key") == key:
                    if say is not None:
                        say(f"mincam-sim: {out} holds the finished results of this same run; shown again "
                            "(--overwrite renders anew)")
                    return done
            except Exception:  # torn or foreign: render again (replaced atomically at the end)
                pass
        sim = Simulation(cfg.mincam, world=build_elements(cfg), max_depth=cfg.run.max_depth,
                         camera=_camera_dict(cfg.camera) if cfg.camera else None)
        frames, background, centres = mover_updates(sim, cfg)
        from .budget import Budget

        solver = StratifiedChange() if cfg.run.estimator == "stratified" else PlainChange()
        budget = Budget(spp=cfg.run.spp, target_rel_stderr=cfg.run.target_rel_stderr,
                        replicates=cfg.run.replicates, seed=cfg.run.seed)
        ch = sim.measure_changes(frames, background, solver, budget, sink=job.sink("run"),
                                 show_progress=show_progress)
        ch.dp.meta["identity_key"] = key
        columns = {"time_s": np.arange(cfg.n_frames) / cfg.frame_rate_hz}
        for mover in cfg.movers:
            for k, axis in enumerate("xyz"):
                columns[f"{mover.id}_offset_{axis}_m"] = mover.offsets_m[:, k]
            for k, axis in enumerate("xyz"):
                columns[f"{mover.id}_centre_{axis}_m"] = centres[mover.id][:, k]
        if cfg.camera is not None:
            rows, cols = _ground_truth(sim, cfg.camera, frames, background, out)
            columns["change_centroid_row_px"], columns["change_centroid_col_px"] = rows, cols
        ch.frame_columns = columns
        plot_changes(ch, out / "dP.png")
        ch.save_csv(out / "measurements.csv")
        ch.save_npz(out / "measurements.npz")  # last: it marks the run finished
    return ch


def _camera_dict(camera: CameraSpec) -> dict:
    from .geometry import look_at

    pose = look_at(camera.position_m, camera.look_at_m, camera.up)
    return sd.pinhole_camera(pose.matrix(), camera.fov_deg, camera.width_px, camera.height_px, spp=camera.spp)


def _ground_truth(sim: Simulation, camera: CameraSpec, frames, background, out: Path):
    """Images of the background and every frame, and the centroid (row, col) [px] of each frame's change:
    background subtraction, |change| > threshold x the background's maximum (the experiments' rule)."""
    sim.update(background)
    bg = sim.camera_image(camera.spp, seed=0)
    images, rows, cols = [], [], []
    for frame in frames:
        sim.update(background)
        sim.update(frame)
        image = sim.camera_image(camera.spp, seed=0)
        images.append(image)
        hit = np.abs(image - bg) > camera.threshold * float(bg.max())
        r, c = np.nonzero(hit)
        rows.append(r.mean() if r.size else np.nan)
        cols.append(c.mean() if c.size else np.nan)
    sim.update(background)
    atomic_save_npz(out / "camera.npz", background=bg, frames=np.array(images))
    return np.array(rows), np.array(cols)


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
    ax.set_title(f"change per mixel ({ch.info.estimator}, {ch.info.rays_per_mixel_per_frame} rays/mixel/frame)")
    ax.legend(fontsize=8, ncol=min(4, len(ch.mixel_names)))
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)
    return path


def world_summary(cfg: WorldConfig, variant: str | None) -> list[str]:
    """What a validated world config will render, one line per part (``mincam-sim render --check``)."""
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
    lines.append(f"run: {cfg.run.estimator}, spp {cfg.run.spp}, {cfg.run.replicates} replicates, seed "
                 f"{cfg.run.seed}, background {cfg.background}, variant {variant or 'automatic'}")
    lines.append(f"out dir: {cfg.run.out_dir}")
    return lines
