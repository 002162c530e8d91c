"""Response maps: what each mixel sees of every display texel, traced once, then any frame is ``sum(W * frame)``.

For texel ``t`` and mixel ``k``::

    W[k, t] = 1/A_d int_det int_texel T(x_m) cos(t_d) cos(t_s) / r^2 V(x_m, x_s) dA_s dA_d

estimated from pairs (x_d on the detector, x_s in the texel); x_m is where the segment crosses the mask plane
(outside the aperture the housing blocks it), ``t_s`` is measured at the screen (emission only from its front),
and V is a visibility ray in the mincam's scene (the other mixels' bodies included).

Sampling: the samples of a texel form ``replicates`` independent blocks of ``k x k`` samples. Within a
block, sample ``(jx, jy)`` takes detector stratum ``(jx, jy)`` and texel stratum ``(pi_x(jy), pi_y(jx))``
with random permutations ``pi_x, pi_y`` of ``0..k-1`` drawn per (texel, block): both factors stay stratified;
the transposition keeps the texel's x stratum independent of the detector's x stratum (the detector blur
couples them along the same axis: that part of the integrand is summed over the full k x k grid of pairs);
and since every sample's texel stratum is uniform over the ``k x k`` strata, every sample is uniform over the
product domain, so each block is unbiased whatever the integrand couples (tilted masks, rotated screens).
Shifts (``pi(j) = j + s mod k``) in place of permutations were unbiased too, but a block then converged to an
integral along one line of strata pairs chosen by its shift: the noise fell with the number of blocks only,
not with the samples per texel (close 2 x 3 mm ramp, 4 blocks: relative sigma 5.8e-4 at 256 and 5.1e-4 at
65,536 samples per texel). With random permutations the terms that couple different axes average over
``k`` random pairs. A *fixed* pairing converges to an integral over a sub-manifold of the product domain,
and identical pairings across blocks hide that from the standard error. The variance of each weight comes
from the spread of the independent blocks.

Random numbers: texel ``t`` of mixel ``k`` draws those of launch ``t`` of the mixel's seed
(:class:`.tracing.LaneSampler`, the launch-seed rule of every loop), and each block's pairing its own stretch of
one PCG64 stream per mixel. Texels are traced in chunks of at most :data:`.tracing.MAX_LANES` samples, and a
map is the same bit for bit whatever the chunks.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mincam_sim.errors import InputError
from mincam_sim.measurements import Measurements
from mincam_sim.model.optics import Mincam, check_mixel_file_names, mixel_file_stem
from mincam_sim.progress import progress
from mincam_sim.render import backend
from mincam_sim.render.kernels import tracing
from mincam_sim.render.kernels.mask_eval import RayWeight, local_to_mask_xy, mask_model_meta, optics_meta
from mincam_sim.render.kernels.mixel_sensor import START_OFFSET_M
from mincam_sim.render.kernels.monte_carlo import derive_seed
from mincam_sim.render.scene.mincam_scene import MincamScene, geometry_meta
from mincam_sim.scene.display import FrameSource, Screen
from mincam_sim.storage.atomic import atomic_path, atomic_save_npz
from mincam_sim.storage.identity import fingerprint, library_versions
from mincam_sim.storage.imageio import write_exr
from mincam_sim.storage.store import ContentCache

MAX_SAMPLES_PER_TEXEL = 1 << 14  # cap of the target-noise search
FIRST_SAMPLES_PER_TEXEL = 16  # the search's first maps
SEARCH_GROWTH = (2, 8)  # each step of the search traces at least 2x, at most 8x the samples of the last one
SEARCH_EXPONENT = (0.5, 1.5)  # bounds of the measured convergence rate (stratified: faster than n^-1/2)
FRAME_CHUNK_BYTES = 1 << 27  # frames measured per chunk: at most 128 MiB of frame data in memory
RANDOM_NUMBERS = "per texel: launch `texel` of the mixel's seed; pairings: one PCG64 stream per mixel, by block"


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
        if frames.ndim != 3 or frames.shape[1:] != self.weights_sr.shape[1:]:
            raise ValueError(f"frames of shape {frames.shape[1:]} do not match the maps' {self.weights_sr.shape[1:]}")
        w = self.weights_sr.reshape(len(self.mixel_names), -1).T
        v = self.variance_sr2.reshape(len(self.mixel_names), -1).T
        values = np.empty((len(frames), w.shape[1]))
        var = np.empty_like(values)
        var_of_var = np.empty_like(values)
        for i in range(0, len(frames), chunk):
            f = frames[i : i + chunk].reshape(len(frames[i : i + chunk]), -1)
            # einsum's own loops, not BLAS: each value is summed in one order whatever the chunk (BLAS blocks by
            # the number of rows, so a frame streamed in another chunk differed in the last bits)
            values[i : i + chunk] = np.einsum("ft,tm->fm", f, w, optimize=False)
            f2 = f * f
            var[i : i + chunk] = np.einsum("ft,tm->fm", f2, v, optimize=False)
            var_of_var[i : i + chunk] = np.einsum("ft,tm->fm", f2 * f2, v * v, optimize=False)
        meta = {**self.meta, "form": "response_map"}
        return Measurements(values, np.sqrt(var), list(self.mixel_names), meta,
                            stderr_dof=effective_dof(var, var_of_var, self.replicate_blocks))

    @property
    def replicate_blocks(self) -> int:
        """Independent blocks per texel whose spread gave each weight's variance (``meta["replicate_blocks"]``;
        4, the solver's default, for maps built without it)."""
        return int(self.meta.get("replicate_blocks", 4))

    def measure_source(self, frames: FrameSource, indices=None, show_progress: bool = False,
                       desc: str = "frames") -> Measurements:
        """Measurements of (some of) a frame source, chunk by chunk (at most ``FRAME_CHUNK_BYTES`` of frames
        in memory); a frame with NaN, infinite or negative radiance is refused, by its index."""
        indices = np.arange(len(frames)) if indices is None else np.asarray(indices)
        values = np.empty((len(indices), len(self.mixel_names)))
        errors = np.empty_like(values)
        dof = np.empty_like(values)
        step = frames.chunk_size(FRAME_CHUNK_BYTES)
        for lo in progress(range(0, len(indices), step), desc=desc, disable=not show_progress):
            idx = indices[lo : lo + step]
            stack = frames[idx]
            check_radiance(stack, idx)
            m = self.measure(stack)
            values[lo : lo + len(idx)], errors[lo : lo + len(idx)] = m.irradiance_w_m2, m.stderr_w_m2
            dof[lo : lo + len(idx)] = m.stderr_dof
        return Measurements(values, errors, list(self.mixel_names), {**self.meta, "form": "response_map"},
                            stderr_dof=dof)

    def save_exr(self, directory: str | Path) -> list[Path]:
        """One OpenEXR per mixel (channels W and sigma), the picture of what the mixel sees."""
        check_mixel_file_names(self.mixel_names)
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        paths = []
        for k, name in enumerate(self.mixel_names):
            path = directory / f"response_{mixel_file_stem(name)}.exr"
            img = np.stack([self.weights_sr[k], np.sqrt(self.variance_sr2[k])], axis=-1)
            with atomic_path(path) as tmp:
                write_exr(tmp, img, channels=("W", "sigma"), metadata={"units": "sr", "mixel": name, **self.meta})
            paths.append(path)
        return paths

    def save_npz(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_save_npz(path, weights_sr=self.weights_sr, variance_sr2=self.variance_sr2,
                        mixel_names=np.array(self.mixel_names), meta_json=np.array(json.dumps(self.meta, default=str)))
        return path

    @classmethod
    def load_npz(cls, path: str | Path) -> ResponseMaps:
        with np.load(path, allow_pickle=False) as d:
            return cls(d["weights_sr"], d["variance_sr2"], [str(s) for s in d["mixel_names"]],
                       json.loads(str(d["meta_json"])))


FLOAT32_MAX = float(np.finfo(np.float32).max)  # [W m^-2 sr^-1] the largest radiance a texture holds


def effective_dof(var: np.ndarray, var_of_var: np.ndarray, replicates: int) -> np.ndarray:
    """Degrees of freedom of each value's variance ``var = sum_t f_t^2 v_t`` (Welch-Satterthwaite): every texel's
    ``v_t`` is the spread of ``replicates`` independent blocks, ``replicates - 1`` degrees of freedom each, so
    ``dof = (replicates - 1) var^2 / sum_t (f_t^2 v_t)^2`` (``var_of_var``). One texel in a value: ``replicates -
    1``; many alike: their number times that. ``inf`` where ``var`` is 0 (no spread to estimate)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        dof = (replicates - 1) * var * var / var_of_var
    return np.where(var > 0, dof, np.inf)


def check_radiance(stack: np.ndarray, indices: np.ndarray) -> None:
    """Refuse NaN, infinite, negative or beyond-float32 radiance (Mitsuba's textures), naming the first bad
    frame."""
    bad = ~((stack >= 0) & (stack <= FLOAT32_MAX)).all(axis=(1, 2))  # NaN fails both comparisons
    if bad.any():
        i = int(indices[np.argmax(bad)])
        raise InputError(f"frame {i} contains NaN, infinite, negative or too large (> {FLOAT32_MAX:.3g}, a 32-bit "
                         "float's largest) radiance; frames must be finite and >= 0 W m^-2 sr^-1")


@dataclass(frozen=True)
class MapSampling:
    """How a texel's samples are traced: ``replicates`` independent blocks of ``strata x strata`` samples."""

    strata: int
    replicates: int

    @classmethod
    def of(cls, samples_per_texel: int, replicates: int) -> MapSampling:
        """The sampling of ``samples_per_texel`` (rounded down to ``replicates x k^2``, k >= 1); a clear
        ``ValueError`` for counts that are not integers or too small."""
        n = samples_per_texel
        if isinstance(n, bool) or int(n) != n or n < 2:
            raise ValueError(f"samples_per_texel must be an integer >= 2, got {n!r}")
        if isinstance(replicates, bool) or int(replicates) != replicates or not 2 <= replicates <= n:
            raise ValueError(f"replicates must be an integer in [2, samples_per_texel], got {replicates!r}")
        return cls(max(1, int(np.sqrt(n / replicates))), int(replicates))

    @property
    def block(self) -> int:
        """Samples per block (``strata^2``)."""
        return self.strata * self.strata

    @property
    def samples_per_texel(self) -> int:
        """Samples traced per texel and mixel."""
        return self.replicates * self.block


def response_maps(
    mincam: Mincam,
    screen: Screen,
    samples_per_texel: int = 64,
    seed: int = 0,
    mixel_indices: Sequence[int] | None = None,
    replicates: int = 4,
    show_progress: bool = False,
    cache: ContentCache | None = None,
) -> ResponseMaps:
    """Trace each mixel's response map over the display's texels (see the module docstring).

    Parameters
    ----------
    samples_per_texel : int
        Samples per texel and mixel; rounded to ``replicates * k^2`` (k strata per axis in a block).
    replicates : int
        Independent blocks per texel (>= 2), whose spread gives each weight's variance.
    show_progress : bool
        A progress bar over (mixel, texel chunk) launches on stderr.
    cache : ContentCache, optional
        Each mixel's map is stored under a key derived from everything it depends on (the whole mincam, whose
        bodies occlude, the screen, the sampling, the seed, the backend and library versions), as soon as it is
        traced: an interrupted tracing resumes mixel by mixel, and any run that needs the same map reuses it.
    """
    backend.require_jit("Response maps")
    sampling = MapSampling.of(samples_per_texel, replicates)
    world = MincamScene.display(mincam, screen)  # moved around the mincam (float32 precision far from the origin)
    indices = list(range(len(mincam))) if mixel_indices is None else list(mixel_indices)
    rows, cols = world.screen.shape
    n_tex = rows * cols
    keys = {k: _mixel_key(world.mincam, k, world.screen, sampling, seed) for k in indices} if cache is not None else {}
    weights = np.zeros((len(indices), n_tex))
    variance = np.zeros((len(indices), n_tex))
    todo = _load_cached(cache, keys, indices, weights, variance)
    tracer = _MapTracer(world, sampling, seed)
    texels_per_chunk = max(1, min(n_tex, tracing.MAX_LANES // sampling.samples_per_texel))
    launches = [(out_k, k, start) for out_k, k in todo for start in range(0, n_tex, texels_per_chunk)]
    for out_k, k, start in progress(launches, desc=f"response maps ({sampling.samples_per_texel} samples/texel)",
                                    disable=not show_progress, unit="chunk"):
        count = min(texels_per_chunk, n_tex - start)
        weights[out_k, start : start + count], variance[out_k, start : start + count] = tracer.trace(k, start, count)
        if cache is not None and start + count == n_tex:  # this mixel is complete
            cache.put(keys[k], {"weights_sr": weights[out_k], "variance_sr2": variance[out_k]},
                      {"mixel": world.mincam[k].name, "samples_per_texel": sampling.samples_per_texel})
    meta = _maps_meta(world.mincam, mincam, screen, indices, sampling, seed, keys)
    return ResponseMaps(weights.reshape(len(indices), rows, cols), variance.reshape(len(indices), rows, cols),
                        [world.mincam[k].name for k in indices], meta)


def _load_cached(cache: ContentCache | None, keys: dict, indices: list[int], weights: np.ndarray,
                 variance: np.ndarray) -> list[tuple[int, int]]:
    """Fill the rows of the mixels whose maps ``cache`` holds; return ``(row, mixel)`` of those left to trace."""
    todo = []
    for out_k, k in enumerate(indices):
        entry = cache.get(keys[k]) if cache is not None else None
        if entry is not None and entry.arrays["weights_sr"].shape == weights.shape[1:]:
            weights[out_k], variance[out_k] = entry.arrays["weights_sr"], entry.arrays["variance_sr2"]
        else:
            todo.append((out_k, k))
    return todo


class _MapTracer:
    """Traces chunks of consecutive texels of one mixel's map (the estimator of the module docstring)."""

    def __init__(self, world: MincamScene, sampling: MapSampling, seed: int) -> None:
        self.mi = backend.mitsuba()
        self.mincam, self.screen, self.sampling, self.seed = world.mincam, world.screen, sampling, int(seed)
        self.scene = world.fast_scene  # screen + the mixels' bodies: the visibility rays' scene
        self._evaluators: dict[int, RayWeight] = {}

    def trace(self, k: int, start: int, count: int) -> tuple[np.ndarray, np.ndarray]:
        """Weights and their variances [sr] of texels ``start .. start + count - 1`` for mixel ``k``."""
        import drjit as dr

        texel, s_det, s_screen = self._samples(k, start, count)
        g = self._pair_weight(k, s_det, self._screen_point(texel, s_screen))
        block, replicates = self.sampling.block, self.sampling.replicates
        blocks = np.asarray(dr.block_sum(g, block), dtype=np.float64).reshape(count, replicates) / block
        return blocks.mean(axis=1), blocks.var(axis=1, ddof=1) / replicates

    def _samples(self, k: int, start: int, count: int):
        """Each lane's texel, detector sample and texel sample (unit square), stratified and paired in blocks.

        Every texel draws its own random numbers (those of launch ``texel`` of the mixel's seed,
        :class:`.tracing.LaneSampler`) and its own pairings: a chunk's numbers do not depend on where the chunk
        starts, so the maps do not depend on the lane limit.
        """
        mi = self.mi
        import drjit as dr

        strata, block, spt = self.sampling.strata, self.sampling.block, self.sampling.samples_per_texel
        replicates = self.sampling.replicates
        lane = dr.arange(mi.UInt32, count * spt)
        texel = lane // spt + dr.opaque(mi.UInt32, start)
        sampler = tracing.LaneSampler(derive_seed(self.seed, "response", k), texel, lane % spt)
        j = lane % block  # detector stratum within the block
        jx, jy = j % strata, j // strata
        pi_x, pi_y = _block_permutations(derive_seed(self.seed, "pairing", k), start * replicates,
                                         count * replicates, strata)
        local_block = lane // block
        mx = dr.gather(mi.UInt32, pi_x, local_block * strata + jy)  # texel stratum paired with (jx, jy)
        my = dr.gather(mi.UInt32, pi_y, local_block * strata + jx)
        jitter_det = sampler.next_2d()
        jitter_screen = sampler.next_2d()
        s_det = mi.Point2f((mi.Float(jx) + jitter_det.x) / strata, (mi.Float(jy) + jitter_det.y) / strata)
        s_screen = mi.Point2f((mi.Float(mx) + jitter_screen.x) / strata, (mi.Float(my) + jitter_screen.y) / strata)
        return texel, s_det, s_screen

    def _screen_point(self, texel, s_screen):
        """World point [m] of the texel sample ``s_screen`` in texel ``texel`` (row-major, row 0 at the top)."""
        mi, screen = self.mi, self.screen
        rows, cols = screen.shape
        right, up, _ = (np.asarray(a).tolist() for a in screen.pose.axes())
        center = [float(c) for c in screen.pose.position_m]
        col = mi.Float(texel % cols)
        row = mi.Float(texel // cols)
        xs = ((col + s_screen.x) / cols - 0.5) * screen.width_m
        ys = (0.5 - (row + s_screen.y) / rows) * screen.height_m
        return mi.Point3f(*(center[i] + xs * right[i] + ys * up[i] for i in range(3)))

    def _pair_weight(self, k: int, s_det, p_screen):
        """``T cos_d cos_s / r^2 A_texel`` of each (detector point, screen point) pair, 0 where the mask, the
        housing, a back-facing screen or a mixel's body stops it."""
        mi = self.mi
        import drjit as dr

        mixel = self.mincam[k]
        if k not in self._evaluators:
            self._evaluators[k] = RayWeight(mixel)
        to_world = mixel.pose.matrix()
        rot = mi.Matrix3f(to_world[:3, :3].tolist())
        origin = mi.Point3f(*(float(c) for c in to_world[:3, 3]))
        rot_t = mi.Matrix3f(to_world[:3, :3].T.tolist())
        d_f, det = mixel.d_f_m, mixel.detector_size_m
        normal = [float(c) for c in np.asarray(self.screen.pose.axes()[2])]
        x_d = mi.Vector3f((s_det.x - 0.5) * det, (s_det.y - 0.5) * det, 0.0)
        p_det = origin + rot @ x_d
        delta = p_screen - p_det
        r2 = dr.squared_norm(delta)
        direction = delta * dr.rsqrt(r2)
        d_local = rot_t @ direction
        cos_d = d_local.z
        cos_s = -dr.dot(direction, mi.Vector3f(*normal))
        valid = (cos_d > 0) & (cos_s > 0)
        t_mask = d_f / dr.maximum(cos_d, 1e-12)
        x_m = x_d + d_local * t_mask
        transmission = self._evaluators[k](*local_to_mask_xy(x_m.x, x_m.y), -d_local.x / cos_d, d_local.y / cos_d,
                                           valid)
        valid &= transmission > 0
        p_start = p_det + direction * (t_mask + START_OFFSET_M)
        dist_after = dr.sqrt(r2) - t_mask - START_OFFSET_M
        shadow = mi.Ray3f(p_start, direction, dist_after * (1 - 1e-5), 0.0, [])
        valid &= ~self.scene.ray_test(shadow, valid)
        return dr.select(valid, transmission * cos_d * cos_s / r2 * self.screen.texel_area_m2, 0.0)


def _maps_meta(mincam: Mincam, user_mincam: Mincam, user_screen: Screen, indices: list[int], sampling: MapSampling,
               seed: int, keys: dict) -> dict:
    """What the maps are: estimator, sampling, seed, units, masks, optics, backend, geometry, cache keys."""
    strata = sampling.strata
    meta = {
        "form": "response_map",
        "estimator": "texel_area_sampling_with_visibility_rays",
        "samples_per_texel": sampling.samples_per_texel,
        "replicate_blocks": sampling.replicates,
        "strata_per_block": f"{strata}x{strata}",
        "pairing": "detector stratum (jx, jy) with texel stratum (pi_x(jy), pi_y(jx)), pi random permutations of "
                   "0..k-1 per block",
        "seed": seed,
        "random_numbers": RANDOM_NUMBERS,
        "units": "sr (W/m^2 on the detector per W m^-2 sr^-1 of texel radiance)",
        "masks": {mincam[k].name: mask_model_meta(mincam[k].mask) for k in indices},
        "optics": {mincam[k].name: optics_meta(mincam[k]) for k in indices},
        **backend.describe(),
        **geometry_meta(Mincam(tuple(user_mincam[k] for k in indices), allow_overlap=True), user_screen),
        "mixel_bodies": "occluding" if mincam.occluding_bodies else "ignored (idealised overlapping mincam)",
    }
    if keys:
        meta["cache_keys"] = {mincam[k].name: keys[k] for k in indices}
    return meta


def _block_permutations(seed: int, first_block: int, n_blocks: int, strata: int):
    """Two random permutations of ``0..strata-1`` for each of blocks ``first_block .. first_block + n_blocks - 1``
    of a mixel, flattened (block-major) as Dr.Jit UInt32 arrays.

    Block ``b`` sorts the doubles ``2 b strata .. 2 (b + 1) strata - 1`` of one PCG64 stream seeded ``seed``
    (the stream is advanced to its block): a block's pairing is the same in whichever chunk it is traced.
    """
    mi = backend.mitsuba()
    if strata == 1:
        zeros = mi.UInt32(np.zeros(n_blocks, dtype=np.uint32))
        return zeros, zeros
    bits = np.random.PCG64(seed)
    bits.advance(int(first_block) * 2 * strata)  # one 64-bit draw per double
    perms = np.random.Generator(bits).random((n_blocks, 2, strata)).argsort(axis=-1).astype(np.uint32)
    return mi.UInt32(perms[:, 0].ravel()), mi.UInt32(perms[:, 1].ravel())


def _mixel_key(mincam: Mincam, k: int, screen: Screen, sampling: MapSampling, seed: int) -> str:
    """Content key of one mixel's map: everything its numbers depend on."""
    return fingerprint({"kind": "response_map", "mincam": mincam, "mixel_index": k, "screen": screen,
                        "samples_per_texel": sampling.samples_per_texel, "replicates": sampling.replicates,
                        "seed": int(seed),
                        "random_numbers": RANDOM_NUMBERS, "variant": backend.variant(),
                        "versions": library_versions()})
