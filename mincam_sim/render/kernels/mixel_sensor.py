"""The fast form of a mincam: one Mitsuba sensor that starts every ray on a mixel's mask aperture.

Position sample: ``x`` in [k/n, (k+1)/n) selects mixel ``k`` of ``n`` and its fractional part the detector
point's x; ``y`` is the detector point's y. With ``mi.render`` a film of ``n x 1`` pixels therefore holds one
mixel per pixel; :func:`mixel_position_sample` builds the same samples for :mod:`.tracing`.

Estimator (irradiance averaged over the detector, W/m^2)::

    E = 1/A_d  int_det int_mask T(x_m) L(x_m -> scene) cos(t_d) cos(t_m) / r^2  dA_m dA_d

with ``x_d`` uniform on the detector (from the sub-pixel film position) and ``x_m`` uniform on the mask (from
the aperture sample): ``weight = A_m T(x_m) cos(t_d) cos(t_m) / r^2`` and both cosines equal the local z of the
ray direction (detector and mask are parallel). The integrator then returns the radiance L arriving along the
ray. The mask is applied as a weight, not as a surface, so no ray is wasted on the mask or the housing.
Masks with an analytic profile are evaluated exactly (:mod:`.mask_eval`); a mixel with ``optics = "wave"``
weighs each ray by its wave response for the ray's direction instead of ``T`` (:class:`.mask_eval.RayWeight`).
Rays start on the mask plane (a hair's breadth beyond it, :data:`START_OFFSET_M`, so that they never meet
the body they leave); the other mixels' bodies are part of the scene (:func:`.scene_dicts.mincam_body_shapes`)
and shadow what they hide.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from mincam_sim.model.optics import Mixel
from mincam_sim.render import backend
from mincam_sim.render.kernels.mask_eval import RayWeight, local_to_mask_xy

PLUGIN_NAME = "mincam_mixel_array"
START_OFFSET_M = 1e-6  # [m] rays start this far along their direction past the mask plane (0.05 % of d_f)


class _Mixels:
    """The mixels' poses, sizes and mask weights, held out of sight of ``dr.freeze``: a frozen function walks
    every Dr.Jit value it can reach from its inputs on every call (the scene reaches this sensor), and the poses
    as ``mi.Transform4f`` and the sizes as tuples took ~60 us a call. They are fixed per configuration (the
    sensor's ``version``, which keys every frozen launch, changes with them), so a recording may hold them."""

    __slots__ = ("matrices", "geometry", "masks")

    def __init__(self, matrices=(), geometry=(), masks=()) -> None:
        self.matrices, self.geometry, self.masks = list(matrices), list(geometry), list(masks)


def _make_class():
    mi = backend.mitsuba()
    import drjit as dr

    class MixelArraySensor(mi.Sensor):
        """All mixels of a mincam in one sensor; configure with :meth:`set_mixels` after loading."""

        def __init__(self, props):
            super().__init__(props)
            self.m_needs_sample_3 = True
            self._mixels = _Mixels()
            self.version = 0  # bumped whenever the mixels change: a frozen launch records again

        @property
        def _n(self) -> int:
            return len(self._mixels.geometry)

        def set_mixels(self, mixels: Sequence[Mixel]) -> None:
            mixels = list(mixels)
            self._mixels = _Mixels([mi.Transform4f(m.pose.matrix().tolist()) for m in mixels],
                                   [(m.d_f_m, m.detector_size_m, m.mask.width_m, m.mask.height_m) for m in mixels],
                                   [RayWeight(m) for m in mixels])
            self.version += 1

        def update_pose(self, index: int, matrix: np.ndarray) -> None:
            self._mixels.matrices[index] = mi.Transform4f(np.asarray(matrix).tolist())
            self.version += 1

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            n = self._n
            px = sample2.x * n
            index = dr.clip(mi.UInt32(dr.floor(px)), 0, n - 1)
            frac_x = px - mi.Float(index)
            frac_y = sample2.y

            origin = dr.zeros(mi.Point3f)
            direction = dr.zeros(mi.Vector3f)
            weight = dr.zeros(mi.Float)
            for k in range(n):
                d_f, det, w, h = self._mixels.geometry[k]
                sel = active & (index == k)
                x_d = mi.Point3f((frac_x - 0.5) * det, (frac_y - 0.5) * det, 0.0)
                x_m = mi.Point3f((sample3.x - 0.5) * w, (sample3.y - 0.5) * h, d_f)
                delta = mi.Vector3f(x_m - x_d)
                r2 = dr.squared_norm(delta)
                d_local = delta * dr.rsqrt(r2)
                transmission = self._mixels.masks[k](*local_to_mask_xy(x_m.x, x_m.y), -d_local.x / d_local.z,
                                              d_local.y / d_local.z, sel)
                w_k = (w * h) * transmission * d_local.z * d_local.z / r2
                to_world = self._mixels.matrices[k]
                origin = dr.select(sel, to_world @ mi.Point3f(x_m + d_local * START_OFFSET_M), origin)
                direction = dr.select(sel, dr.normalize(to_world @ d_local), direction)
                weight = dr.select(sel, w_k, weight)
            ray = mi.Ray3f(origin, direction, time, [])
            return ray, mi.Spectrum(weight)

        def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
            ray, weight = self.sample_ray(time, sample1, sample2, sample3, active)
            return mi.RayDifferential3f(ray), weight

        def bbox(self):
            return mi.ScalarBoundingBox3f()

        def to_string(self):
            return f"MixelArraySensor[{self._n} mixels]"

    return MixelArraySensor


_registered = False


def register() -> None:
    """Register the plugin with Mitsuba (once per process, on first use)."""
    global _registered
    if _registered:
        return
    backend.require_jit("The fast mixel sensor (a Python Mitsuba plugin)")
    cls = _make_class()
    backend.mitsuba().register_sensor(PLUGIN_NAME, lambda props: cls(props))
    _registered = True


def mixel_position_sample(n_mixels: int, replicates: int):
    """Position-sample map for :func:`.tracing.trace_groups`: group ``g = k * replicates + r`` -> mixel ``k``."""
    mi = backend.mitsuba()

    def position(group, u):
        k = mi.Float(group // replicates)
        # keep x strictly inside [k/n, (k+1)/n) despite float32 rounding (shrinks the detector by 2e-6)
        return mi.Point2f((k + 0.5 + (u.x - 0.5) * (1 - 2e-6)) / n_mixels, u.y)

    return position


def sensor_dict(n_mixels: int, spp: int = 1) -> dict:
    """Scene-dict entry for the sensor; film = one pixel per mixel, ``spp`` samples per pixel."""
    register()
    return {
        "type": PLUGIN_NAME,
        "sampler": {"type": "independent", "sample_count": int(spp)},
        "film": {
            "type": "hdrfilm",
            "width": int(n_mixels),
            "height": 1,
            "pixel_format": "luminance",
            "rfilter": {"type": "box"},
            "sample_border": False,
        },
    }
