"""The idealised dot-product model of a mixel, beside the physics: its mask stretched over the field it sees, dotted
with the frame (the model of learned-mask simulators such as Klotz & Nayar's ``F.linear(image, M)``), with
options that add the physics one effect at a time. Exact (deterministic quadrature, no Monte Carlo); pure numpy.

The mapping (``docs/ideal_model.md``). A mixel's *image* is what a pinhole camera sees whose pinhole is the
mincam's centre (``parallax=True``: the mixel's own detector centre), whose axes are the mixel's, and whose image
plane is the mask plane ``d_f`` in front of it: each screen texel ``t`` covers a region ``R_t`` of the mask plane
(its central projection, clipped to the aperture). The bare model weighs every point of the mask plane alike::

    W[k, t] = (pi F / A_mask) * int_{R_t} T(x_m) dA_m           [sr]

with ``pi F = 1/d_f^2 int_aperture cos^4(theta) dA_m`` the view factor of the aperture from the detector centre
(closed form), so that an open mask before a uniform screen that fills the field gives the physical irradiance
``pi F L`` of the closed form. ``vignetting=True`` replaces the constant ``pi F / A_mask`` by ``cos^4(theta) / d_f^2``
about the mixel's axis (theta from the pinhole to the mask point): with ``parallax=True`` that is the physical
irradiance at the detector centre, ``int T L cos(theta) d omega``. ``detector_blur=True`` averages the pinhole
over the detector (Gauss-Legendre nodes), and all three together are the physics of a single mixel; the model
never has other mixels' bodies in the way (ignored, as ``meta`` says). A measurement is then ``sum(W * frame)``
in W/m^2 averaged over the detector, as from every solver, with standard error 0.

Quadrature: texels whose image lies inside the aperture are integrated over their image (a quadrilateral: a
central projection keeps lines straight) with ``nodes x nodes`` Gauss-Legendre points; texels cut by the
aperture's edge (or the mask plane) are clipped exactly and integrated on a fan of triangles. Exact for a
transmission that is a polynomial of degree < 2 nodes over a texel's image; a jump of the transmission inside
a texel (a band's edge, the texels of a nearest-neighbour mask) is resolved to within that texel.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from mincam_sim.budget import Budget
from mincam_sim.errors import InputError
from mincam_sim.masks.freeform import transmission_at
from mincam_sim.measurements import Measurements
from mincam_sim.model.optics import Mincam, Mixel
from mincam_sim.progress import progress
from mincam_sim.render.kernels.map_tracing import FRAME_CHUNK_BYTES, ResponseMaps
from mincam_sim.render.kernels.mask_eval import mask_model_meta
from mincam_sim.render.solvers.base import Plan, Row, Solver
from mincam_sim.scene.display import Screen, check_visible

FRAME_CHUNK = 64  # frames per row chunk (at most FRAME_CHUNK_BYTES of frame data)
MAX_NODES = 16


def aperture_view_factor_pi(mixel: Mixel) -> float:
    """``pi F`` [sr]: the view factor of the mixel's aperture (``w x h`` at ``d_f``, centred) from the detector
    centre, times pi (Howell B-3, four corner rectangles); the bare model's total weight for an open mask."""
    x, y = mixel.mask.width_m / (2 * mixel.d_f_m), mixel.mask.height_m / (2 * mixel.d_f_m)
    ax, ay = np.sqrt(1 + x * x), np.sqrt(1 + y * y)
    corner = (x / ax * np.arctan(y / ax) + y / ay * np.arctan(x / ay)) / (2 * np.pi)
    return float(4 * np.pi * corner)


@dataclass(frozen=True)
class DotProduct(Solver):
    """The idealised model: each mixel's mask stretched over the field it sees from the mincam's centre, dotted
    with the frame; exact (no Monte Carlo: standard error 0). Displays only; the budget is not used.

    Parameters
    ----------
    parallax : bool
        Each mixel sees from its own detector centre (the field-of-view offset between mixels), not the mincam's.
    vignetting : bool
        Weigh the mask by ``cos^4`` about the mixel's axis (the physical fall-off) instead of uniformly.
    detector_blur : bool
        Average the pinhole over the detector's area (the blur of a finite detector).
    nodes : int
        Gauss-Legendre points per axis of each texel's image (and of the detector, with ``detector_blur``).
    """

    name: ClassVar[str] = "dot_product"
    budget_reads: ClassVar[tuple[str, ...]] = ()  # exact quadrature: no samples
    scenes: ClassVar[tuple[str, ...]] = ("display",)

    parallax: bool = False
    vignetting: bool = False
    detector_blur: bool = False
    nodes: int = 4

    def __post_init__(self) -> None:
        for key in ("parallax", "vignetting", "detector_blur"):
            if not isinstance(getattr(self, key), bool):
                raise InputError(f"DotProduct {key} must be True or False, got {getattr(self, key)!r}")
        if isinstance(self.nodes, bool) or not isinstance(self.nodes, int) or not 1 <= self.nodes <= MAX_NODES:
            raise InputError(f"DotProduct nodes must be an integer from 1 to {MAX_NODES} (Gauss-Legendre points per "
                             f"axis of a texel), got {self.nodes!r}")

    def effects(self) -> list[str]:
        """The physical effects this model includes (besides the bare mapping)."""
        return [k for k in ("parallax", "vignetting", "detector_blur") if getattr(self, k)]

    def maps(self, mincam: Mincam, screen: Screen, show_progress: bool = False) -> ResponseMaps:
        """Each mixel's weights over the screen's texels [sr] (variance 0), as :class:`ResponseMaps`."""
        for m in mincam:
            if m.optics != "geometric":
                raise InputError(f"mixel {m.name!r} has optics = {m.optics!r}; the dot-product model is geometric: "
                                 "use ResponseMap or Aperture for wave optics")
        check_visible(screen, mincam)  # the set-ups the ray solvers refuse: a mixel behind the screen, in it, blind
        centre = np.asarray(mincam.centre_m, dtype=np.float64)
        rows, cols = screen.shape
        weights = np.zeros((len(mincam), rows, cols))
        for k in progress(range(len(mincam)), desc="dot_product: mixels", disable=not show_progress):
            weights[k] = self._mixel_weights(mincam[k], screen, centre)
        meta = self.meta(mincam, screen)
        return ResponseMaps(weights, np.zeros_like(weights), list(mincam.names), meta)

    def meta(self, mincam: Mincam, screen: Screen) -> dict:
        """What the maps are: the model, its effects, the quadrature, the units, and what it ignores."""
        from mincam_sim.render.scene.mincam_scene import geometry_meta

        return {"form": "dot_product", "solver": self.name,
                "estimator": "deterministic quadrature of the idealised model (no Monte Carlo: standard error 0)",
                "model": "mask stretched over the field seen from the "
                         + ("mixel's own detector centre" if self.parallax else "mincam's centre")
                         + (", cos^4 vignetting about the mixel's axis" if self.vignetting else ", uniform weights")
                         + (", averaged over the detector" if self.detector_blur else ", a pinhole detector"),
                "effects": self.effects(), "exact": True, "nodes": self.nodes,
                "ignored": ["other mixels' bodies"] + ([] if self.parallax else ["field-of-view offset (parallax)"])
                + ([] if self.vignetting else ["cos^4 vignetting"])
                + ([] if self.detector_blur else ["detector size (blur)"]),
                "units": "sr (W/m^2 on the detector per W m^-2 sr^-1 of texel radiance)",
                "masks": {m.name: mask_model_meta(m.mask) for m in mincam},
                **geometry_meta(mincam, screen), "mixel_bodies": "ignored (the idealised model)"}

    def plan(self, sim, frames, budget: Budget, *, background=None, cache=None, show_progress: bool = False) -> Plan:
        return DotProductPlan(self, sim, frames, budget, show_progress)

    # ------------------------------------------------------------------------------------------- geometry
    def _mixel_weights(self, mixel: Mixel, screen: Screen, centre_m: np.ndarray) -> np.ndarray:
        rot = mixel.pose.matrix()[:3, :3]  # columns: local x (viewer's left), y (up), z (forward)
        origin = np.asarray(mixel.pose.position_m, dtype=np.float64) if self.parallax else centre_m
        s = mixel.detector_size_m
        if self.detector_blur:
            x, w = np.polynomial.legendre.leggauss(self.nodes)
            offsets = [(a * s / 2, b * s / 2, wa * wb / 4) for a, wa in zip(x, w, strict=True)
                       for b, wb in zip(x, w, strict=True)]
        else:
            offsets = [(0.0, 0.0, 1.0)]
        scale = None if self.vignetting else aperture_view_factor_pi(mixel) / mixel.mask.area_m2
        total = np.zeros(screen.shape)
        for a, b, weight in offsets:
            pinhole = origin + rot @ np.array([a, b, 0.0])
            total += weight * _pinhole_weights(mixel, screen, pinhole, rot, (a, b), scale, self.nodes)
        return total


class DotProductPlan(Plan):
    """The model's maps, then each chunk of frames a product with them (as :class:`~.response_map.MapPlan`)."""

    def __init__(self, solver: DotProduct, sim, frames, budget: Budget, show_progress: bool) -> None:
        self.solver, self.sim, self.show_progress = solver, sim, show_progress
        self.frames = sim.frame_source(frames)
        self.maps = solver.maps(sim.mincam, sim.screen, show_progress)
        self.n_rows, self.columns = len(self.frames), list(sim.mincam.names)

    def rows(self, pending: np.ndarray) -> Iterator[Row]:
        step = max(1, min(FRAME_CHUNK, self.frames.chunk_size(FRAME_CHUNK_BYTES)))
        batches = [pending[i : i + step] for i in range(0, len(pending), step)]
        for idx in progress(batches, desc="dot_product: frames", disable=not self.show_progress,
                            total=len(batches), unit="chunk"):
            m = self.maps.measure_source(self.frames, idx, show_progress=False)
            yield idx, m.irradiance_w_m2, m.stderr_w_m2

    def result(self, values: np.ndarray, errors: np.ndarray) -> Measurements:
        meta = {**self.maps.meta, "reached_rel_stderr": 0.0}
        m = Measurements(values, errors, list(self.sim.mincam.names), meta)
        m.maps = self.maps
        return m


def _gl01(n: int) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1), 0.5 * w


def _pinhole_weights(mixel: Mixel, screen: Screen, pinhole: np.ndarray, rot: np.ndarray, offset: tuple[float, float],
                     scale: float | None, nodes: int) -> np.ndarray:
    """Weights [sr] of every texel seen from one pinhole (a point on the detector plane, ``offset`` from the mask's
    axis): the integral over the texel's image on the mask plane of ``T * scale`` (bare) or ``T cos^4 / d_f^2``."""
    rows, cols = screen.shape
    right, up, normal = (np.asarray(a, dtype=np.float64) for a in screen.pose.axes())
    centre = np.asarray(screen.pose.position_m, dtype=np.float64)
    if (pinhole - centre) @ normal <= 0:
        return np.zeros((rows, cols))  # behind the emitting side
    d_f, (a, b) = mixel.d_f_m, offset
    hw, hh = mixel.mask.width_m / 2, mixel.mask.height_m / 2

    def to_mask(xs: np.ndarray, ys: np.ndarray):
        """Screen coordinates -> (x_m, y_m) on the mask plane [m], and the depth along the mixel's axis."""
        q = (centre + xs[..., None] * right + ys[..., None] * up - pinhole) @ rot
        depth = q[..., 2]
        safe = np.where(depth > 0, depth, np.inf)
        return -(a + q[..., 0] * d_f / safe), b + q[..., 1] * d_f / safe, depth

    def integrand(x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        t = transmission_at(mixel.mask, x_m, y_m)
        if scale is not None:
            return t * scale
        cos2 = d_f * d_f / ((x_m + a) ** 2 + (y_m - b) ** 2 + d_f * d_f)  # the pinhole is at x_m = -a
        return t * cos2 * cos2 / (d_f * d_f)

    xe = (np.arange(cols + 1) / cols - 0.5) * screen.width_m
    ye = (0.5 - np.arange(rows + 1) / rows) * screen.height_m
    gx, gy = np.meshgrid(xe, ye)
    mx, my, depth = to_mask(gx, gy)
    corners = [(slice(0, -1), slice(0, -1)), (slice(0, -1), slice(1, None)), (slice(1, None), slice(1, None)),
               (slice(1, None), slice(0, -1))]  # per texel: top-left, top-right, bottom-right, bottom-left
    cx = np.stack([mx[c] for c in corners], axis=-1)
    cy = np.stack([my[c] for c in corners], axis=-1)
    cz = np.stack([depth[c] for c in corners], axis=-1)
    beyond = (cz > d_f).all(axis=-1)
    inside = beyond & (np.abs(cx) <= hw).all(axis=-1) & (np.abs(cy) <= hh).all(axis=-1)
    away = ((cx > hw).all(axis=-1) | (cx < -hw).all(axis=-1) | (cy > hh).all(axis=-1) | (cy < -hh).all(axis=-1))
    out = np.zeros((rows, cols))
    out[inside] = _quads(cx[inside], cy[inside], integrand, nodes)
    cut = ~inside & ~(beyond & away) & (cz > d_f).any(axis=-1)
    if cut.any():
        out[cut] = _clipped(np.argwhere(cut), xe, ye, to_mask, (right, up, centre, pinhole, rot, d_f), (hw, hh),
                            integrand, nodes)
    return out


def _quads(cx: np.ndarray, cy: np.ndarray, integrand, nodes: int) -> np.ndarray:
    """Integrals of ``integrand`` over quadrilaterals (corners (n, 4) in order), by the bilinear map of the unit
    square and ``nodes x nodes`` Gauss-Legendre points."""
    u, wu = _gl01(nodes)
    uu, vv = (g.ravel() for g in np.meshgrid(u, u, indexing="ij"))
    ww = np.outer(wu, wu).ravel()
    # P(u, v) = (1-u)(1-v) p0 + u(1-v) p1 + u v p2 + (1-u) v p3 (p0 top-left, p1 top-right, p2 bottom-right)
    basis = np.stack([(1 - uu) * (1 - vv), uu * (1 - vv), uu * vv, (1 - uu) * vv], axis=0)  # (4, m)
    du = np.stack([-(1 - vv), 1 - vv, vv, -vv], axis=0)
    dv = np.stack([-(1 - uu), -uu, uu, 1 - uu], axis=0)
    px, py = cx @ basis, cy @ basis
    jac = np.abs((cx @ du) * (cy @ dv) - (cx @ dv) * (cy @ du))
    return (integrand(px, py) * jac) @ ww


def _clipped(texels: np.ndarray, xe: np.ndarray, ye: np.ndarray, to_mask, frame, half: tuple[float, float],
             integrand, nodes: int) -> np.ndarray:
    """Integrals over the images of texels cut by the mask plane or the aperture's edge: each texel clipped to the
    part beyond the mask plane (on the screen), projected, clipped to the aperture, split into a fan of triangles
    integrated by a collapsed ``nodes x nodes`` Gauss-Legendre rule (all texels at once)."""
    right, up, centre, pinhole, rot, d_f = frame
    hw, hh = half
    axis = rot[:, 2]
    i, j = texels[:, 0], texels[:, 1]
    polys = np.stack([np.stack([xe[j], ye[i]], -1), np.stack([xe[j + 1], ye[i]], -1),
                      np.stack([xe[j + 1], ye[i + 1]], -1), np.stack([xe[j], ye[i + 1]], -1)], axis=1)
    count = np.full(len(texels), 4)
    polys, count = _clip_halfplanes(polys, count, np.array([right @ axis, up @ axis]),
                                    float((centre - pinhole) @ axis - d_f))
    x_m, y_m, _ = to_mask(polys[..., 0], polys[..., 1])
    img = np.stack([np.where(np.isfinite(x_m), x_m, 0.0), np.where(np.isfinite(y_m), y_m, 0.0)], axis=-1)
    for normal, offset in ((np.array([1.0, 0.0]), hw), (np.array([-1.0, 0.0]), hw), (np.array([0.0, 1.0]), hh),
                           (np.array([0.0, -1.0]), hh)):
        img, count = _clip_halfplanes(img, count, normal, offset)
    if img.shape[1] < 3:
        return np.zeros(len(texels))
    u, wu = _gl01(nodes)
    su, sv = (g.ravel() for g in np.meshgrid(u, u, indexing="ij"))
    sw = np.outer(wu, wu).ravel() * su  # collapsed square -> triangle: Jacobian s
    p0 = img[:, :1]  # fan (0, k, k + 1), k = 1 .. count - 2
    p1, p2 = img[:, 1:-1], img[:, 2:]
    live = np.arange(1, img.shape[1] - 1)[None, :] <= count[:, None] - 2
    area2 = np.abs((p1[..., 0] - p0[..., 0]) * (p2[..., 1] - p0[..., 1])
                   - (p1[..., 1] - p0[..., 1]) * (p2[..., 0] - p0[..., 0])) * live
    tx = p0[..., 0, None] + su * (p1[..., 0, None] - p0[..., 0, None]) + su * sv * (p2[..., 0, None] - p1[..., 0, None])
    ty = p0[..., 1, None] + su * (p1[..., 1, None] - p0[..., 1, None]) + su * sv * (p2[..., 1, None] - p1[..., 1, None])
    values = integrand(tx, ty) * area2[..., None] * sw
    return values.sum(axis=(1, 2))


def _clip_halfplanes(polys: np.ndarray, count: np.ndarray, normal: np.ndarray, offset: float):
    """Sutherland-Hodgman for many convex polygons at once: the part of each polygon (``polys`` (n, v, 2), the first
    ``count`` vertices valid) where ``normal . p + offset >= 0``; returns the clipped polygons, padded, and counts."""
    n, v = polys.shape[:2]
    idx = np.arange(v)[None, :]
    valid = idx < count[:, None]
    nxt = np.where(idx + 1 < count[:, None], idx + 1, 0)
    q = np.take_along_axis(polys, nxt[..., None], axis=1)
    side_p, side_q = polys @ normal + offset, q @ normal + offset
    keep = valid & (side_p >= 0)
    cross = valid & ((side_p >= 0) != (side_q >= 0))
    t = np.where(cross, side_p / np.where(cross, side_p - side_q, 1.0), 0.0)
    hit = polys + t[..., None] * (q - polys)
    cand = np.stack([polys, hit], axis=2).reshape(n, 2 * v, 2)  # per edge: its start, then its crossing
    flags = np.stack([keep, cross], axis=2).reshape(n, 2 * v)
    order = np.argsort(~flags, axis=1, kind="stable")
    new_count = flags.sum(axis=1)
    width = max(int(new_count.max(initial=0)), 1)
    clipped = np.take_along_axis(cand, order[:, :width, None], axis=1)
    return np.where((np.arange(width)[None, :] < new_count[:, None])[..., None], clipped, 0.0), new_count


__all__ = ["DotProduct", "DotProductPlan", "aperture_view_factor_pi"]
