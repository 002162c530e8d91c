"""Differentiable mixel measurements of objects on a plane, with Dr.Jit's automatic differentiation.

The only module of the package that uses Dr.Jit AD. Scenes are uniform-radiance squares ("objects") on a
plane at ``depth_m`` in front of the mincam, facing it (the display of the display solvers, one object per
frame). The estimator is the response map's (:mod:`.response_map`): for frame ``f`` with a square ``S_f`` of
radiance ``L_f`` and area ``A_f``, and mixel ``k``::

    E_kf = 1/A_d int_det int_S_f T_k(x_m) L_f cos(t_d) cos(t_s) / r^2 dA_s dA_d
         ~ mean_i  A_f L_f T_k(x_m,i) cos(t_d,i) cos(t_s,i) / r_i^2          [W/m^2]

with ``x_d`` uniform on the detector, ``x_s`` stratified-uniform on the square, and ``x_m`` where the segment
``x_d -> x_s`` crosses the mask plane at ``d_f``; outside the aperture the housing blocks it, and a visibility
ray in Mitsuba's scene of the mincam's bodies tests the rest of the way (:func:`.scene_dicts.mincam_body_shapes`).
Random numbers come from a seeded NumPy generator, so the same seed gives the same samples: a central finite
difference of :func:`irradiance` then differs from its AD derivative only by curvature and rounding (the test
harness of Mitsuba's ``test_ad_integrators``).

Parameters that carry gradients:

* mask texels (``texels``: a flat ``mi.Float`` of ``H * W`` transmissions, bilinear or nearest lookup),
* ``d_f`` (``mi.Float``, one lane) and the mixel's position (``mi.Point3f``, world metres).

The aperture edge and visibility are not differentiated (no boundary terms): derivatives with respect to
``d_f`` and the position are exact only when no sample crosses the aperture edge for a small change, i.e. for
objects well inside the field of view (:func:`check_inside_fov` says which).

For mask design, measurements are linear in the mask: :func:`design_matrix` bins the same samples by printer
dot (``nearest``) so that ``E_k = A_k @ T_k``; the design floor (:mod:`mincam_sim.design.optimiser`) then
optimises texel logits, a decoder and the film's tone mapping through that linear model with ``mi.ad.Adam``
(its Dr.Jit operations from :mod:`.autodiff`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mincam_sim.model.optics import Mincam, Mixel
from mincam_sim.render import backend
from mincam_sim.render.gradients.autodiff import single_threaded
from mincam_sim.render.kernels.mask_eval import local_to_mask_xy
from mincam_sim.render.kernels.mixel_sensor import START_OFFSET_M


@dataclass(frozen=True)
class SquareScenes:
    """Uniform squares on a plane facing the mincam, one per frame.

    Attributes
    ----------
    depth_m : float
        Distance of the plane from the mincam's detectors along -z [m] (the plane is ``z = -depth_m``).
    centers_m : (n, 2) ndarray
        Square centres in plane coordinates (x right, y up, as the screen's) [m].
    sizes_m : (n,) ndarray
        Square sides [m].
    radiance : (n,) ndarray
        Square radiance [W m^-2 sr^-1]; the rest of the plane is black.
    heights_m : (n,) ndarray, optional
        Heights [m] of rectangles of width ``sizes_m`` (default: squares).
    """

    depth_m: float
    centers_m: np.ndarray
    sizes_m: np.ndarray
    radiance: np.ndarray
    heights_m: np.ndarray | None = None

    def __post_init__(self) -> None:
        c = np.asarray(self.centers_m, dtype=np.float64).reshape(-1, 2)
        n = len(c)
        s = np.broadcast_to(np.asarray(self.sizes_m, dtype=np.float64), (n,)).copy()
        r = np.broadcast_to(np.asarray(self.radiance, dtype=np.float64), (n,)).copy()
        if not (np.isfinite(self.depth_m) and self.depth_m > 0):
            raise ValueError(f"SquareScenes.depth_m must be > 0 metres, got {self.depth_m!r}")
        if np.any(~np.isfinite(s)) or np.any(s <= 0):
            raise ValueError("SquareScenes.sizes_m must be positive sides in metres")
        if np.any(~np.isfinite(r)) or np.any(r < 0):
            raise ValueError("SquareScenes.radiance must be finite and >= 0 W m^-2 sr^-1")
        h = s.copy() if self.heights_m is None else np.broadcast_to(
            np.asarray(self.heights_m, dtype=np.float64), (n,)).copy()
        if np.any(~np.isfinite(h)) or np.any(h <= 0):
            raise ValueError("SquareScenes.heights_m must be positive heights in metres")
        object.__setattr__(self, "heights_m", h)
        object.__setattr__(self, "centers_m", c)
        object.__setattr__(self, "sizes_m", s)
        object.__setattr__(self, "radiance", r)

    def __len__(self) -> int:
        return len(self.centers_m)


@dataclass
class Samples:
    """Per-sample quantities of one mixel for a set of frames (Dr.Jit arrays, ``n_frames * per_frame`` lanes).

    ``u, v``: mask texture coordinates (0..1 inside the aperture, :mod:`.mask_eval` convention);
    ``weight``: ``A_f L_f cos cos / r^2`` with visibility and the aperture applied [W m^-2 per unit
    transmission]; both are attached to ``d_f`` and the position when those carry gradients.
    """

    u: object
    v: object
    weight: object
    n_frames: int
    per_frame: int


def _mi():
    backend.require_jit("Differentiable mixel measurements (Dr.Jit AD)")
    return backend.mitsuba()


def bodies_scene(mincam: Mincam):
    """Mitsuba scene of the mincam's bodies (housings and back plates) for the visibility rays."""
    from mincam_sim.render.scene.scene_dicts import mincam_body_shapes

    mi = _mi()
    return mi.load_dict({"type": "scene", **mincam_body_shapes(mincam)}, optimize=False)


def _random(seed: int, n: int, k: int) -> np.ndarray:
    return np.random.default_rng([int(seed), int(k), 0x5EED]).random((4, n))


def mixel_samples(
    mincam: Mincam,
    k: int,
    scenes: SquareScenes,
    strata: int = 16,
    seed: int = 0,
    d_f=None,
    position=None,
    bodies=None,
) -> Samples:
    """Trace the samples of mixel ``k`` for every frame of ``scenes`` (see the module docstring).

    Parameters
    ----------
    mincam : Mincam
        Its mixels' poses, geometry and bodies; mixel ``k`` must look along -z at the plane.
    k : int
        Mixel index.
    scenes : SquareScenes
        One square per frame.
    strata : int
        The square is sampled on ``strata x strata`` jittered strata (one detector point per sample).
    seed : int
        Seed of the sample positions (same seed, same samples, whatever the parameters).
    d_f, position : Dr.Jit arrays, optional
        ``mi.Float`` mask distance [m] and ``mi.Point3f`` detector centre [m] (world) to differentiate with
        respect to; default: the mixel's own values, without gradients.
    bodies : Mitsuba scene, optional
        The mincam's bodies for the visibility rays (built once by the caller for speed).
    """
    mi = _mi()
    import drjit as dr

    mixel: Mixel = mincam[k]
    n_f, per = len(scenes), int(strata) ** 2
    n = n_f * per
    rnd = _random(seed, n, k)
    lane = np.arange(n)
    j = lane % per
    frame = lane // per
    sx = (j % strata + rnd[0]) / strata - 0.5
    sy = (j // strata + rnd[1]) / strata - 0.5
    xs = scenes.centers_m[frame, 0] + sx * scenes.sizes_m[frame]
    ys = scenes.centers_m[frame, 1] + sy * scenes.heights_m[frame]
    scale = (scenes.sizes_m * scenes.heights_m * scenes.radiance)[frame]  # A_f L_f
    det = mixel.detector_size_m
    xd_local = (rnd[2] - 0.5) * det
    yd_local = (rnd[3] - 0.5) * det

    m = mixel.pose.matrix()
    if np.abs(m[:3, 2] - (0.0, 0.0, -1.0)).max() > 1e-9:
        raise ValueError(f"mixel {mixel.name!r} must look along -z (forward (0, 0, -1)) for plane scenes")
    rot = mi.Matrix3f(m[:3, :3].tolist())
    rot_t = mi.Matrix3f(m[:3, :3].T.tolist())
    origin = position if position is not None else mi.Point3f(*(float(c) for c in m[:3, 3]))
    dist_f = d_f if d_f is not None else mi.Float(mixel.d_f_m)

    p_det = origin + rot @ mi.Vector3f(mi.Float(xd_local), mi.Float(yd_local), 0.0)
    p_scr = mi.Point3f(mi.Float(xs), mi.Float(ys), mi.Float(np.full(n, -scenes.depth_m)))
    delta = p_scr - p_det
    r2 = dr.squared_norm(delta)
    direction = delta * dr.rsqrt(r2)
    d_local = rot_t @ direction
    cos_d = d_local.z
    cos_s = -direction.z  # the plane faces the mincam: its normal is +z, the ray runs along -z
    valid = (cos_d > 0) & (cos_s > 0)
    t_mask = dist_f / dr.maximum(cos_d, 1e-12)
    x_m = mi.Vector3f(mi.Float(xd_local), mi.Float(yd_local), 0.0) + d_local * t_mask
    mx, my = local_to_mask_xy(x_m.x, x_m.y)
    u = 0.5 + mx / mixel.mask.width_m
    v = 0.5 - my / mixel.mask.height_m
    valid &= (u >= 0) & (u <= 1) & (v >= 0) & (v <= 1)  # the housing blocks the rest
    if bodies is None:
        bodies = bodies_scene(mincam)
    p_start = dr.detach(p_det + direction * (t_mask + START_OFFSET_M))
    dist_after = dr.detach(dr.sqrt(r2) - t_mask - START_OFFSET_M)
    shadow = mi.Ray3f(p_start, dr.detach(direction), dist_after * (1 - 1e-5), 0.0, [])
    valid &= ~bodies.ray_test(shadow, dr.detach(valid))
    weight = dr.select(valid, mi.Float(scale) * cos_d * cos_s / r2, 0.0)
    return Samples(u, v, weight, n_f, per)


def lookup(texels, shape: tuple[int, int], u, v, interpolation: str = "bilinear"):
    """Transmission of a flat texel array (row 0 at the top) at texture coordinates ``(u, v)``.

    ``bilinear``: between texel centres, clamped at the border (as Mitsuba's ``bitmap`` with ``clamp``);
    ``nearest``: the texel containing the point (printer dots). Differentiable in the texels and in u, v.
    """
    mi = _mi()
    import drjit as dr

    h, w = shape
    if interpolation == "nearest":
        col = dr.clip(mi.Int32(dr.floor(u * w)), 0, w - 1)
        row = dr.clip(mi.Int32(dr.floor(v * h)), 0, h - 1)
        return dr.gather(mi.Float, texels, mi.UInt32(row * w + col))
    if interpolation != "bilinear":
        raise ValueError(f"interpolation must be 'bilinear' or 'nearest', got {interpolation!r}")
    x = u * w - 0.5
    y = v * h - 0.5
    x0 = dr.floor(dr.detach(x))
    y0 = dr.floor(dr.detach(y))
    fx, fy = x - x0, y - y0
    c0 = dr.clip(mi.Int32(x0), 0, w - 1)
    c1 = dr.clip(mi.Int32(x0) + 1, 0, w - 1)
    r0 = dr.clip(mi.Int32(y0), 0, h - 1)
    r1 = dr.clip(mi.Int32(y0) + 1, 0, h - 1)

    def at(r, c):
        return dr.gather(mi.Float, texels, mi.UInt32(r * w + c))

    return ((1 - fx) * (1 - fy) * at(r0, c0) + fx * (1 - fy) * at(r0, c1)
            + (1 - fx) * fy * at(r1, c0) + fx * fy * at(r1, c1))


def irradiance(samples: Samples, texels, shape: tuple[int, int], interpolation: str = "bilinear"):
    """Mean irradiance on the detector per frame (``mi.Float``, n_frames lanes) [W/m^2], differentiable."""
    import drjit as dr

    t = lookup(texels, shape, samples.u, samples.v, interpolation)
    return dr.block_sum(samples.weight * t, samples.per_frame) / samples.per_frame


def design_matrix(samples: Samples, dot_shape: tuple[int, int]) -> np.ndarray:
    """Linear model of a nearest-texel mask: ``E = A @ T`` with ``A`` of shape (n_frames, H * W) [W/m^2].

    Row ``f`` holds, for each printer dot, the irradiance it passes when fully transparent.
    """
    import drjit as dr

    h, w = dot_shape
    u = np.asarray(dr.detach(samples.u), dtype=np.float64)
    v = np.asarray(dr.detach(samples.v), dtype=np.float64)
    g = np.asarray(dr.detach(samples.weight), dtype=np.float64)
    col = np.clip(np.floor(u * w).astype(np.int64), 0, w - 1)
    row = np.clip(np.floor(v * h).astype(np.int64), 0, h - 1)
    frame = np.arange(len(g)) // samples.per_frame
    flat = frame * (h * w) + row * w + col
    a = np.bincount(flat, weights=g, minlength=samples.n_frames * h * w) / samples.per_frame
    return a.reshape(samples.n_frames, h * w)


def check_inside_fov(mincam: Mincam, scenes: SquareScenes, margin: float = 0.02) -> np.ndarray:
    """True per frame when, for every mixel, the square's image through every detector point stays inside the
    aperture by ``margin`` of its width (so derivatives in ``d_f`` and the position have no edge term)."""
    ok = np.ones(len(scenes), dtype=bool)
    for mixel in mincam:
        tan_x, tan_y = mixel.half_fov_tan()
        pos = np.asarray(mixel.pose.position_m)
        d = scenes.depth_m + pos[2]
        for axis, tan in ((0, tan_x), (1, tan_y)):
            half = (scenes.sizes_m if axis == 0 else scenes.heights_m) / 2
            reach = np.abs(scenes.centers_m[:, axis] - pos[axis]) + half
            ok &= reach / d < tan * (1 - 2 * margin) - mixel.detector_size_m / (2 * mixel.d_f_m)
    return ok


# ----------------------------------------------------------------------------------------------------------
# Gradient checks (forward-mode AD against central differences with the same samples)


class GradientProbe:
    """Irradiances of mixel ``k`` for ``scenes`` as a function of its (bilinear) mask texels, ``d_f`` and its
    position, with the samples fixed by ``seed``: the values, forward-mode derivatives and central differences.
    """

    def __init__(self, mincam: Mincam, k: int, scenes: SquareScenes, texels: np.ndarray, strata: int = 48,
                 seed: int = 0) -> None:
        self.mincam, self.k, self.scenes, self.strata, self.seed = mincam, k, scenes, strata, seed
        self.texels = np.asarray(texels, dtype=np.float64)
        self.d_f_m = float(mincam[k].d_f_m)
        self.position_m = np.asarray(mincam[k].pose.position_m, dtype=np.float64)
        self._bodies = bodies_scene(mincam)

    def _measure(self, texels, d_f, position):
        smp = mixel_samples(self.mincam, self.k, self.scenes, strata=self.strata, seed=self.seed, d_f=d_f,
                            position=position, bodies=self._bodies)
        return irradiance(smp, texels, self.texels.shape)

    def _inputs(self, texels=None, d_f=None, position=None):
        mi = _mi()
        t = self.texels.ravel() if texels is None else texels
        p = self.position_m if position is None else position
        return (mi.Float(np.asarray(t, dtype=np.float32)), mi.Float(self.d_f_m if d_f is None else d_f),
                mi.Point3f(*(float(c) for c in p)))

    def values(self, texels=None, d_f=None, position=None) -> np.ndarray:
        """Irradiance per frame [W/m^2] (float64 copy of the float32 estimate)."""
        return np.asarray(self._measure(*self._inputs(texels, d_f, position)), dtype=np.float64)

    def influence(self) -> np.ndarray:
        """Reverse-mode derivative of the summed irradiance with respect to every texel (H*W,)."""
        import drjit as dr

        texels, d_f, position = self._inputs()
        dr.enable_grad(texels)
        with single_threaded():  # the reverse pass scatter-adds: fixed order
            dr.backward(dr.sum(self._measure(texels, d_f, position)))
            return np.asarray(dr.grad(texels), dtype=np.float64)

    def forward(self, parameter: str, index: int = 0) -> np.ndarray:
        """Forward-mode derivative per frame with respect to ``texel`` [index], ``d_f_m`` or ``position_m``
        [axis index] [W/m^2 per unit, per m, per m]."""
        mi = _mi()
        import drjit as dr

        texels, d_f, position = self._inputs()
        if parameter == "texel":
            dr.enable_grad(texels)
            e = self._measure(texels, d_f, position)
            tangent = np.zeros(self.texels.size, dtype=np.float32)
            tangent[index] = 1.0
            dr.set_grad(texels, mi.Float(tangent))
        elif parameter == "d_f_m":
            dr.enable_grad(d_f)
            e = self._measure(texels, d_f, position)
            dr.set_grad(d_f, 1.0)
        elif parameter == "position_m":
            dr.enable_grad(position)
            e = self._measure(texels, d_f, position)
            unit = [0.0, 0.0, 0.0]
            unit[index] = 1.0
            dr.set_grad(position, mi.Vector3f(*unit))
        else:
            raise ValueError(f"parameter must be 'texel', 'd_f_m' or 'position_m', got {parameter!r}")
        dr.forward_to(e)
        return np.asarray(dr.grad(e), dtype=np.float64)

    def central_difference(self, parameter: str, index: int, step: float) -> np.ndarray:
        """``(E(p + h) - E(p - h)) / 2h`` with the same samples."""
        if parameter == "texel":
            plus, minus = self.texels.ravel().copy(), self.texels.ravel().copy()
            plus[index] += step
            minus[index] -= step
            return (self.values(texels=plus) - self.values(texels=minus)) / (2 * step)
        if parameter == "d_f_m":
            return (self.values(d_f=self.d_f_m + step) - self.values(d_f=self.d_f_m - step)) / (2 * step)
        plus, minus = self.position_m.copy(), self.position_m.copy()
        plus[index] += step
        minus[index] -= step
        return (self.values(position=plus) - self.values(position=minus)) / (2 * step)


__all__ = [
    "GradientProbe",
    "Samples",
    "SquareScenes",
    "bodies_scene",
    "check_inside_fov",
    "design_matrix",
    "irradiance",
    "lookup",
    "mixel_samples",
    "single_threaded",
]
