"""Curved and circular ramps (the paper's Sec. 4.1 extension to curved boundaries): transmission = arc-length
fraction of the closest point on a curve."""

from __future__ import annotations

import numpy as np

from mincam_sim.errors import InputError
from mincam_sim.masks import profiles as prof
from mincam_sim.masks.mask import DEFAULT_MASK_SIZE_M, DEFAULT_RESOLUTION, Mask, _check_resolution, _normalized_grid


def _to_physical_points(
    points: np.ndarray, coords: str, width_m: float, height_m: float, what: str
) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise InputError(f"{what}: curve must be an (N, 2) array of (x, y) points, got shape {p.shape}")
    if p.shape[0] < 2:
        raise InputError(f"{what}: curve needs at least 2 points, got {p.shape[0]}")
    if not np.isfinite(p).all():
        raise InputError(f"{what}: curve points must be finite numbers (found NaN or infinity)")
    if coords == "normalized":
        return np.column_stack(((p[:, 0] - 0.5) * width_m, (p[:, 1] - 0.5) * height_m))
    if coords == "physical":
        return p.copy()
    raise InputError(f"{what}: coords must be 'normalized' or 'physical', got {coords!r}")


def _arc_length_fraction(
    points_m: np.ndarray, query_m: np.ndarray, chunk_elems: int = 4_000_000
) -> np.ndarray:
    """s / L of the closest point on a polyline for each query point.

    Parameters
    ----------
    points_m : (N, 2) ndarray
        Polyline vertices [m]; consecutive duplicates must already be removed.
    query_m : (Q, 2) ndarray
        Query points [m].

    Returns
    -------
    (Q,) ndarray
        Arc-length fraction in [0, 1]. Ties (several equally close curve points) go to the first segment.
    """
    a = points_m[:-1]
    d = points_m[1:] - a
    seg_len2 = np.einsum("ij,ij->i", d, d)
    seg_len = np.sqrt(seg_len2)
    cum = np.concatenate(([0.0], np.cumsum(seg_len)))
    total = cum[-1]
    out = np.empty(len(query_m))
    step = max(1, chunk_elems // len(a))
    for lo in range(0, len(query_m), step):
        q = query_m[lo : lo + step]
        rx = q[:, 0, None] - a[None, :, 0]
        ry = q[:, 1, None] - a[None, :, 1]
        t = np.clip((rx * d[None, :, 0] + ry * d[None, :, 1]) / seg_len2[None, :], 0.0, 1.0)
        ex = rx - t * d[None, :, 0]
        ey = ry - t * d[None, :, 1]
        k = np.argmin(ex * ex + ey * ey, axis=1)
        rows = np.arange(len(q))
        out[lo : lo + step] = (cum[k] + t[rows, k] * seg_len[k]) / total
    return np.clip(out, 0.0, 1.0)


def curved_ramp(
    curve_xy: np.ndarray,
    resolution: int | tuple[int, int] = DEFAULT_RESOLUTION,
    width_m: float = DEFAULT_MASK_SIZE_M,
    height_m: float | None = None,
    coords: str = "normalized",
    values: tuple[float, float] = (0.0, 1.0),
    closed: bool = False,
    name: str = "curved_ramp",
) -> Mask:
    """Ramp that varies linearly along the arc length of a curve (the paper's Section 4.1 extension).

    For a virtual boundary along a curve ``s`` the paper makes "the linear variation of the mask ... along the
    circumference of the circle or along the curved boundary". Here each texel takes the arc-length fraction
    ``s / L`` of its *closest point* on the polyline, mapped linearly to ``values``::

        M = values[0] + (values[1] - values[0]) * s / L

    Parameters
    ----------
    curve_xy : (N, 2) array_like of float
        Polyline vertices (x, y), N >= 2, in the order of increasing ``s``. In ``"normalized"`` coords x, y
        are in mask units (x left to right, y bottom to top, [0, 1] spans the mask; points may lie outside);
        in ``"physical"`` coords they are metres from the mask centre (+x right, +y up).
    resolution : int or (int, int)
        Texels per side, or (H, W).
    width_m, height_m : float
        Physical mask size [m]; ``height_m`` defaults to ``width_m``.
    coords : {"normalized", "physical"}
        Coordinate system of ``curve_xy``.
    values : (float, float)
        Transmission at the start (s = 0) and the end (s = L) of the curve, both in [0, 1]; ``(1, 0)``
        gives the complementary ramp.
    closed : bool
        Append the first vertex to close the curve (the ramp then jumps from ``values[1]`` back to
        ``values[0]`` at the start point).
    name : str
        Mask name.

    Returns
    -------
    Mask
        ``meta`` records the curve (in physical coordinates [m]), its length [m] and ``values``.

    Notes
    -----
    Distances and arc lengths are measured in physical units, so a curve keeps its shape on non-square masks.
    Off the curve, a texel takes the value of the nearest curve point: texels beyond the ends of an open curve
    get ``values[0]`` or ``values[1]``, and texels equidistant from several curve points (e.g. the centre of a
    circle, or the medial axis of a bent curve) take the first of them along the curve, so the mask can jump
    there. Only the transmission on (and near) the curve matters when the scene boundary is imaged onto it.
    Cost is O(texels x segments) (about 1 s for 256 x 256 texels and 360 segments).
    """
    h, w = _check_resolution(resolution)
    hgt = width_m if height_m is None else height_m
    for key, v in (("width_m", width_m), ("height_m", hgt)):
        if not (np.isfinite(v) and v > 0):
            raise InputError(f"curved_ramp: {key} must be a positive size in metres, got {v!r}")
    v0, v1 = (float(v) for v in values)
    if not (0.0 <= v0 <= 1.0 and 0.0 <= v1 <= 1.0):
        raise InputError(f"curved_ramp: values must both lie in [0, 1], got {values!r}")
    pts = _to_physical_points(curve_xy, coords, width_m, hgt, "curved_ramp")
    if closed:
        pts = np.vstack((pts, pts[:1]))
    keep = np.concatenate(([True], np.any(np.diff(pts, axis=0) != 0.0, axis=1)))
    pts = pts[keep]
    if len(pts) < 2:
        raise InputError("curved_ramp: the curve has zero length (all points coincide); give distinct points")
    x, y = _normalized_grid(h, w)
    query = np.column_stack((((x - 0.5) * width_m).ravel(), ((y - 0.5) * hgt).ravel()))
    frac = _arc_length_fraction(pts, query).reshape(h, w)
    t = np.clip(v0 + (v1 - v0) * frac, 0.0, 1.0)
    length = float(np.sum(np.hypot(*np.diff(pts, axis=0).T)))
    meta = {"kind": "curved_ramp", "curve_m": pts.tolist(), "length_m": length, "values": [v0, v1]}
    return Mask(t, width_m, hgt, name, meta)


def circular_ramp(
    center: tuple[float, float] = (0.5, 0.5),
    radius: float = 0.35,
    start_angle_deg: float = 0.0,
    sweep_deg: float = 360.0,
    resolution: int | tuple[int, int] = DEFAULT_RESOLUTION,
    width_m: float = DEFAULT_MASK_SIZE_M,
    height_m: float | None = None,
    coords: str = "normalized",
    values: tuple[float, float] = (0.0, 1.0),
    n_segments: int | None = None,
    name: str = "circular_ramp",
) -> Mask:
    """Ramp along a circular arc: transmission = fraction of the arc angle swept from ``start_angle_deg``.

    This is :func:`curved_ramp` for a circular arc, with the same rule (each texel takes the arc-length
    fraction of its closest arc point). By default the closest point on the exact circle is used: the radial
    projection of the texel (its polar angle about the centre) when that falls on the arc, otherwise the
    nearer arc end. With ``n_segments`` the arc is instead approximated by a polygon of equal chords and passed
    to :func:`curved_ramp` (slower; off the circle the fraction then deviates by ~ (dr / R) (chord angle)).

    Parameters
    ----------
    center : (float, float)
        Circle centre: normalised mask coords (x right, y up, [0, 1]) or metres from the mask centre, see
        ``coords``.
    radius : float
        Radius: a fraction of the mask *width* for ``coords="normalized"`` (the circle stays round on
        non-square masks), metres for ``coords="physical"``.
    start_angle_deg : float
        Angle where the ramp starts (value ``values[0]``), degrees counter-clockwise from +x (right).
    sweep_deg : float
        Angular extent, degrees; positive = counter-clockwise, negative = clockwise. ``|sweep| <= 360``.
    resolution, width_m, height_m
        As in :func:`curved_ramp`.
    values : (float, float)
        Transmission at the start and end of the arc.
    n_segments : int, optional
        If given, approximate the arc by this many chords and use :func:`curved_ramp`; default: exact circle.
    name : str
        Mask name.

    Returns
    -------
    Mask
        Texels near the circle get ``values[0] + (values[1] - values[0]) * angle / sweep``; elsewhere, the
        value of the nearest arc point (so inside a full circle the value follows the polar angle about the
        centre; the start angle is a seam where it jumps from ``values[1]`` to ``values[0]``).
    """
    if not (np.isfinite(radius) and radius > 0):
        raise InputError(f"circular_ramp: radius must be positive, got {radius!r}")
    if not (np.isfinite(sweep_deg) and 0 < abs(sweep_deg) <= 360):
        raise InputError(f"circular_ramp: sweep_deg must be in [-360, 0) or (0, 360], got {sweep_deg!r}")
    hgt = width_m if height_m is None else height_m
    if coords == "normalized":
        cx, cy = (center[0] - 0.5) * width_m, (center[1] - 0.5) * hgt
        r_m = radius * width_m
    elif coords == "physical":
        (cx, cy), r_m = center, radius
    else:
        raise InputError(f"circular_ramp: coords must be 'normalized' or 'physical', got {coords!r}")
    meta = {
        "kind": "circular_ramp", "center_m": [float(cx), float(cy)], "radius_m": float(r_m),
        "start_angle_deg": float(start_angle_deg), "sweep_deg": float(sweep_deg), "n_segments": n_segments,
    }
    if n_segments is not None:
        n = int(n_segments)
        if n < 1 or n != n_segments:
            raise InputError(f"circular_ramp: n_segments must be an integer >= 1, got {n_segments!r}")
        ang = np.deg2rad(start_angle_deg + sweep_deg * np.linspace(0.0, 1.0, n + 1))
        curve = np.column_stack((cx + r_m * np.cos(ang), cy + r_m * np.sin(ang)))
        m = curved_ramp(curve, resolution, width_m, hgt, coords="physical", values=values, name=name)
        meta["values"] = list(m.meta["values"])
        return Mask(m.transmission, m.width_m, m.height_m, name, meta)

    h, w = _check_resolution(resolution)
    v0, v1 = (float(v) for v in values)
    if not (0.0 <= v0 <= 1.0 and 0.0 <= v1 <= 1.0):
        raise InputError(f"circular_ramp: values must both lie in [0, 1], got {values!r}")
    x, y = _normalized_grid(h, w)
    dx, dy = (x - 0.5) * width_m - cx, (y - 0.5) * hgt - cy
    sweep = np.deg2rad(abs(sweep_deg))
    start = np.deg2rad(start_angle_deg)
    rel = np.mod((np.arctan2(dy, dx) - start) * np.sign(sweep_deg), 2 * np.pi)  # angle along the sweep
    frac = rel / sweep
    outside = rel > sweep  # beyond the ends of a partial arc: nearer end point
    if outside.any():
        end = start + np.deg2rad(sweep_deg)
        d_start = np.hypot(dx - r_m * np.cos(start), dy - r_m * np.sin(start))
        d_end = np.hypot(dx - r_m * np.cos(end), dy - r_m * np.sin(end))
        frac = np.where(outside, np.where(d_start <= d_end, 0.0, 1.0), frac)
    frac = np.where((dx == 0) & (dy == 0), 0.0, np.clip(frac, 0.0, 1.0))  # centre: all points tie -> start
    meta["values"] = [v0, v1]
    profile = prof.CircularArc(float(cx), float(cy), float(r_m), float(start_angle_deg), float(sweep_deg), v0, v1)
    return Mask(np.clip(v0 + (v1 - v0) * frac, 0.0, 1.0), width_m, hgt, name, meta, profile)
