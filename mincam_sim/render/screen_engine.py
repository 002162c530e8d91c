"""Mixel measurements of a flat display, by three estimators of the same integral.

* ``reference``: the literal scene (mask surface, housing, detector with Mitsuba's ``irradiancemeter``,
  ``path`` integrator). Slow and obviously right.
* ``fast``: the :mod:`~mincam_sim.render.mixel_sensor` plugin, rays start on the mask apertures
  (``path`` integrator, all mixels in one render).
* ``response map``: :func:`response_maps` traces, for every display texel, rays from detector points through
  the mask plane to points in the texel (with a visibility test in the Mitsuba scene); any frame is then
  ``sum(W * frame)``, exact in expectation.

All return irradiance averaged over each detector [W/m^2] with its Monte Carlo standard error.
"""

from __future__ import annotations

import hashlib
import zlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..measurements import Measurements
from ..optics import Mincam
from ..progress import progress
from ..screen import Screen, check_visible
from ..store import ResultStore
from . import backend
from .mixel_sensor import mixel_position_sample, sensor_dict
from .scene_dicts import (
    SCREEN_KEY,
    SCREEN_RADIANCE_PARAM,
    frame_tensor,
    mask_transmission_texture,
    mixel_reference_shapes,
    screen_shape,
)
from .tracing import trace_groups

REFERENCE_MAX_DEPTH = 3  # camera ray -> mask pass-through (one bounce) -> screen emission, plus margin


def derive_seed(*parts: int | str) -> int:
    """A 32-bit seed derived deterministically from ``parts`` (same inputs, same seed)."""
    return zlib.crc32(repr(parts).encode()) & 0x7FFFFFFF


def geometry_meta(mincam: Mincam, screen: Screen | None = None) -> dict:
    """JSON-friendly description of the set-up, stored with every output."""
    meta: dict = {
        "mixels": [
            {
                "name": m.name,
                "position_m": list(m.pose.position_m),
                "forward": list(m.pose.forward),
                "up": list(m.pose.up),
                "d_f_m": m.d_f_m,
                "detector_size_m": m.detector_size_m,
                "mask": {"name": m.mask.name, "width_m": m.mask.width_m, "height_m": m.mask.height_m,
                         "shape": list(m.mask.shape)},
            }
            for m in mincam
        ]
    }
    if screen is not None:
        meta["screen"] = {
            "width_m": screen.width_m,
            "height_m": screen.height_m,
            "resolution": list(screen.resolution),
            "position_m": list(screen.pose.position_m),
            "forward": list(screen.pose.forward),
            "up": list(screen.pose.up),
        }
    return meta


def _check_counts(spp: int, replicates: int) -> None:
    if int(spp) != spp or spp <= 0:
        raise ValueError(f"spp (samples per mixel per frame) must be a positive integer, got {spp!r}")
    if int(replicates) != replicates or replicates < 2:
        raise ValueError(f"replicates must be an integer >= 2 (needed for a standard error), got {replicates!r}")


def _as_frames(screen: Screen, frames) -> list[np.ndarray]:
    arr = frames if isinstance(frames, np.ndarray) else None
    if arr is not None and arr.ndim == 2:
        return [screen.check_frame(arr)]
    return [screen.check_frame(f, f"frame {i}") for i, f in enumerate(frames)]


def _mean_and_stderr(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard error over axis 0 (independent replicates)."""
    r = samples.shape[0]
    return samples.mean(axis=0), samples.std(axis=0, ddof=1) / np.sqrt(r)


class ScreenRenderer:
    """A mincam in front of a display in a dark room, rendered with Mitsuba.

    Parameters
    ----------
    mincam : Mincam
    screen : Screen
    form : {"fast", "reference"}
        Which estimator renders frames (see module docstring).
    replicates : int
        Independent estimates per measurement whose spread gives the standard error (>= 2).
    """

    def __init__(self, mincam: Mincam, screen: Screen, form: str = "fast", replicates: int = 8) -> None:
        if form not in ("fast", "reference"):
            raise ValueError(f"form must be 'fast' or 'reference', got {form!r}")
        _check_counts(1, replicates)
        check_visible(screen, mincam)
        self.mincam, self.screen, self.form, self.replicates = mincam, screen, form, int(replicates)
        self.mi = backend.mitsuba()
        scene = {"type": "scene", SCREEN_KEY: screen_shape(screen)}
        if form == "reference":
            scene["integrator"] = {"type": "path", "max_depth": REFERENCE_MAX_DEPTH}
            for k, mixel in enumerate(mincam):
                scene.update(mixel_reference_shapes(mixel, f"mixel{k}", spp=1))
            self.scene = self.mi.load_dict(scene, optimize=False)
            self._sensors = self._reference_sensors()
        else:
            scene["integrator"] = {"type": "path", "max_depth": 2}
            scene["sensor"] = sensor_dict(len(mincam))
            self.scene = self.mi.load_dict(scene)
            self.scene.sensors()[0].set_mixels(list(mincam))
        self.params = self.mi.traverse(self.scene)

    def _reference_sensors(self) -> list:
        by_shape = {}
        for shape in self.scene.shapes():
            sensor = shape.sensor()
            if sensor is not None:
                by_shape[shape.id()] = sensor
        return [by_shape[f"mixel{k}_detector"] for k in range(len(self.mincam))]

    def set_frame(self, frame: np.ndarray) -> None:
        """Show ``frame`` (radiance, W m^-2 sr^-1, row 0 at the top) on the display."""
        self.params[SCREEN_RADIANCE_PARAM] = frame_tensor(self.screen.check_frame(frame))
        self.params.update()

    def _estimates(self, spp: int, replicates: int, seed: int) -> np.ndarray:
        """(replicates, n_mixels) independent estimates, each from ``spp / replicates`` rays."""
        per_rep = max(1, -(-spp // replicates))
        n = len(self.mincam)
        if self.form == "fast":
            sensor = self.scene.sensors()[0]
            means = trace_groups(self.scene, sensor, n * replicates, per_rep, derive_seed(seed, "fast"),
                                 position_sample=mixel_position_sample(n, replicates))
            return means.reshape(n, replicates).T
        out = np.zeros((replicates, n))
        for k, sensor in enumerate(self._sensors):
            out[:, k] = trace_groups(self.scene, sensor, replicates, per_rep, derive_seed(seed, "ref", k))
        return out

    def render(
        self,
        frames: np.ndarray | Iterable[np.ndarray],
        spp: int = 1 << 16,
        seed: int = 0,
        show_progress: bool = False,
    ) -> Measurements:
        """Measure every frame.

        Parameters
        ----------
        frames : (rows, cols) array or iterable of them
            Display radiance [W m^-2 sr^-1].
        spp : int
            Samples per mixel per frame (split into ``replicates`` independent estimates).
        seed : int
            Base seed. The same seed is used for every frame, so the noise of two frames is correlated and
            largely cancels in their difference; same seed, same numbers.
        show_progress : bool
            Show a progress bar over frames.
        """
        replicates = self.replicates
        _check_counts(spp, replicates)
        frames = _as_frames(self.screen, frames)
        values, errors = [], []
        for frame in progress(frames, desc=f"{self.form} render", disable=not show_progress):
            self.set_frame(frame)
            mean, err = _mean_and_stderr(self._estimates(spp, replicates, seed))
            values.append(mean)
            errors.append(err)
        meta = {
            "form": self.form,
            "estimator": "mixel_sensor_path" if self.form == "fast" else "irradiancemeter_path",
            "spp_per_mixel_per_frame": int(replicates * max(1, -(-spp // replicates))),
            "replicates": replicates,
            "seed": seed,
            "units": "W/m^2 (irradiance averaged over the detector)",
            **backend.describe(),
            **geometry_meta(self.mincam, self.screen),
        }
        return Measurements(np.array(values), np.array(errors), self.mincam.names, meta)


@dataclass
class ResponseMaps:
    """What each mixel sees on the display: ``P_k = sum(W[k] * frame)``.

    Attributes
    ----------
    weights_sr : (n_mixels, rows, cols) ndarray
        Irradiance on the detector per unit texel radiance [W/m^2 per W m^-2 sr^-1 = sr].
    variance_sr2 : (n_mixels, rows, cols) ndarray
        Monte Carlo variance of each weight; texels are independent.
    """

    weights_sr: np.ndarray
    variance_sr2: np.ndarray
    mixel_names: list[str]
    meta: dict = field(default_factory=dict)

    def measure(self, frames: np.ndarray, chunk: int = 256) -> Measurements:
        """Measurements of frames (n, rows, cols) or one frame (rows, cols) [W m^-2 sr^-1]."""
        frames = np.asarray(frames, dtype=np.float64)
        if frames.ndim == 2:
            frames = frames[None]
        if frames.shape[1:] != self.weights_sr.shape[1:]:
            raise ValueError(f"frames of shape {frames.shape[1:]} do not match the maps' {self.weights_sr.shape[1:]}")
        w = self.weights_sr.reshape(len(self.mixel_names), -1).T
        v = self.variance_sr2.reshape(len(self.mixel_names), -1).T
        values = np.empty((len(frames), w.shape[1]))
        var = np.empty_like(values)
        for i in range(0, len(frames), chunk):
            f = frames[i : i + chunk].reshape(len(frames[i : i + chunk]), -1)
            values[i : i + chunk] = f @ w
            var[i : i + chunk] = (f * f) @ v
        meta = {**self.meta, "form": "response_map"}
        return Measurements(values, np.sqrt(var), list(self.mixel_names), meta)

    def save_exr(self, directory: str | Path) -> list[Path]:
        """One OpenEXR per mixel (channels W and sigma), the picture of what the mixel sees."""
        from ..imageio import write_exr

        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        paths = []
        for k, name in enumerate(self.mixel_names):
            path = directory / f"response_{_safe(name)}.exr"
            img = np.stack([self.weights_sr[k], np.sqrt(self.variance_sr2[k])], axis=-1)
            write_exr(path, img, channels=("W", "sigma"), metadata={"units": "sr", "mixel": name, **self.meta})
            paths.append(path)
        return paths

    def save_npz(self, path: str | Path) -> Path:
        import json

        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(path, weights_sr=self.weights_sr, variance_sr2=self.variance_sr2,
                 mixel_names=np.array(self.mixel_names), meta_json=np.array(json.dumps(self.meta, default=str)))
        return path

    @classmethod
    def load_npz(cls, path: str | Path) -> ResponseMaps:
        import json

        with np.load(path, allow_pickle=False) as d:
            return cls(d["weights_sr"], d["variance_sr2"], [str(s) for s in d["mixel_names"]],
                       json.loads(str(d["meta_json"])))


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name)


def response_maps(
    mincam: Mincam,
    screen: Screen,
    samples_per_texel: int = 64,
    seed: int = 0,
    mixel_indices: Sequence[int] | None = None,
    max_lanes: int = 1 << 23,
    replicates: int = 4,
) -> ResponseMaps:
    """Trace each mixel's response map over the display's texels.

    For texel ``t`` and mixel ``k``::

        W[k, t] = 1/A_d int_det int_texel T(x_m) cos(t_d) cos(t_s) / r^2 V(x_m, x_s) dA_s dA_d

    estimated from pairs (x_d on the detector, x_s in the texel); x_m is where the segment crosses the mask
    plane (outside the aperture the housing blocks it), ``t_s`` is measured at the screen (emission only from
    its front), and V is a shadow ray in the Mitsuba scene.

    Sampling: the samples of a texel form ``replicates`` independent blocks of ``k x k`` jittered strata on
    the detector and, in another stratum order, on the texel (``samples_per_texel`` is rounded to
    ``replicates * k^2``). Stratification removes most of the noise of the smooth integrand; the variance of
    each weight is estimated from the spread of the independent blocks, so it stays honest.
    """
    backend.require_jit("Response maps")
    check_visible(screen, mincam)
    if int(samples_per_texel) != samples_per_texel or samples_per_texel < 2:
        raise ValueError(f"samples_per_texel must be an integer >= 2, got {samples_per_texel!r}")
    if int(replicates) != replicates or not 2 <= replicates <= samples_per_texel:
        raise ValueError(f"replicates must be an integer in [2, samples_per_texel], got {replicates!r}")
    strata = max(1, int(np.sqrt(samples_per_texel / replicates)))  # k: strata per axis within a block
    mi = backend.mitsuba()
    import drjit as dr

    scene = mi.load_dict({"type": "scene", SCREEN_KEY: screen_shape(screen)})
    rows, cols = screen.shape
    n_tex = rows * cols
    block = strata * strata
    spt = replicates * block
    texels_per_chunk = max(1, min(n_tex, max_lanes // spt))
    right, up, normal = (np.asarray(a).tolist() for a in screen.pose.axes())
    center = [float(c) for c in screen.pose.position_m]
    texel_area = screen.texel_area_m2
    indices = list(range(len(mincam))) if mixel_indices is None else list(mixel_indices)

    weights = np.zeros((len(indices), n_tex))
    variance = np.zeros((len(indices), n_tex))
    sampler = mi.load_dict({"type": "independent"})
    for out_k, k in enumerate(indices):
        mixel = mincam[k]
        texture = mi.load_dict(mask_transmission_texture(mixel.mask))
        to_world = mixel.pose.matrix()
        rot = mi.Matrix3f(to_world[:3, :3].tolist())
        origin = mi.Point3f(*(float(c) for c in to_world[:3, 3]))
        rot_t = mi.Matrix3f(to_world[:3, :3].T.tolist())
        d_f, det = mixel.d_f_m, mixel.detector_size_m
        w_m, h_m = mixel.mask.width_m, mixel.mask.height_m
        for start in range(0, n_tex, texels_per_chunk):
            count = min(texels_per_chunk, n_tex - start)
            sampler.seed(derive_seed(seed, "response", k, start), count * spt)
            lane = dr.arange(mi.UInt32, count * spt)
            texel = lane // spt + start
            col = mi.Float(texel % cols)
            row = mi.Float(texel // cols)
            j = lane % block  # stratum index within the block
            jx, jy = mi.Float(j % strata), mi.Float(j // strata)
            jitter_screen = sampler.next_2d()
            jitter_det = sampler.next_2d()
            # detector strata in row order, texel strata in transposed, reversed order: both cover their domain
            s_det = mi.Point2f((jx + jitter_det.x) / strata, (jy + jitter_det.y) / strata)
            s_screen = mi.Point2f((strata - 1 - jy + jitter_screen.x) / strata, (jx + jitter_screen.y) / strata)
            xs = ((col + s_screen.x) / cols - 0.5) * screen.width_m
            ys = (0.5 - (row + s_screen.y) / rows) * screen.height_m
            p_screen = mi.Point3f(
                center[0] + xs * right[0] + ys * up[0],
                center[1] + xs * right[1] + ys * up[1],
                center[2] + xs * right[2] + ys * up[2],
            )
            x_d = mi.Vector3f((s_det.x - 0.5) * det, (s_det.y - 0.5) * det, 0.0)
            p_det = origin + rot @ x_d
            delta = p_screen - p_det
            r2 = dr.squared_norm(delta)
            direction = delta * dr.rsqrt(r2)
            d_local = rot_t @ direction
            cos_d = d_local.z
            cos_s = -dr.dot(direction, mi.Vector3f(*(float(c) for c in normal)))
            valid = (cos_d > 0) & (cos_s > 0)
            t_mask = d_f / dr.maximum(cos_d, 1e-12)
            x_m = x_d + d_local * t_mask
            u = 0.5 - x_m.x / w_m
            v = 0.5 - x_m.y / h_m
            valid &= (u >= 0) & (u <= 1) & (v >= 0) & (v <= 1)
            si = dr.zeros(mi.SurfaceInteraction3f)
            si.uv = mi.Point2f(u, v)
            transmission = texture.eval_1(si, valid)
            p_mask = p_det + direction * t_mask
            dist_after = dr.sqrt(r2) - t_mask
            shadow = mi.Ray3f(p_mask, direction, dist_after * (1 - 1e-5), 0.0, [])
            valid &= ~scene.ray_test(shadow, valid)
            g = dr.select(valid, transmission * cos_d * cos_s / r2 * texel_area, 0.0)
            blocks = np.asarray(dr.block_sum(g, block), dtype=np.float64).reshape(count, replicates) / block
            weights[out_k, start : start + count] = blocks.mean(axis=1)
            variance[out_k, start : start + count] = blocks.var(axis=1, ddof=1) / replicates
    names = [mincam[k].name for k in indices]
    meta = {
        "form": "response_map",
        "estimator": "texel_area_sampling_with_shadow_rays",
        "samples_per_texel": spt,
        "replicate_blocks": replicates,
        "strata_per_block": f"{strata}x{strata}",
        "seed": seed,
        "units": "sr (W/m^2 on the detector per W m^-2 sr^-1 of texel radiance)",
        **backend.describe(),
        **geometry_meta(Mincam(tuple(mincam[k] for k in indices)), screen),
    }
    return ResponseMaps(weights.reshape(len(indices), rows, cols), variance.reshape(len(indices), rows, cols),
                        names, meta)


MAX_SAMPLES_PER_TEXEL = 1 << 14
MAX_SPP = 1 << 28


def _required(pilot: int, measured_rel: float, target: float, cap: int) -> int:
    if not np.isfinite(measured_rel) or measured_rel <= 0:
        return pilot
    return int(min(cap, max(pilot, np.ceil(pilot * (measured_rel / target) ** 2 * 1.1))))


def response_maps_to_target(
    mincam: Mincam, screen: Screen, frames: np.ndarray, target_rel_stderr: float, seed: int = 0,
    max_samples_per_texel: int = MAX_SAMPLES_PER_TEXEL,
) -> tuple[ResponseMaps, list[dict]]:
    """Response maps whose measurements of ``frames`` all reach ``target_rel_stderr`` (if the cap allows).

    Two pilots (16 and 64 samples per texel) give the empirical convergence rate ``rel ~ n^-a`` (stratified
    sampling converges faster than ``n^-1/2``); the sample count is extrapolated with it, then checked and, if
    needed, raised again assuming the plain Monte Carlo rate. Returns the maps and the trail of
    (samples_per_texel, worst relative stderr) tried.
    """
    trail: list[dict] = []

    def attempt(n: int) -> tuple[ResponseMaps, float]:
        maps = response_maps(mincam, screen, n, seed)
        rel = worst_relative_stderr(maps.measure(frames))
        trail.append({"samples_per_texel": int(maps.meta["samples_per_texel"]), "worst_rel_stderr": rel})
        return maps, rel

    n1, n2 = 16, 64
    maps, rel1 = attempt(n1)
    if not rel1 > target_rel_stderr:
        return maps, trail
    maps, rel2 = attempt(n2)
    rate = float(np.clip(np.log(rel1 / rel2) / np.log(n2 / n1), 0.5, 1.5)) if rel2 > 0 else 0.5
    n, rel = n2, rel2
    while rel > target_rel_stderr and n < max_samples_per_texel:
        exponent = rate if len(trail) == 2 else 0.5
        n = int(min(max_samples_per_texel, max(2 * n, np.ceil(n * 1.2 * (rel / target_rel_stderr) ** (1 / exponent)))))
        maps, rel = attempt(n)
    return maps, trail


def worst_relative_stderr(m: Measurements) -> float:
    """Largest stderr/value over non-zero measurements (NaN if all are zero)."""
    live = m.irradiance_w_m2 > 0
    return float(np.max(m.relative_stderr()[live])) if live.any() else float("nan")


def render_frames(
    mincam: Mincam,
    screen: Screen,
    frames: np.ndarray,
    form: str = "response_map",
    spp: int = 1 << 16,
    samples_per_texel: int = 64,
    target_rel_stderr: float = 0.0,
    seed: int = 0,
    replicates: int = 8,
    out_dir: str | Path | None = None,
    show_progress: bool = False,
    chunk: int = 64,
) -> tuple[Measurements, ResponseMaps | None]:
    """Measure a stack of frames with any form, optionally to a target noise, resumably.

    Parameters
    ----------
    frames : (n, rows, cols) ndarray
        Display radiance [W m^-2 sr^-1].
    form : {"response_map", "fast", "reference"}
    spp, samples_per_texel : int
        Sample counts when ``target_rel_stderr`` is 0.
    target_rel_stderr : float
        If > 0, a pilot run measures the noise and the sample count is extrapolated (variance ~ 1/samples) so
        that the worst non-zero measurement reaches this relative standard error; the reached value is in
        ``meta["reached_rel_stderr"]``.
    out_dir : path, optional
        If given, per-frame results are written as they are computed and an interrupted run resumes there.

    Returns
    -------
    (Measurements, ResponseMaps or None)
    """
    frames = np.asarray(frames, dtype=np.float64)
    if frames.ndim == 2:
        frames = frames[None]
    if form not in ("response_map", "fast", "reference"):
        raise ValueError(f"form must be 'response_map', 'fast' or 'reference', got {form!r}")
    if not (np.isfinite(target_rel_stderr) and target_rel_stderr >= 0):
        raise ValueError(f"target_rel_stderr must be >= 0 (0 = use the given sample counts), got {target_rel_stderr}")
    for i, f in enumerate(frames):
        screen.check_frame(f, f"frame {i}")
    budget: dict = {"target_rel_stderr": target_rel_stderr}
    maps = None
    renderer = None
    if form == "response_map":
        maps_path = Path(out_dir) / "response_maps.npz" if out_dir else None
        if maps_path is not None and maps_path.exists():
            maps = ResponseMaps.load_npz(maps_path)
        else:
            if target_rel_stderr > 0:
                maps, trail = response_maps_to_target(mincam, screen, frames, target_rel_stderr, seed)
                samples_per_texel = int(maps.meta["samples_per_texel"])
                budget.update(budget_trail=trail)
            else:
                maps = response_maps(mincam, screen, samples_per_texel, seed)
            if maps_path is not None:
                maps.save_npz(maps_path)
        measure = maps.measure
        meta = dict(maps.meta)
    else:
        renderer = ScreenRenderer(mincam, screen, form, replicates)
        if target_rel_stderr > 0:
            pilot_spp = replicates * 2048
            pilot = renderer.render(frames[: min(len(frames), 4)], spp=pilot_spp, seed=derive_seed(seed, "pilot"))
            rel = worst_relative_stderr(pilot)
            spp = _required(pilot_spp, rel, target_rel_stderr, MAX_SPP)
            budget.update(pilot_spp=pilot_spp, pilot_rel_stderr=rel)

        def measure(stack):
            return renderer.render(stack, spp=spp, seed=seed)

        meta = {"form": form, "seed": seed, "replicates": replicates, **backend.describe(),
                **geometry_meta(mincam, screen)}
    budget.update(spp=spp if form != "response_map" else None,
                  samples_per_texel=samples_per_texel if form == "response_map" else None)
    store = None
    if out_dir is not None:
        identity = {"form": form, "seed": seed, "replicates": replicates, "budget": budget,
                    "frames_sha256": hashlib.sha256(np.ascontiguousarray(frames).tobytes()).hexdigest()[:16],
                    "geometry": geometry_meta(mincam, screen)}
        store = ResultStore(out_dir, len(frames), mincam.names, identity)
        todo = store.pending()
    else:
        todo = np.arange(len(frames))
    values = np.full((len(frames), len(mincam)), np.nan)
    errors = np.full_like(values, np.nan)
    if store is not None:
        values[:] = store.values
        errors[:] = store.stderr
    step = chunk if form == "response_map" else 1
    batches = [todo[i : i + step] for i in range(0, len(todo), step)]
    for idx in progress(batches, desc=f"{form}: frames", disable=not show_progress, total=len(batches)):
        m = measure(frames[idx])
        values[idx], errors[idx] = m.irradiance_w_m2, m.stderr_w_m2
        if store is not None:
            store.write(idx, m.irradiance_w_m2, m.stderr_w_m2)
    result = Measurements(values, errors, mincam.names, {**meta, **budget})
    result.meta["reached_rel_stderr"] = worst_relative_stderr(result)
    return result, maps
