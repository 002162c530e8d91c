"""Transmission masks: a 2D grayscale transmission texture in [0, 1] with a physical size.

Array convention (the same for every mask and every file this package writes): ``transmission[i, j]``
with row ``i = 0`` at the *top* and column ``j = 0`` at the *left*, as seen from the detector looking out
through the mask (mixel "up" is local +y). Because a lensless mask does not invert the scene, a mask point on
the right of the detector sees the scene on the right: the mask picture overlays directly on the scene as the
mixel sees it.

Normalised mask coordinates used by the generators: ``x`` in [0, 1] from left to right and ``y`` in [0, 1]
from bottom to top (the paper's M = x, 1 - x, y, 1 - y). Physical mask coordinates ``x_m``, ``y_m`` [m] are
centred on the mask, +x_m to the right, +y_m up.

Besides the analytic generators (ramps, sinusoids, curved/circular ramps for the paper's Section 4.1
extension) the module loads and saves masks (PNG/OpenEXR), models what a printer makes of a mask on
transparency film (:class:`PrintedFilm`), exports print-ready PNGs and writes a standard mask library.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from . import mask_profiles as prof
from .mask_profiles import MaskProfile

DEFAULT_MASK_SIZE_M = 2e-3  # [m] square mask side: with d_f = 2 mm it gives a ~53 degree field of view
DEFAULT_RESOLUTION = 256  # texels per side of generated masks
MAX_TEXELS = 8192 * 8192


@dataclass(frozen=True, eq=False)
class Mask:
    """A transmission mask.

    Parameters
    ----------
    transmission : (H, W) array_like of float
        Transmission in [0, 1] (fraction of light passed), row 0 at the top (see module docstring).
    width_m, height_m : float
        Physical size of the mask [m].
    name : str
        Short label used in file names and metadata.
    meta : dict
        Free-form description (generator parameters, film ...).
    profile : MaskProfile, optional
        The exact analytic transmission (set by the generators: ramps, sinusoids, circular ramps ...). The
        renderer evaluates it at every ray, so the texel array is then only a picture of the mask; without a
        profile the array *is* the mask, reconstructed with ``interpolation``.
    interpolation : {"bilinear", "nearest"}
        How a raster mask (no profile) is read between texels: ``"bilinear"`` between texel centres (smooth
        images) or ``"nearest"`` (piecewise-constant printer dots).
    """

    transmission: np.ndarray
    width_m: float = DEFAULT_MASK_SIZE_M
    height_m: float = DEFAULT_MASK_SIZE_M
    name: str = "mask"
    meta: dict = field(default_factory=dict)
    profile: MaskProfile | None = None
    interpolation: str = "bilinear"

    def __post_init__(self) -> None:
        t = np.array(self.transmission, dtype=np.float64, copy=True)
        if t.ndim == 3 and t.shape[2] == 1:
            t = t[..., 0]
        if t.ndim != 2:
            raise ValueError(
                f"mask {self.name!r}: transmission must be a 2D array (H, W), got shape {t.shape}"
            )
        if t.size == 0:
            raise ValueError(f"mask {self.name!r}: transmission array is empty; give at least 1x1 texels")
        if t.size > MAX_TEXELS:
            raise ValueError(
                f"mask {self.name!r}: {t.shape} is too large (max {MAX_TEXELS} texels); downsample it"
            )
        bad = ~np.isfinite(t)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise ValueError(
                f"mask {self.name!r}: {int(bad.sum())} texel(s) are NaN or infinite"
                f" (first at row {i}, column {j}); transmission must be finite numbers in [0, 1]"
            )
        lo, hi = float(t.min()), float(t.max())
        if lo < 0.0 or hi > 1.0:
            raise ValueError(
                f"mask {self.name!r}: transmission must lie in [0, 1] but spans [{lo:.4g}, {hi:.4g}];"
                " rescale it (e.g. divide by its maximum) or clip it"
            )
        for key in ("width_m", "height_m"):
            v = getattr(self, key)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"mask {self.name!r}: {key} must be a positive size in metres, got {v!r}")
        if self.profile is not None and not isinstance(self.profile, MaskProfile):
            raise TypeError(f"mask {self.name!r}: profile must be a mincam_sim.mask_profiles.MaskProfile or None")
        if self.interpolation not in ("bilinear", "nearest"):
            raise ValueError(f"mask {self.name!r}: interpolation must be 'bilinear' or 'nearest', "
                             f"got {self.interpolation!r}")
        t.setflags(write=False)
        object.__setattr__(self, "transmission", t)
        object.__setattr__(self, "width_m", float(self.width_m))
        object.__setattr__(self, "height_m", float(self.height_m))

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) in texels."""
        return self.transmission.shape  # type: ignore[return-value]

    @property
    def area_m2(self) -> float:
        """Physical aperture area [m^2]."""
        return self.width_m * self.height_m

    def scaled(self, k: float) -> Mask:
        """The same mask with transmission multiplied by ``k`` (result must stay in [0, 1])."""
        profile = None if self.profile is None else prof.Affine(self.profile, float(k), 0.0)
        return Mask(self.transmission * k, self.width_m, self.height_m, f"{self.name}*{k:g}", dict(self.meta),
                    profile, self.interpolation)

    def complement(self) -> Mask:
        """The complementary mask 1 - M."""
        profile = None if self.profile is None else prof.Affine(self.profile, -1.0, 1.0)
        return Mask(1.0 - self.transmission, self.width_m, self.height_m, f"1-{self.name}", dict(self.meta),
                    profile, self.interpolation)

    @property
    def is_analytic(self) -> bool:
        """True when the renderer evaluates the mask exactly (a profile), not from its texel array."""
        return self.profile is not None

    def fingerprint_parts(self) -> dict:
        """Everything that determines what this mask transmits (for run identities)."""
        import hashlib

        return {
            "transmission_sha256": hashlib.sha256(np.ascontiguousarray(self.transmission).tobytes()).hexdigest(),
            "shape": list(self.shape),
            "width_m": self.width_m,
            "height_m": self.height_m,
            "profile": None if self.profile is None else self.profile.describe(),
            "interpolation": self.interpolation,
        }

    def normalized_coords(self) -> tuple[np.ndarray, np.ndarray]:
        """Texel-centre coordinates (x, y) in [0, 1], x left to right, y bottom to top, each (H, W)."""
        h, w = self.shape
        return _normalized_grid(h, w)

    def physical_coords(self) -> tuple[np.ndarray, np.ndarray]:
        """Texel-centre coordinates (x_m, y_m) [m] centred on the mask, +x right, +y up, each (H, W)."""
        x, y = self.normalized_coords()
        return (x - 0.5) * self.width_m, (y - 0.5) * self.height_m


def _normalized_grid(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    x = (np.arange(w) + 0.5) / w
    y = 1.0 - (np.arange(h) + 0.5) / h
    return np.meshgrid(x, y)


def _check_resolution(resolution: int | tuple[int, int]) -> tuple[int, int]:
    h, w = (resolution, resolution) if np.isscalar(resolution) else tuple(resolution)  # type: ignore[misc]
    if int(h) != h or int(w) != w or h < 1 or w < 1:
        raise ValueError(f"mask resolution must be positive integers (H, W), got {resolution!r}")
    return int(h), int(w)


def from_function(
    func,
    name: str,
    resolution: int | tuple[int, int] = DEFAULT_RESOLUTION,
    width_m: float = DEFAULT_MASK_SIZE_M,
    height_m: float | None = None,
    **meta,
) -> Mask:
    """Mask sampled at texel centres from ``func(x, y) -> transmission`` with x, y in [0, 1] (y up)."""
    h, w = _check_resolution(resolution)
    x, y = _normalized_grid(h, w)
    values = np.broadcast_to(np.asarray(func(x, y), dtype=float), (h, w))
    return Mask(values, width_m, width_m if height_m is None else height_m, name, meta)


def from_profile(
    profile: MaskProfile,
    name: str,
    resolution: int | tuple[int, int] = DEFAULT_RESOLUTION,
    width_m: float = DEFAULT_MASK_SIZE_M,
    height_m: float | None = None,
    **meta,
) -> Mask:
    """An analytic mask: exact ``profile`` (evaluated per ray when rendering) and its texel picture."""
    h, w = _check_resolution(resolution)
    hgt = width_m if height_m is None else height_m
    for key, v in (("width_m", width_m), ("height_m", hgt)):
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"mask {name!r}: {key} must be a positive size in metres, got {v!r}")
    return Mask(prof.sample(profile, (h, w), width_m, hgt), width_m, hgt, name, meta, profile)


def ramp(
    kind: str = "x",
    resolution: int | tuple[int, int] = DEFAULT_RESOLUTION,
    width_m: float = DEFAULT_MASK_SIZE_M,
    height_m: float | None = None,
) -> Mask:
    """Linear ramp mask: ``kind`` is ``"x"``, ``"1-x"``, ``"y"`` or ``"1-y"`` (the paper's Eq. 2 and 5)."""
    kinds = ("x", "1-x", "y", "1-y")
    if kind not in kinds:
        raise ValueError(f"unknown ramp {kind!r}: choose one of {', '.join(kinds)}")
    hgt = width_m if height_m is None else height_m
    return from_profile(prof.Ramp(kind, float(width_m), float(hgt)), f"ramp_{kind}", resolution, width_m, hgt,
                        kind="ramp", ramp=kind)


def constant(
    value: float = 1.0,
    resolution: int | tuple[int, int] = 1,
    width_m: float = DEFAULT_MASK_SIZE_M,
    height_m: float | None = None,
) -> Mask:
    """Uniform mask of transmission ``value`` (1 = open aperture)."""
    if not (np.isfinite(value) and 0.0 <= value <= 1.0):
        raise ValueError(f"constant mask transmission must lie in [0, 1], got {value!r}")
    return from_profile(prof.Constant(float(value)), f"constant_{value:g}", resolution, width_m, height_m,
                        kind="constant", value=value)


def sinusoid(
    omega_rad_per_m: float,
    a0: float = 0.5,
    a1: float = 0.5,
    phase_rad: float = 0.0,
    direction_deg: float = 0.0,
    resolution: int | tuple[int, int] = DEFAULT_RESOLUTION,
    width_m: float = DEFAULT_MASK_SIZE_M,
    height_m: float | None = None,
) -> Mask:
    """Sinusoid mask M = a0 + a1 cos(omega (x_m cos t + y_m sin t) + phase) (the paper's Eq. 9).

    Parameters
    ----------
    omega_rad_per_m : float
        Angular spatial frequency on the mask [rad/m] (omega_df in the paper).
    a0, a1 : float
        Mean and amplitude; a0 - |a1| >= 0 and a0 + |a1| <= 1 keep the mask physical.
    phase_rad : float
        Phase at the mask centre [rad].
    direction_deg : float
        Direction t of the wave vector, degrees counter-clockwise from +x (right).
    """
    if not np.isfinite(omega_rad_per_m) or omega_rad_per_m < 0:
        raise ValueError(f"omega_rad_per_m must be a finite frequency >= 0 [rad/m], got {omega_rad_per_m!r}")
    if a0 - abs(a1) < -1e-12 or a0 + abs(a1) > 1 + 1e-12:
        raise ValueError(f"sinusoid a0={a0}, a1={a1} leaves [0, 1]: need a0 - |a1| >= 0 and a0 + |a1| <= 1")
    hgt = width_m if height_m is None else height_m
    profile = prof.Sinusoid(float(omega_rad_per_m), float(a0), float(a1), float(phase_rad), float(direction_deg))
    return from_profile(
        profile, f"sinusoid_{omega_rad_per_m:g}", resolution, width_m, hgt, kind="sinusoid",
        omega_rad_per_m=omega_rad_per_m, a0=a0, a1=a1, phase_rad=phase_rad, direction_deg=direction_deg,
    )


# ============================================================================================ curved ramps
def _to_physical_points(
    points: np.ndarray, coords: str, width_m: float, height_m: float, what: str
) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"{what}: curve must be an (N, 2) array of (x, y) points, got shape {p.shape}")
    if p.shape[0] < 2:
        raise ValueError(f"{what}: curve needs at least 2 points, got {p.shape[0]}")
    if not np.isfinite(p).all():
        raise ValueError(f"{what}: curve points must be finite numbers (found NaN or infinity)")
    if coords == "normalized":
        return np.column_stack(((p[:, 0] - 0.5) * width_m, (p[:, 1] - 0.5) * height_m))
    if coords == "physical":
        return p.copy()
    raise ValueError(f"{what}: coords must be 'normalized' or 'physical', got {coords!r}")


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
            raise ValueError(f"curved_ramp: {key} must be a positive size in metres, got {v!r}")
    v0, v1 = (float(v) for v in values)
    if not (0.0 <= v0 <= 1.0 and 0.0 <= v1 <= 1.0):
        raise ValueError(f"curved_ramp: values must both lie in [0, 1], got {values!r}")
    pts = _to_physical_points(curve_xy, coords, width_m, hgt, "curved_ramp")
    if closed:
        pts = np.vstack((pts, pts[:1]))
    keep = np.concatenate(([True], np.any(np.diff(pts, axis=0) != 0.0, axis=1)))
    pts = pts[keep]
    if len(pts) < 2:
        raise ValueError("curved_ramp: the curve has zero length (all points coincide); give distinct points")
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
        Angular extent, degrees; positive = counter-clockwise, negative = clockwise. |sweep| <= 360.
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
        raise ValueError(f"circular_ramp: radius must be positive, got {radius!r}")
    if not (np.isfinite(sweep_deg) and 0 < abs(sweep_deg) <= 360):
        raise ValueError(f"circular_ramp: sweep_deg must be in [-360, 0) or (0, 360], got {sweep_deg!r}")
    hgt = width_m if height_m is None else height_m
    if coords == "normalized":
        cx, cy = (center[0] - 0.5) * width_m, (center[1] - 0.5) * hgt
        r_m = radius * width_m
    elif coords == "physical":
        (cx, cy), r_m = center, radius
    else:
        raise ValueError(f"circular_ramp: coords must be 'normalized' or 'physical', got {coords!r}")
    meta = {
        "kind": "circular_ramp", "center_m": [float(cx), float(cy)], "radius_m": float(r_m),
        "start_angle_deg": float(start_angle_deg), "sweep_deg": float(sweep_deg), "n_segments": n_segments,
    }
    if n_segments is not None:
        n = int(n_segments)
        if n < 1 or n != n_segments:
            raise ValueError(f"circular_ramp: n_segments must be an integer >= 1, got {n_segments!r}")
        ang = np.deg2rad(start_angle_deg + sweep_deg * np.linspace(0.0, 1.0, n + 1))
        curve = np.column_stack((cx + r_m * np.cos(ang), cy + r_m * np.sin(ang)))
        m = curved_ramp(curve, resolution, width_m, hgt, coords="physical", values=values, name=name)
        meta["values"] = list(m.meta["values"])
        return Mask(m.transmission, m.width_m, m.height_m, name, meta)

    h, w = _check_resolution(resolution)
    v0, v1 = (float(v) for v in values)
    if not (0.0 <= v0 <= 1.0 and 0.0 <= v1 <= 1.0):
        raise ValueError(f"circular_ramp: values must both lie in [0, 1], got {values!r}")
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


# ============================================================================================ file I/O
_LUMA_709 = np.array([0.2126, 0.7152, 0.0722])


def _to_transmission(arr: np.ndarray, channels: list[str], src: str) -> np.ndarray:
    """Reduce an image (H, W) or (H, W, C) to one transmission channel."""
    if arr.ndim == 2:
        return arr
    names = list(channels)
    if "A" in names:
        alpha = arr[..., names.index("A")]
        if np.any(alpha < 1.0 - 1e-6):
            raise ValueError(
                f"mask file {src!r} has a transparent alpha channel; transmission would be ambiguous:"
                " flatten the image onto white or black and save it without alpha"
            )
        keep = [k for k, n in enumerate(names) if n != "A"]
        arr, names = arr[..., keep], [names[k] for k in keep]
        if arr.shape[-1] == 1:
            return arr[..., 0]
    if "Y" in names:
        return arr[..., names.index("Y")]
    if all(c in names for c in ("R", "G", "B")) and len(names) == 3:
        rgb = np.stack([arr[..., names.index(c)] for c in ("R", "G", "B")], axis=-1)
        return rgb @ _LUMA_709
    raise ValueError(
        f"mask file {src!r} has {arr.shape[-1]} channels ({', '.join(names)}); give a single-channel"
        " grayscale (PNG 'L' / EXR 'Y') or an RGB image"
    )


def load(
    path: str | Path,
    width_m: float | None = None,
    height_m: float | None = None,
    invert: bool = False,
    name: str | None = None,
) -> Mask:
    """Load a mask from a PNG (8/16-bit) or OpenEXR file.

    Parameters
    ----------
    path : str or Path
        Image file; the format is detected from its content. Image row 0 (top) is mask row 0 (top as seen from
        the detector looking out), i.e. the picture overlays the scene as the mixel sees it.
    width_m : float, optional
        Physical mask width [m]. Required for PNG; for EXR files written by :func:`save_exr` it defaults to
        the stored size.
    height_m : float, optional
        Physical mask height [m]; defaults to the stored size (EXR) or ``width_m * H / W`` (square texels).
    invert : bool
        Use ``1 - value`` (for files where black means clear).
    name : str, optional
        Mask name; defaults to the stored name (EXR) or the file stem.

    Returns
    -------
    Mask
        ``meta`` records the source file and format (and, for EXR, the stored metadata).

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        For an empty, unreadable or non-image file, an unsupported channel layout, NaN/infinite values, values
        outside [0, 1] (EXR) or a missing/invalid physical size.

    Notes
    -----
    PNG values are divided by 255 (8-bit) or 65535 (16-bit). RGB images are reduced to luminance with the
    Rec. 709 weights 0.2126 R + 0.7152 G + 0.0722 B applied to the stored values (no gamma decoding: the file
    value is taken to be the intended transmission). An alpha channel is accepted only if fully opaque.
    """
    from . import imageio

    p = Path(path)
    fmt = imageio.sniff_format(p, "mask file")
    stored: dict = {}
    if fmt == "exr":
        arr, info = imageio.read_exr(p)
        arr = np.asarray(arr, dtype=np.float64)
        stored = info
        t = _to_transmission(arr, info["channels"], str(p))
        bad = ~np.isfinite(t)
        if bad.any():
            raise ValueError(
                f"mask file {str(p)!r}: {int(bad.sum())} pixel(s) are NaN or infinite;"
                " transmission must be finite numbers in [0, 1]"
            )
        lo, hi = float(t.min()), float(t.max())
        if lo < 0.0 or hi > 1.0:
            raise ValueError(
                f"mask file {str(p)!r}: values span [{lo:.4g}, {hi:.4g}] but transmission must lie in [0, 1];"
                " rescale the image (e.g. divide by its maximum) or clip it before loading"
            )
    else:
        arr, info = imageio.read_png(p)
        t = _to_transmission(arr, info["channels"], str(p))
    h, w = t.shape
    if width_m is None:
        width_m = stored.get("width_m")
    if width_m is None:
        hint = ""
        if "dpi" in info and info["dpi"][0] > 0:
            dpi_x = info["dpi"][0]
            hint = f" (the file says {dpi_x:g} dpi, i.e. width_m={w / dpi_x * 0.0254:.6g} m)"
        raise ValueError(f"mask file {str(p)!r} has no physical size: give width_m in metres{hint}")
    if height_m is None:
        same_width = "width_m" in stored and width_m == stored.get("width_m")
        height_m = stored.get("height_m") if same_width else None
    if height_m is None:
        height_m = float(width_m) * h / w
    if invert:
        t = 1.0 - t
    label = name if name is not None else str(stored.get("name") or p.stem)
    meta = dict(stored.get("meta", {})) if isinstance(stored.get("meta"), dict) else {}
    meta.update({"source": str(p), "format": fmt, "invert": bool(invert)})
    if fmt == "png":
        meta["bit_depth"] = info["bit_depth"]
    return Mask(t, width_m, height_m, label, meta)


def save_exr(mask: Mask, path: str | Path) -> Path:
    """Write a mask to OpenEXR (one float32 channel ``Y`` = transmission) with its physical size.

    The header records ``width_m``, ``height_m``, ``units`` ("m"), ``name``, the array convention and the
    mask's ``meta``; :func:`load` reads them back (values exact to float32, ~6e-8).

    Returns
    -------
    Path
        The written file.
    """
    from . import imageio

    metadata = {
        "width_m": mask.width_m,
        "height_m": mask.height_m,
        "units": "m",
        "name": mask.name,
        "quantity": "transmission",
        "convention": "row 0 = top, column 0 = left, as seen from the detector looking out",
        "meta": mask.meta,
    }
    return imageio.write_exr(path, mask.transmission, ("Y",), metadata)


# ============================================================================================ printing
_BAYER8 = np.array(
    [
        [0, 32, 8, 40, 2, 34, 10, 42],
        [48, 16, 56, 24, 50, 18, 58, 26],
        [12, 44, 4, 36, 14, 46, 6, 38],
        [60, 28, 52, 20, 62, 30, 54, 22],
        [3, 35, 11, 43, 1, 33, 9, 41],
        [51, 19, 59, 27, 49, 17, 57, 25],
        [15, 47, 7, 39, 13, 45, 5, 37],
        [63, 31, 55, 23, 61, 29, 53, 21],
    ]
)


def _box_matrix(n_src: int, n_dst: int):
    """(n_dst, n_src) sparse matrix averaging piecewise-constant source cells over each destination cell."""
    from scipy import sparse

    i = np.arange(n_dst)
    lo, hi = i / n_dst, (i + 1) / n_dst
    first = np.floor(lo * n_src).astype(int)
    m = int(np.ceil(n_src / n_dst)) + 2
    k = first[:, None] + np.arange(m)[None, :]
    k_ok = (k >= 0) & (k < n_src)
    kc = np.clip(k, 0, n_src - 1)
    right = np.minimum(hi[:, None], (kc + 1) / n_src)
    overlap = np.clip(right - np.maximum(lo[:, None], kc / n_src), 0.0, None)
    wgt = np.where(k_ok, overlap * n_dst, 0.0)
    wgt /= wgt.sum(axis=1, keepdims=True)
    rows = np.broadcast_to(i[:, None], k.shape)
    mat = sparse.csr_matrix((wgt.ravel(), (rows.ravel(), kc.ravel())), shape=(n_dst, n_src))
    mat.sum_duplicates()
    return mat


def resample(mask: Mask, shape: tuple[int, int]) -> np.ndarray:
    """Area-average the mask (taken as piecewise constant over its texels) onto a regular (H, W) grid.

    Works for up- and down-sampling; a constant mask stays exactly constant and the mean is preserved.
    """
    h, w = _check_resolution(shape)
    ay = _box_matrix(mask.shape[0], h)
    ax = _box_matrix(mask.shape[1], w)
    out = ay @ (ax @ mask.transmission.T).T
    return np.clip(np.asarray(out), 0.0, 1.0)


@dataclass(frozen=True)
class PrintedFilm:
    """What a printer really makes of a mask on transparency film.

    Parameters
    ----------
    t_min : float
        Transmission of fully inked film (printer value 0, black). Typical printed black on transparency film
        passes ~1-5 % of visible light; default 0.02. Measure your own film for quantitative work.
    t_max : float
        Transmission of the unprinted film (printer value 1, white). Clear transparency film typically
        transmits ~85-92 %; default 0.9.
    dpi : float
        Printer addressable resolution [dots per inch]; default 600. Note that a 2 mm mask is only ~47 dots
        across at 600 dpi.
    levels : int or None
        Grey levels the printer reproduces per dot (256 = 8-bit); ``None`` = continuous. Ignored when
        halftoning.
    halftone : {None, "ordered"}
        ``"ordered"``: each dot is either fully inked or clear, grey produced by an 8x8 Bayer ordered dither
        (65 effective levels over 8x8 dots), as laser and many inkjet printers do. Deterministic.
    gamma : float
        Tone response: transmission = t_min + (t_max - t_min) * value**gamma (1 = linear; fit it to a printed
        step wedge if needed).

    Notes
    -----
    The printed transmission spans [t_min, t_max], not [0, 1]: a complementary pair M, 1 - M sums to
    t_min + t_max instead of 1, and the dark parts of a mask still leak light. These defaults are typical
    values only; set them from measurements of your film and printer.
    """

    t_min: float = 0.02
    t_max: float = 0.9
    dpi: float = 600.0
    levels: int | None = 256
    halftone: str | None = None
    gamma: float = 1.0

    def __post_init__(self) -> None:
        if not (0.0 <= self.t_min < self.t_max <= 1.0):
            raise ValueError(
                f"PrintedFilm: need 0 <= t_min < t_max <= 1, got t_min={self.t_min}, t_max={self.t_max}"
            )
        if not (np.isfinite(self.dpi) and self.dpi > 0):
            raise ValueError(f"PrintedFilm: dpi must be a positive number of dots per inch, got {self.dpi!r}")
        if self.levels is not None and (int(self.levels) != self.levels or self.levels < 2):
            raise ValueError(f"PrintedFilm: levels must be an integer >= 2 or None, got {self.levels!r}")
        if self.halftone not in (None, "ordered"):
            raise ValueError(f"PrintedFilm: halftone must be None or 'ordered', got {self.halftone!r}")
        if not (np.isfinite(self.gamma) and self.gamma > 0):
            raise ValueError(f"PrintedFilm: gamma must be positive, got {self.gamma!r}")

    @property
    def dots_per_m(self) -> float:
        """Printer resolution [dots/m]."""
        return self.dpi / 0.0254

    def grid_shape(self, width_m: float, height_m: float) -> tuple[int, int]:
        """(H, W) printer dots covering a ``width_m`` x ``height_m`` [m] mask (rounded, at least 1)."""
        return _dot_grid(width_m, height_m, self.dpi)

    def printer_input(self, mask: Mask) -> np.ndarray:
        """Printer grey values in [0, 1] (0 = full ink) on the dot grid: resampled, quantised or halftoned."""
        v = resample(mask, self.grid_shape(mask.width_m, mask.height_m))
        if self.halftone == "ordered":
            h, w = v.shape
            thr = (np.tile(_BAYER8, (h // 8 + 1, w // 8 + 1))[:h, :w] + 0.5) / 64.0
            return (v >= thr).astype(np.float64)
        if self.levels is not None:
            v = np.rint(v * (self.levels - 1)) / (self.levels - 1)
        return v

    def print(self, mask: Mask) -> Mask:
        """The mask as printed on this film.

        The mask is area-averaged onto the printer's dot grid for its physical size (``round(size * dpi)``
        dots per side; the dot pitch is adjusted by less than half a dot so the print covers exactly the mask
        size), quantised to ``levels`` (or halftoned) and mapped to [t_min, t_max].

        Returns
        -------
        Mask
            Same physical size, one texel per printer dot; ``meta["film"]`` records this film and
            ``meta["printed_from"]`` the source mask name.
        """
        v = self.printer_input(mask)
        t = self.t_min + (self.t_max - self.t_min) * v**self.gamma
        meta = dict(mask.meta)
        meta.update({"film": asdict(self), "printed_from": mask.name})
        return Mask(np.clip(t, 0.0, 1.0), mask.width_m, mask.height_m, f"{mask.name}@film", meta,
                    interpolation="nearest")


def _dot_grid(width_m: float, height_m: float, dpi: float) -> tuple[int, int]:
    if not (np.isfinite(dpi) and dpi > 0):
        raise ValueError(f"dpi must be a positive number of dots per inch, got {dpi!r}")
    per_m = dpi / 0.0254
    h, w = max(1, round(height_m * per_m)), max(1, round(width_m * per_m))
    if h * w > MAX_TEXELS:
        raise ValueError(
            f"print grid {h}x{w} dots is too large (max {MAX_TEXELS}); lower the dpi or the mask size"
        )
    return h, w


def export_print_png(
    mask: Mask,
    path: str | Path,
    dpi: float | None = None,
    film: PrintedFilm | None = None,
    bit_depth: int = 8,
) -> Path:
    """Write a print-ready grayscale PNG of a mask at its physical size.

    Parameters
    ----------
    mask : Mask
        Mask to print; white (1) = no ink = clear, black (0) = full ink.
    path : str or Path
        Output PNG.
    dpi : float, optional
        Printer resolution [dots per inch]; default ``film.dpi`` if a film is given, else 600. The image has
        ``round(width_m * dpi / 0.0254)`` x ``round(height_m * dpi / 0.0254)`` pixels and the PNG records
        the dpi so that printing at 100 % scale reproduces the physical size.
    film : PrintedFilm, optional
        If given, the pixels are the film's printer input (quantised to its levels, or halftoned), i.e.
        exactly what :meth:`PrintedFilm.print` assumes is printed.
    bit_depth : {8, 16}
        PNG bit depth (printer drivers generally use 8).

    Returns
    -------
    Path
        The written file.

    Notes
    -----
    The image is the mask as seen from the detector looking out; mount the film so the print reads the same
    way from the detector side (printing on the far side of the film mirrors it as seen from the scene).
    """
    from . import imageio

    if dpi is None:
        dpi = film.dpi if film is not None else 600.0
    if film is not None:
        if dpi != film.dpi:
            film = replace(film, dpi=float(dpi))
        values = film.printer_input(mask)
    else:
        values = resample(mask, _dot_grid(mask.width_m, mask.height_m, dpi))
    return imageio.write_png(path, values, bit_depth=bit_depth, dpi=dpi)


# ============================================================================================ library & plots
LIBRARY_SINUSOID_PERIOD_M = 0.5e-3  # [m] period of the library sinusoid (omega = 2 pi / 0.5 mm)


def standard_library(resolution: int = DEFAULT_RESOLUTION, size_m: float = DEFAULT_MASK_SIZE_M) -> list[Mask]:
    """The standard masks: four ramps, open aperture, a sinusoid (period 0.5 mm) and a circular ramp."""
    masks = [ramp(k, resolution, size_m) for k in ("x", "1-x", "y", "1-y")]
    masks.append(constant(1.0, resolution, size_m))
    sin = sinusoid(2 * np.pi / LIBRARY_SINUSOID_PERIOD_M, 0.5, 0.5, resolution=resolution, width_m=size_m)
    masks.append(replace(sin, name=f"sinusoid_period{LIBRARY_SINUSOID_PERIOD_M * 1e3:g}mm"))
    masks.append(circular_ramp(resolution=resolution, width_m=size_m))
    return masks


def generate_library(
    out_dir: str | Path, resolution: int = DEFAULT_RESOLUTION, size_m: float = DEFAULT_MASK_SIZE_M
) -> list[Path]:
    """Write :func:`standard_library` as OpenEXR files plus an 8-bit grayscale PNG preview of each.

    Files are ``<name>.exr`` and ``<name>.png`` in ``out_dir`` (created if needed): ``ramp_x``, ``ramp_1-x``,
    ``ramp_y``, ``ramp_1-y``, ``constant_1``, ``sinusoid_period0.5mm``, ``circular_ramp``. Output is
    deterministic (byte-identical for equal arguments).

    Parameters
    ----------
    out_dir : str or Path
        Output directory.
    resolution : int
        Texels per side.
    size_m : float
        Side of the square masks [m].

    Returns
    -------
    list of Path
        Written files, EXR and PNG alternating, in library order.
    """
    from . import imageio

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths: list[Path] = []
    for m in standard_library(resolution, size_m):
        paths.append(save_exr(m, out / f"{m.name}.exr"))
        paths.append(imageio.write_png(out / f"{m.name}.png", m.transmission, bit_depth=8))
    return paths


def plot_mask(mask: Mask, ax=None, cmap: str = "gray", colorbar: bool = True, title: str | None = None):
    """Show a mask with physical axes in millimetres and a transmission colourbar.

    Parameters
    ----------
    mask : Mask
        Mask to draw (row 0 at the top, +y up, as seen from the detector).
    ax : matplotlib.axes.Axes, optional
        Axes to draw into; by default a new Agg-safe ``matplotlib.figure.Figure`` (no pyplot state) is made,
        reachable as ``ax.figure``.
    cmap : str
        Colormap; transmission 0 to 1 maps to its full range.
    colorbar : bool
        Add a colourbar labelled "transmission".
    title : str, optional
        Axes title; defaults to the mask name.

    Returns
    -------
    matplotlib.axes.Axes
    """
    if ax is None:
        from matplotlib.figure import Figure

        ax = Figure(figsize=(4.2, 3.5), layout="constrained").subplots()
    wmm, hmm = mask.width_m * 1e3, mask.height_m * 1e3
    im = ax.imshow(
        mask.transmission, cmap=cmap, vmin=0.0, vmax=1.0, origin="upper", interpolation="nearest",
        extent=(-wmm / 2, wmm / 2, -hmm / 2, hmm / 2),
    )
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_title(mask.name if title is None else title)
    if colorbar:
        ax.figure.colorbar(im, ax=ax, label="transmission")
    return ax
