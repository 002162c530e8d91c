"""Monte Carlo estimates straight from a sensor and the scene's integrator, accumulated in float64.

``mi.render`` pours samples into a float32 film with parallel atomic adds: the order (and so the last bits)
changes from run to run, and millions of samples in one pixel drift by ~1e-4. Here every lane's
``weight x L`` comes back as an array and is summed in float64 in a fixed order, so the same seed gives the
same numbers and no film precision is involved.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from mincam_sim.render import backend

MAX_LANES = 1 << 22  # lanes (rays, samples) per kernel launch: the one limit of every launch loop of the package


def launch_seed(seed: int, launch: int) -> int:
    """The sampler seed of kernel launch ``launch`` of a run seeded ``seed`` (the one rule every launch loop of
    the fast forms uses: same seed and launch, same random numbers)."""
    return (int(seed) * 1_000_003 + int(launch)) & 0x7FFFFFFF


def seeded_sampler(seed: int, launch: int, lanes: int):
    """An independent sampler seeded for ``launch`` with ``lanes`` lanes."""
    sampler = backend.mitsuba().load_dict({"type": "independent"})
    sampler.seed(launch_seed(seed, launch), int(lanes))
    return sampler


def launch_seeds(seed: int, launches):
    """:func:`launch_seed` lane by lane, for a Dr.Jit ``UInt32`` array of launch indices (the same arithmetic
    modulo 2^31)."""
    mi = backend.mitsuba()
    import drjit as dr

    return (dr.opaque(mi.UInt32, (int(seed) * 1_000_003) & 0xFFFFFFFF) + launches) & 0x7FFFFFFF


class LaneSampler:
    """Mitsuba's ``independent`` sampler lane by lane: the lane of ``index`` in launch ``launch`` (``UInt32``
    arrays, one entry per lane) draws exactly what lane ``index`` of ``seeded_sampler(seed, launch, lanes)``
    draws (the TEA-scrambled PCG32 stream Mitsuba gives that lane). Unmasked: every lane advances on every draw.

    So a loop that gives every *group* of samples (a texel, a replicate) a launch index of its own draws the
    same numbers however many groups a kernel launch packs (up to :data:`MAX_LANES`), and any subset of a
    launch's lanes can be traced again alone (:meth:`for_launch`).
    """

    def __init__(self, seed: int, launch, index) -> None:
        self._seed(launch_seeds(seed, launch), index)

    @classmethod
    def for_launch(cls, launch_seed_u32, index) -> LaneSampler:
        """The lanes ``index`` (a ``UInt32`` array) of one launch whose seed (:func:`launch_seed`) is given as a
        Dr.Jit ``UInt32`` (opaque in a frozen launch)."""
        sampler = cls.__new__(cls)
        sampler._seed(launch_seed_u32, index)
        return sampler

    def _seed(self, launch_seed_u32, index) -> None:
        mi = backend.mitsuba()
        v0, v1 = mi.sample_tea_32(launch_seed_u32, index)
        self._point = mi.Point2f
        self._rng = mi.PCG32()
        self._rng.seed(mi.UInt64(v0), mi.UInt64(v1))  # as the independent sampler seeds its lane ``index``

    def next_1d(self, active=True):
        """One uniform number in [0, 1) per lane."""
        return self._rng.next_float32()

    def next_2d(self, active=True):
        """A uniform point of [0, 1)^2 per lane (x drawn first, as the independent sampler's ``next_2d``)."""
        x = self._rng.next_float32()
        y = self._rng.next_float32()
        return self._point(x, y)


def trace_groups(
    scene,
    sensor,
    n_groups: int,
    samples_per_group: int,
    seed: int,
    position_sample: Callable | None = None,
) -> np.ndarray:
    """Mean of ``weight x L`` over ``samples_per_group`` rays for each of ``n_groups`` groups.

    Parameters
    ----------
    scene : mi.Scene
        Scene whose integrator (``path``) computes the radiance L along each ray.
    sensor : mi.Sensor
        Generates rays and their weights from (position, aperture) samples in [0, 1]^2.
    position_sample : callable, optional
        ``f(group_index: mi.UInt32, u: mi.Point2f) -> mi.Point2f`` maps a uniform sample to the sensor's
        position sample for a group (e.g. to pick a mixel); default: ``u`` itself.
    seed : int
        Seed of the independent sampler; each kernel launch derives its own.
    """
    mi = backend.mitsuba()
    if not backend.is_jit():
        return _render_groups_scalar(mi, scene, sensor, n_groups, samples_per_group, seed, position_sample)
    integrator = scene.integrator()
    totals = np.zeros(n_groups, dtype=np.float64)
    for launch in sensor_launches(sensor, n_groups, samples_per_group, seed, position_sample):
        radiance, _, _ = integrator.sample(scene, launch.sampler, launch.ray, None, True)
        totals[launch.groups] += lane_sums(launch.weight * radiance, launch.samples)
    return totals / samples_per_group


@dataclass
class SensorLaunch:
    """One kernel launch of :func:`sensor_launches`: ``samples`` lanes for each group of ``groups``, lane ``i``
    in group ``groups.start + i // samples``; the sampler has drawn the ray's samples and goes on to the
    integrator."""

    groups: slice
    samples: int
    sampler: object
    ray: object
    weight: object


def sensor_launches(sensor, n_groups: int, samples_per_group: int, seed: int,
                    position_sample: Callable | None = None) -> Iterator[SensorLaunch]:
    """The launches of :func:`trace_groups`: at most :data:`MAX_LANES` lanes each, seeded by
    :func:`launch_seed`, with the sensor's rays drawn (position, aperture, wavelength samples, in that order).
    Everything that traces the same seed as :func:`trace_groups` goes through here, so that it draws the same
    rays and the same random numbers after them."""
    mi = backend.mitsuba()
    import drjit as dr

    groups_per_launch = max(1, MAX_LANES // samples_per_group)
    per_launch = min(samples_per_group, MAX_LANES)
    launch = 0
    for g0 in range(0, n_groups, groups_per_launch):
        ng = min(groups_per_launch, n_groups - g0)
        for s0 in range(0, samples_per_group, per_launch):
            ns = min(per_launch, samples_per_group - s0)
            sampler = seeded_sampler(seed, launch, ng * ns)
            launch += 1
            group = dr.arange(mi.UInt32, ng * ns) // ns + g0
            u = sampler.next_2d()
            if position_sample is not None:
                u = position_sample(group, u)
            aperture = sampler.next_2d()
            wavelength = sampler.next_1d()
            ray, weight = sensor.sample_ray_differential(0.0, wavelength, u, aperture)
            yield SensorLaunch(slice(g0, g0 + ng), ns, sampler, ray, weight)


def lane_sums(values, samples: int) -> np.ndarray:
    """Sums of a launch's lane values (a Dr.Jit spectrum per lane) over each run of ``samples`` lanes, in float64
    and a fixed order; RGB variants (gray scenes) average the channels first."""
    value = np.asarray(values, dtype=np.float64).reshape(-1)
    import drjit as dr

    lanes = int(dr.width(values))
    if value.size != lanes:
        value = value.reshape(lanes, -1).mean(axis=1)
    return value.reshape(-1, samples).sum(axis=1)


def _render_groups_scalar(mi, scene, sensor, n_groups, samples_per_group, seed, position_sample) -> np.ndarray:
    """Scalar variants trace one ray at a time in C++: use ``mi.render`` (1 x 1 film, one render per group)."""
    if position_sample is not None:
        backend.require_jit("Tracing groups with a position-sample map (the fast mixel sensor)")
    out = np.empty(n_groups)
    for g in range(n_groups):
        image = mi.render(scene, sensor=sensor, spp=int(samples_per_group), seed=launch_seed(seed, g))
        out[g] = float(np.asarray(image, dtype=np.float64).mean())
    return out
