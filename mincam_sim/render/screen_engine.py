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

import zlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..measurements import Measurements
from ..optics import Mincam
from ..progress import progress
from ..screen import Screen, check_visible
from . import backend
from .mixel_sensor import sensor_dict
from .scene_dicts import (
    SCREEN_KEY,
    SCREEN_RADIANCE_PARAM,
    frame_tensor,
    mask_transmission_texture,
    mixel_reference_shapes,
    screen_shape,
)

MAX_SPP_PER_PASS = 1 << 20  # a film pixel accumulates in float32: keep each pass well below ~2^22 samples
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
            scene["sensor"] = sensor_dict(len(mincam), replicates=self.replicates, spp=1)
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

    def _render_fast(self, spp: int, replicates: int, seed: int) -> np.ndarray:
        """(replicates, n_mixels) independent estimates."""
        mi = self.mi
        n = len(self.mincam)
        per_pixel = max(1, -(-spp // replicates))
        passes = -(-per_pixel // MAX_SPP_PER_PASS)
        acc = np.zeros((replicates, n))
        for p in range(passes):
            spp_pass = min(MAX_SPP_PER_PASS, per_pixel - p * MAX_SPP_PER_PASS)
            img = mi.render(self.scene, spp=spp_pass, seed=derive_seed(seed, "fast", p))
            acc += np.asarray(img, dtype=np.float64).reshape(replicates, n) * spp_pass
        return acc / per_pixel

    def _render_reference(self, spp: int, replicates: int, seed: int) -> np.ndarray:
        mi = self.mi
        per_rep = max(1, -(-spp // replicates))
        out = np.zeros((replicates, len(self.mincam)))
        for k, sensor in enumerate(self._sensors):
            for r in range(replicates):
                done = 0
                while done < per_rep:
                    n = min(MAX_SPP_PER_PASS, per_rep - done)
                    img = mi.render(self.scene, sensor=sensor, spp=n, seed=derive_seed(seed, "ref", k, r, done))
                    out[r, k] += float(np.asarray(img, dtype=np.float64).mean()) * n
                    done += n
        return out / per_rep

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
            if self.form == "fast":
                est = self._render_fast(spp, replicates, seed)
            else:
                est = self._render_reference(spp, replicates, seed)
            mean, err = _mean_and_stderr(est)
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
) -> ResponseMaps:
    """Trace each mixel's response map over the display's texels.

    For texel ``t`` and mixel ``k``::

        W[k, t] = 1/A_d int_det int_texel T(x_m) cos(t_d) cos(t_s) / r^2 V(x_m, x_s) dA_s dA_d

    estimated with ``samples_per_texel`` pairs (x_d uniform on the detector, x_s uniform in the texel); x_m is
    where the segment crosses the mask plane (outside the aperture the housing blocks it), ``t_s`` is measured
    at the screen (emission only from its front), and V is a shadow ray in the Mitsuba scene.
    """
    backend.require_jit("Response maps")
    check_visible(screen, mincam)
    if int(samples_per_texel) != samples_per_texel or samples_per_texel < 2:
        raise ValueError(f"samples_per_texel must be an integer >= 2, got {samples_per_texel!r}")
    mi = backend.mitsuba()
    import drjit as dr

    scene = mi.load_dict({"type": "scene", SCREEN_KEY: screen_shape(screen)})
    rows, cols = screen.shape
    n_tex = rows * cols
    spt = int(samples_per_texel)
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
            s_screen = sampler.next_2d()
            s_det = sampler.next_2d()
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
            s1 = dr.block_sum(g, spt)
            s2 = dr.block_sum(g * g, spt)
            s1_np = np.asarray(s1, dtype=np.float64)
            s2_np = np.asarray(s2, dtype=np.float64)
            mean = s1_np / spt
            weights[out_k, start : start + count] = mean
            variance[out_k, start : start + count] = np.maximum(s2_np - spt * mean**2, 0.0) / (spt - 1) / spt
    names = [mincam[k].name for k in indices]
    meta = {
        "form": "response_map",
        "estimator": "texel_area_sampling_with_shadow_rays",
        "samples_per_texel": spt,
        "seed": seed,
        "units": "sr (W/m^2 on the detector per W m^-2 sr^-1 of texel radiance)",
        **backend.describe(),
        **geometry_meta(Mincam(tuple(mincam[k] for k in indices)), screen),
    }
    return ResponseMaps(weights.reshape(len(indices), rows, cols), variance.reshape(len(indices), rows, cols),
                        names, meta)
