"""The idealised dot-product model of a mixel, beside the physics: its mask stretched over the field it sees, dotted
with the frame (the model of learned-mask simulators such as Klotz & Nayar's ``F.linear(image, M)``), with
options that add the physics one effect at a time. Deterministic quadrature (no Monte Carlo) with an error
estimate; pure numpy.

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
in W/m^2 averaged over the detector, as from every solver, with the quadrature's error estimate as its error.

Quadrature: texels whose image lies inside the aperture are integrated over their image (a quadrilateral: a
central projection keeps lines straight) with ``nodes x nodes`` Gauss-Legendre points; texels cut by the
aperture's edge (or the mask plane) are clipped exactly and integrated on a fan of triangles. A raster mask's
interpolation kinks (bilinear: at the lines through its texels' centres) or jumps (nearest: at its texels'
edges), so each image that such a line crosses is cut along them into pieces on which the mask is bilinear or
constant, each integrated on its fan (:func:`raster_lines`): the bare model of a raster mask is then exact to
rounding (the tests check it against closed-form overlaps of every image with every mask texel). The detector is
split into ``detector_cells x detector_cells`` squares of ``nodes x nodes`` Gauss-Legendre points (the pinhole's
measurement has a kink wherever a texel's edge crosses the field's edge: a single high-order rule converges
slowly there, a composite one faster). Neither rule is exact for every mask and frame, so every measurement
carries an *error estimate* in its ``stderr_w_m2`` (deterministic, not a Monte Carlo standard error): the larger
of ``|P - P'|`` for two other detector rules (half and one fewer points per cell) plus twice ``|P_c' - P_c|`` at
the detector's centre for the texels' images split twice as finely (without ``detector_blur`` the finer rule is
the value). An estimate, not a bound (``docs/ideal_model.md`` says how it held on random set-ups).
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
from mincam_sim.render.kernels.monte_carlo import worst_relative_stderr
from mincam_sim.render.solvers.base import Plan, Row, Solver
from mincam_sim.scene.display import Screen, check_visible

FRAME_CHUNK = 64  # frames per row chunk (at most FRAME_CHUNK_BYTES of frame data)
MAX_NODES = 16
MAX_DETECTOR_CELLS = 32
# The texels' rule is checked against itself on images split 2 x 2: a rule whose error falls as h^p leaves
# D / (1 - 2^-p) of a difference D, at most 2 D for p >= 1 (the detector's check needs no factor: the finer rule's
# error is D / (2^p - 1) <= D)
TEXEL_CHECK_FACTOR = 2.0
ROUNDING_REL = 1e-12  # float64 sums over ~1e5 texels and points: well above their rounding, far below any rule's
MAX_PIECES_PER_CHUNK = 1 << 14  # pieces of a raster mask's texel images integrated at a time (memory)
BIG_M = 1e30  # [m] a strip's open side: beyond any mask


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
    with the frame; deterministic quadrature (no Monte Carlo) whose error estimate is each measurement's
    ``stderr_w_m2``. Displays only; the budget is not used.

    Parameters
    ----------
    parallax : bool
        Each mixel sees from its own detector centre (the field-of-view offset between mixels), not the mincam's.
    vignetting : bool
        Weigh the mask by ``cos^4`` about the mixel's axis (the physical fall-off) instead of uniformly.
    detector_blur : bool
        Average the pinhole over the detector's area (the blur of a finite detector).
    nodes : int
        Gauss-Legendre points per axis of each texel's image on the mask plane (or of each of its pieces, for a
        raster mask) and, with ``detector_blur``, of each detector cell.
    detector_cells : int
        With ``detector_blur``: squares per axis the detector is split into (``(detector_cells * nodes)^2``
        pinholes). Raise it where the error estimate is too large: a detector large beside ``d_f`` sweeps its view
        over many texels, and the pinhole's measurement has a kink at each (one high-order rule converges slowly
        there; a composite one faster).
    """

    name: ClassVar[str] = "dot_product"
    budget_reads: ClassVar[tuple[str, ...]] = ()  # deterministic quadrature: no samples
    scenes: ClassVar[tuple[str, ...]] = ("display",)

    parallax: bool = False
    vignetting: bool = False
    detector_blur: bool = False
    nodes: int = 4
    detector_cells: int = 1

    def __post_init__(self) -> None:
        for key in ("parallax", "vignetting", "detector_blur"):
            if not isinstance(getattr(self, key), bool):
                raise InputError(f"DotProduct {key} must be True or False, got {getattr(self, key)!r}")
        if isinstance(self.nodes, bool) or not isinstance(self.nodes, int) or not 1 <= self.nodes <= MAX_NODES:
            raise InputError(f"DotProduct nodes must be an integer from 1 to {MAX_NODES} (Gauss-Legendre points per "
                             f"axis of a texel), got {self.nodes!r}")
        cells = self.detector_cells
        if isinstance(cells, bool) or not isinstance(cells, int) or not 1 <= cells <= MAX_DETECTOR_CELLS:
            raise InputError(f"DotProduct detector_cells must be an integer from 1 to {MAX_DETECTOR_CELLS} (squares "
                             f"per axis of the detector, nodes x nodes points each), got {cells!r}")
        if self.detector_blur and self.nodes < 2:
            raise InputError("DotProduct with detector_blur needs nodes >= 2: the detector's error estimate compares "
                             "its rule with rules of fewer points per cell (raise detector_cells for more pinholes)")

    def detector_nodes_per_axis(self) -> int:
        """Pinholes per axis of the detector's rule (``detector_cells * nodes``; 1 without ``detector_blur``)."""
        return self.detector_cells * self.nodes if self.detector_blur else 1

    def effects(self) -> list[str]:
        """The physical effects this model includes (besides the bare mapping)."""
        return [k for k in ("parallax", "vignetting", "detector_blur") if getattr(self, k)]

    def maps(self, mincam: Mincam, screen: Screen, show_progress: bool = False) -> ResponseMaps:
        """Each mixel's weights over the screen's texels [sr] (variance 0), as :class:`ResponseMaps`; ``meta
        ["quadrature"]`` says the rules and the error estimate for a uniform frame."""
        return self.maps_and_checks(mincam, screen, show_progress)[0]

    def maps_and_checks(self, mincam: Mincam, screen: Screen,
                        show_progress: bool = False) -> tuple[ResponseMaps, np.ndarray]:
        """The maps and the three check maps of the error estimate, (3, n_mixels, rows, cols) [sr]: the maps minus
        the detector rules with half and with one fewer points per cell (0 without ``detector_blur``) and, at the
        detector's centre, twice the texels' finer rule minus their rule. A frame's error estimate is
        ``error_estimate`` of the checks' products with it."""
        for m in mincam:
            if m.optics != "geometric":
                raise InputError(f"mixel {m.name!r} has optics = {m.optics!r}; the dot-product model is geometric: "
                                 "use ResponseMap or Aperture for wave optics")
        check_visible(screen, mincam)  # the set-ups the ray solvers refuse: a mixel behind the screen, in it, blind
        centre = np.asarray(mincam.centre_m, dtype=np.float64)
        rows, cols = screen.shape
        weights = np.zeros((len(mincam), rows, cols))
        checks = np.zeros((3, len(mincam), rows, cols))
        for k in progress(range(len(mincam)), desc="dot_product: mixels", disable=not show_progress):
            weights[k], *parts = self._mixel_weights(mincam[k], screen, centre)
            checks[:, k] = parts
        total = weights.sum(axis=(1, 2))
        uniform = error_estimate(checks.sum(axis=(2, 3)).T, total) / np.where(total > 0, total, np.inf)
        meta = {**self.meta(mincam, screen), "quadrature": {
            "texel_rule": f"{self.nodes} x {self.nodes} Gauss-Legendre points per texel image",
            "detector_rule": (f"{self.detector_cells} x {self.detector_cells} cells of {self.nodes} x "
                              f"{self.nodes} Gauss-Legendre points" if self.detector_blur
                              else "a pinhole (no detector blur)"),
            "error_estimate": "max(|P - P(nodes // 2 per cell)|, |P - P(nodes - 1 per cell)|) + 2 |P_centre(texel "
                              "images split twice as fine) - P_centre|: deterministic, an estimate (not a bound); "
                              "each measurement's stderr_w_m2",
            "uniform_frame_rel_error": {m.name: float(e) for m, e in zip(mincam, uniform, strict=True)}}}
        return ResponseMaps(weights, np.zeros_like(weights), list(mincam.names), meta), checks

    def meta(self, mincam: Mincam, screen: Screen) -> dict:
        """What the maps are: the model, its effects, the quadrature, the units, and what it ignores."""
        from mincam_sim.render.scene.mincam_scene import geometry_meta

        return {"form": "dot_product", "solver": self.name,
                "estimator": "deterministic quadrature of the idealised model (no Monte Carlo; stderr_w_m2 is the "
                             "quadrature's error estimate)",
                "model": "mask stretched over the field seen from the "
                         + ("mixel's own detector centre" if self.parallax else "mincam's centre")
                         + (", cos^4 vignetting about the mixel's axis" if self.vignetting else ", uniform weights")
                         + (", averaged over the detector" if self.detector_blur else ", a pinhole detector"),
                "effects": self.effects(), "deterministic": True, "nodes": self.nodes,
                "detector_cells": self.detector_cells if self.detector_blur else None,
                "ignored": ["other mixels' bodies"] + ([] if self.parallax else ["field-of-view offset (parallax)"])
                + ([] if self.vignetting else ["cos^4 vignetting"])
                + ([] if self.detector_blur else ["detector size (blur)"]),
                "units": "sr (W/m^2 on the detector per W m^-2 sr^-1 of texel radiance)",
                "masks": {m.name: mask_model_meta(m.mask) for m in mincam},
                **geometry_meta(mincam, screen), "mixel_bodies": "ignored (the idealised model)"}

    def plan(self, sim, frames, budget: Budget, *, background=None, cache=None, show_progress: bool = False) -> Plan:
        return DotProductPlan(self, sim, frames, budget, show_progress)

    # ------------------------------------------------------------------------------------------- geometry
    def _mixel_weights(self, mixel: Mixel, screen: Screen,
                       centre_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The mixel's weights [sr] and its three check maps (:meth:`maps_and_checks`)."""
        rot = mixel.pose.matrix()[:3, :3]  # columns: local x (viewer's left), y (up), z (forward)
        origin = np.asarray(mixel.pose.position_m, dtype=np.float64) if self.parallax else centre_m
        scale = None if self.vignetting else aperture_view_factor_pi(mixel) / mixel.mask.area_m2

        def pinhole(a: float, b: float, refine: int = 1) -> np.ndarray:
            return _pinhole_weights(mixel, screen, origin + rot @ np.array([a, b, 0.0]), rot, (a, b), scale,
                                    self.nodes, refine)

        def detector(points: list[tuple[float, float, float]]) -> np.ndarray:
            return sum(w * pinhole(a, b) for a, b, w in points)

        centre, finer = pinhole(0.0, 0.0), pinhole(0.0, 0.0, refine=2)
        texel_check = TEXEL_CHECK_FACTOR * (finer - centre)
        if not self.detector_blur:  # one pinhole: its finer rule is the value (at the cost of the check alone)
            return finer, np.zeros_like(centre), np.zeros_like(centre), texel_check
        size, cells, nodes = mixel.detector_size_m, self.detector_cells, self.nodes
        weights = detector(detector_rule(size, cells, nodes))
        return (weights, weights - detector(detector_rule(size, cells, max(1, nodes // 2))),
                weights - detector(detector_rule(size, cells, max(1, nodes - 1))), texel_check)


def detector_rule(size_m: float, cells: int, nodes: int) -> list[tuple[float, float, float]]:
    """Points ``(a, b)`` [m] on a square detector of side ``size_m`` centred at 0, and their weights (sum 1): the
    detector split into ``cells x cells`` squares, ``nodes x nodes`` Gauss-Legendre points in each."""
    u, w = _composite01(nodes, cells)
    x = (u - 0.5) * size_m
    return [(a, b, wa * wb) for a, wa in zip(x, w, strict=True) for b, wb in zip(x, w, strict=True)]


class DotProductPlan(Plan):
    """The model's maps, then each chunk of frames a product with them (as :class:`~.response_map.MapPlan`)."""

    def __init__(self, solver: DotProduct, sim, frames, budget: Budget, show_progress: bool) -> None:
        self.solver, self.sim, self.show_progress = solver, sim, show_progress
        self.frames = sim.frame_source(frames)
        self.maps, checks = solver.maps_and_checks(sim.mincam, sim.screen, show_progress)
        self.checks = [ResponseMaps(c, np.zeros_like(c), self.maps.mixel_names) for c in checks]
        self.n_rows, self.columns = len(self.frames), list(sim.mincam.names)

    def rows(self, pending: np.ndarray) -> Iterator[Row]:
        step = max(1, min(FRAME_CHUNK, self.frames.chunk_size(FRAME_CHUNK_BYTES)))
        batches = [pending[i : i + step] for i in range(0, len(pending), step)]
        for idx in progress(batches, desc="dot_product: frames", disable=not self.show_progress,
                            total=len(batches), unit="chunk"):
            m = self.maps.measure_source(self.frames, idx, show_progress=False)
            error = error_estimate(np.stack([c.measure_source(self.frames, idx).irradiance_w_m2
                                             for c in self.checks], axis=-1), m.irradiance_w_m2)
            yield idx, m.irradiance_w_m2, error

    def result(self, values: np.ndarray, errors: np.ndarray) -> Measurements:
        meta = {**self.maps.meta, "reached_rel_stderr": worst_relative_stderr(values, errors)}
        m = Measurements(values, errors, list(self.sim.mincam.names), meta)
        m.maps = self.maps
        return m


def error_estimate(checked: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The error estimate [W/m^2] from the three check maps' products with a frame (last axis): the larger of the
    two detector checks plus the texels' check, and the sums' rounding (``ROUNDING_REL`` of the ``values``)."""
    checked = np.abs(checked)
    return np.maximum(checked[..., 0], checked[..., 1]) + checked[..., 2] + ROUNDING_REL * np.abs(values)


def _composite01(n: int, split: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Points and weights on [0, 1]: ``split`` equal parts, ``n`` Gauss-Legendre points in each."""
    x, w = np.polynomial.legendre.leggauss(n)
    parts = np.arange(split)[:, None]
    return ((parts + 0.5 * (x + 1)) / split).ravel(), np.tile(0.5 * w / split, split)


def _pinhole_weights(mixel: Mixel, screen: Screen, pinhole: np.ndarray, rot: np.ndarray, offset: tuple[float, float],
                     scale: float | None, nodes: int, refine: int = 1) -> np.ndarray:
    """Weights [sr] of every texel seen from one pinhole (a point on the detector plane, ``offset`` from the mask's
    axis): the integral over the texel's image on the mask plane of ``T * scale`` (bare) or ``T cos^4 / d_f^2``,
    each image (a raster mask's: each of its pieces, :func:`_piece_integrals`) integrated with its parameter
    square split into ``refine x refine`` parts of ``nodes x nodes`` points."""
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
    cut = ~inside & ~(beyond & away) & (cz > d_f).any(axis=-1)
    if mixel.mask.profile is None:  # a raster: every image cut along the mask's kinks or jumps, exactly
        lines = raster_lines(mixel.mask)
        if inside.any():
            quads = np.stack([cx[inside], cy[inside]], axis=-1)
            out[inside] = _piece_integrals(quads, np.full(len(quads), 4), lines, integrand, nodes, refine)
        if cut.any():
            polys, count = _cut_images(np.argwhere(cut), xe, ye, to_mask, (right, up, centre, pinhole, rot, d_f),
                                       (hw, hh))
            out[cut] = _piece_integrals(polys, count, lines, integrand, nodes, refine)
        return out
    out[inside] = _quads(cx[inside], cy[inside], integrand, nodes, refine)
    if cut.any():
        polys, count = _cut_images(np.argwhere(cut), xe, ye, to_mask, (right, up, centre, pinhole, rot, d_f),
                                   (hw, hh))
        out[cut] = _fan_integrals(polys, count, integrand, nodes, refine)
    return out


def raster_lines(mask) -> tuple[np.ndarray, np.ndarray]:
    """The lines of a raster mask's plane [m] (x = const, y = const) where its transmission kinks or jumps, as
    ``transmission_at`` reads it: ``nearest``, the texels' edges; ``bilinear``, the lines through the texels'
    centres (linear between them, constant beyond the outer ones up to the aperture's edge)."""
    rows, cols = mask.shape
    if mask.interpolation == "nearest":
        u, v = np.arange(1, cols) / cols, np.arange(1, rows) / rows
    else:
        u, v = (np.arange(cols) + 0.5) / cols, (np.arange(rows) + 0.5) / rows
    return (u - 0.5) * mask.width_m, np.sort((0.5 - v) * mask.height_m)


def _piece_integrals(polys: np.ndarray, count: np.ndarray, lines: tuple[np.ndarray, np.ndarray], integrand,
                     nodes: int, refine: int = 1) -> np.ndarray:
    """Integrals of ``integrand`` over convex polygons (``polys`` (n, v, 2) [m], the first ``count`` vertices
    valid), each cut along the grid ``lines`` (x, y) into pieces on which a raster mask is smooth (constant or
    bilinear), every piece integrated on its fan of triangles (:func:`_fan_integrals`); about
    ``MAX_PIECES_PER_CHUNK`` pieces at a time (a coarse screen's texel image can hold hundreds of mask texels)."""
    valid = np.arange(polys.shape[1])[None, :] < count[:, None]
    pieces = np.ones(len(polys), dtype=np.int64)
    for axis in (0, 1):  # the pieces a polygon's bounding box promises: (lines crossing in x + 1)(in y + 1)
        coord = polys[..., axis]
        lo = np.searchsorted(lines[axis], np.where(valid, coord, np.inf).min(axis=1), side="right")
        hi = np.searchsorted(lines[axis], np.where(valid, coord, -np.inf).max(axis=1), side="left")
        pieces *= np.maximum(hi - lo, 0) + 1
    out = np.zeros(len(polys))
    whole = pieces == 1  # inside one smooth part of the mask: integrated as it is, a quadrilateral on its own map
    quads = whole & (count == 4)
    if quads.any():
        out[quads] = _quads(polys[quads, :4, 0], polys[quads, :4, 1], integrand, nodes, refine)
    if (whole & ~quads).any():
        out[whole & ~quads] = _fan_integrals(polys[whole & ~quads], count[whole & ~quads], integrand, nodes, refine)
    cut = np.flatnonzero(~whole)
    bounds = np.searchsorted(np.cumsum(pieces[cut]), np.arange(MAX_PIECES_PER_CHUNK, int(pieces[cut].sum()),
                                                               MAX_PIECES_PER_CHUNK), side="right")
    for lo, hi in zip([0, *bounds.tolist()], [*bounds.tolist(), len(cut)], strict=True):
        if hi <= lo:
            continue
        chunk, n, owner = polys[cut[lo:hi]], count[cut[lo:hi]], np.arange(hi - lo)
        for axis in (0, 1):
            chunk, n, kept = _cut_along(chunk, n, lines[axis], axis)
            owner = owner[kept]
        out[cut[lo:hi]] = np.bincount(owner, weights=_fan_integrals(chunk, n, integrand, nodes, refine),
                                      minlength=hi - lo)
    return out


def _cut_along(polys: np.ndarray, count: np.ndarray, lines: np.ndarray, axis: int):
    """Each convex polygon cut by the lines ``coordinate[axis] = lines`` (sorted) it crosses into its strips
    between them; returns the pieces (padded), their vertex counts and the index of the polygon each came from."""
    valid = np.arange(polys.shape[1])[None, :] < count[:, None]
    coord = polys[..., axis]
    lo = np.where(valid, coord, np.inf).min(axis=1)
    hi = np.where(valid, coord, -np.inf).max(axis=1)
    first = np.searchsorted(lines, lo, side="right")  # the lines strictly inside (lo, hi) cut the polygon
    strips = np.maximum(np.searchsorted(lines, hi, side="left") - first, 0) + 1
    owner = np.repeat(np.arange(len(polys)), strips)
    k = np.arange(len(owner)) - np.repeat(np.cumsum(strips) - strips, strips)  # the strip's index in its polygon
    # strip k lies between edges[first + k] and edges[first + k + 1]: the outer ones are lines beyond the polygon
    # (or +-BIG_M), which cut nothing
    edges = np.concatenate([[-BIG_M], lines, [BIG_M]])
    lower, upper = edges[first[owner] + k], edges[first[owner] + k + 1]
    normal = np.zeros(2)
    normal[axis] = 1.0
    pieces, n = _clip_halfplanes(polys[owner], count[owner], normal, -lower)
    pieces, n = _clip_halfplanes(pieces, n, -normal, upper)
    return pieces, n, owner


def _quads(cx: np.ndarray, cy: np.ndarray, integrand, nodes: int, split: int = 1) -> np.ndarray:
    """Integrals of ``integrand`` over quadrilaterals (corners (n, 4) in order), by the bilinear map of the unit
    square and ``nodes x nodes`` Gauss-Legendre points in each of its ``split x split`` parts."""
    u, wu = _composite01(nodes, split)
    uu, vv = (g.ravel() for g in np.meshgrid(u, u, indexing="ij"))
    ww = np.outer(wu, wu).ravel()
    # P(u, v) = (1-u)(1-v) p0 + u(1-v) p1 + u v p2 + (1-u) v p3 (p0 top-left, p1 top-right, p2 bottom-right)
    basis = np.stack([(1 - uu) * (1 - vv), uu * (1 - vv), uu * vv, (1 - uu) * vv], axis=0)  # (4, m)
    du = np.stack([-(1 - vv), 1 - vv, vv, -vv], axis=0)
    dv = np.stack([-(1 - uu), -uu, uu, 1 - uu], axis=0)
    px, py = cx @ basis, cy @ basis
    jac = np.abs((cx @ du) * (cy @ dv) - (cx @ dv) * (cy @ du))
    return (integrand(px, py) * jac) @ ww


def _cut_images(texels: np.ndarray, xe: np.ndarray, ye: np.ndarray, to_mask, frame,
                half: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """The images of texels cut by the mask plane or the aperture's edge: each texel clipped to the part beyond
    the mask plane (on the screen), projected, clipped to the aperture; (polygons (n, v, 2) [m] on the mask
    plane, padded; their vertex counts)."""
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
    return img, count


def _fan_integrals(img: np.ndarray, count: np.ndarray, integrand, nodes: int, split: int = 1) -> np.ndarray:
    """Integrals of ``integrand`` over convex polygons (``img`` (n, v, 2) [m], the first ``count`` vertices valid),
    each split into a fan of triangles integrated by a collapsed ``nodes x nodes`` Gauss-Legendre rule on each of
    ``split x split`` parts of its square (all polygons at once)."""
    if img.shape[1] < 3:
        return np.zeros(len(img))
    u, wu = _composite01(nodes, split)
    su, sv = (g.ravel() for g in np.meshgrid(u, u, indexing="ij"))
    sw = np.outer(wu, wu).ravel() * su  # collapsed square -> triangle: Jacobian s
    # the fan's live triangles (0, k, k + 1), k = 1 .. count - 2, of every polygon: none of the padding's
    poly, k = np.nonzero(np.arange(1, img.shape[1] - 1)[None, :] <= count[:, None] - 2)
    p0, p1, p2 = img[poly, 0], img[poly, k + 1], img[poly, k + 2]
    area2 = np.abs((p1[:, 0] - p0[:, 0]) * (p2[:, 1] - p0[:, 1]) - (p1[:, 1] - p0[:, 1]) * (p2[:, 0] - p0[:, 0]))
    tx = p0[:, 0, None] + su * (p1[:, 0, None] - p0[:, 0, None]) + su * sv * (p2[:, 0, None] - p1[:, 0, None])
    ty = p0[:, 1, None] + su * (p1[:, 1, None] - p0[:, 1, None]) + su * sv * (p2[:, 1, None] - p1[:, 1, None])
    return np.bincount(poly, weights=(integrand(tx, ty) @ sw) * area2, minlength=len(img))


def _clip_halfplanes(polys: np.ndarray, count: np.ndarray, normal: np.ndarray, offset):
    """Sutherland-Hodgman for many convex polygons at once: the part of each polygon (``polys`` (n, v, 2), the first
    ``count`` vertices valid) where ``normal . p + offset >= 0`` (``offset`` one number, or one per polygon);
    returns the clipped polygons, padded, and counts."""
    n, v = polys.shape[:2]
    idx = np.arange(v)[None, :]
    valid = idx < count[:, None]
    nxt = np.where(idx + 1 < count[:, None], idx + 1, 0)
    q = np.take_along_axis(polys, nxt[..., None], axis=1)
    offset = np.reshape(offset, (-1, 1)) if np.ndim(offset) else offset  # one per polygon, or one for all
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


__all__ = ["DotProduct", "DotProductPlan", "aperture_view_factor_pi", "detector_rule"]
