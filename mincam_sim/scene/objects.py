"""Scene content for the paper's experiments: toy meshes, printed/road textures and object trajectories.

Pure numpy / scipy / trimesh (no Mitsuba, no Dr.Jit), so it can be imported and tested anywhere; the
renderer turns these into Mitsuba shapes and textures.

Conventions
-----------
* Lengths in metres [m], times in seconds [s], angles in radians [rad].
* World frame: the table top is the plane ``z = 0`` with ``+z`` up. Meshes are built (and
  :func:`load_mesh` recentres them) so that they *rest on* ``z = 0`` (``min z == 0``) and their bounding box
  is centred on the origin in ``x`` and ``y``. Vehicles and wind-up toys face ``+x`` (heading 0); a heading
  ``h`` rotates the object counter-clockwise about ``+z`` (seen from above), so it then faces
  ``(cos h, sin h)``.
* Every mesh carries a grayscale diffuse albedo in ``mesh.metadata["albedo"]`` (float in [0, 1]); the
  defaults are bright (0.7-0.9) so the toys contrast with the mid-grey (mean ~0.4) printed background, as a
  brightly coloured toy does with a grey print. ``mesh.metadata["name"]`` holds a short label and
  ``mesh.metadata["n_parts"]`` the number of primitive parts. Note that trimesh does not keep ``metadata``
  through every operation (e.g. export/re-import), so read it right after construction.
* Composite toys (car, wind-up toys) are a *concatenation* of closed (watertight) primitives: boxes,
  cylinders, cones, icospheres and capsules. Parts may interpenetrate, so the union is not a single
  watertight solid, but every part is closed with outward normals (``mesh.split()`` gives the parts back
  because parts share no vertices). That is all a renderer needs for opaque diffuse objects.
* Textures are 2D float64 arrays in [0, 1] (reflectance / displayed intensity), row 0 at the *top*,
  column 0 at the left; they are deterministic functions of the seed / :class:`numpy.random.Generator`.
* Trajectories (:class:`Trajectory`) hold object positions on the table plane ``(x, y)`` [m] and headings
  [rad] at sample times [s].

Experiments (paper §4): §4.1.1 two toy cars race across a finish line ``x = x0`` on a printed background
(:func:`toy_car`, :func:`race_pair`, :func:`printed_background`); §4.2.1 wind-up toys move along random paths
on a static background (:func:`windup_toy`, :func:`random_smooth_path`); §4.3.1 a moving road video for
speed estimation (:func:`road_texture`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import trimesh
from scipy import ndimage

__all__ = [
    "DEFAULT_CAR_ALBEDO",
    "DEFAULT_TOY_ALBEDO",
    "Trajectory",
    "load_mesh",
    "mesh_at",
    "printed_background",
    "race_pair",
    "random_smooth_path",
    "rest_on_ground",
    "road_texture",
    "straight_race",
    "toy_car",
    "windup_toy",
]

DEFAULT_CAR_ALBEDO = 0.8  # bright toy car against a ~0.4 printed background
DEFAULT_TOY_ALBEDO = {"robot": 0.75, "chick": 0.9, "frog": 0.7}
DEFAULT_LOADED_ALBEDO = 0.8

RngLike = np.random.Generator | int | None


def _as_rng(rng: RngLike) -> np.random.Generator:
    """A Generator from a Generator, an int seed or ``None`` (seed 0, so results are reproducible)."""
    if isinstance(rng, np.random.Generator):
        return rng
    if rng is None:
        return np.random.default_rng(0)
    if isinstance(rng, int | np.integer):
        return np.random.default_rng(int(rng))
    raise TypeError(f"rng must be a numpy.random.Generator, an int seed or None, got {type(rng).__name__}")


def _check_positive(**values: float) -> None:
    for name, v in values.items():
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a finite positive number, got {v!r}")


def _check_albedo(albedo: float) -> float:
    a = float(albedo)
    if not (0.0 <= a <= 1.0):
        raise ValueError(f"albedo must be in [0, 1], got {albedo!r}")
    return a


# ----------------------------------------------------------------------------------------------------------
# Meshes
# ----------------------------------------------------------------------------------------------------------


def rest_on_ground(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Translate ``mesh`` in place so its bounding box is centred at x = y = 0 and ``min z == 0``.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Mesh with vertices in metres.

    Returns
    -------
    trimesh.Trimesh
        The same mesh object (modified in place), for chaining.
    """
    lo, hi = mesh.bounds
    shift = np.array([-(lo[0] + hi[0]) / 2.0, -(lo[1] + hi[1]) / 2.0, -lo[2]])
    mesh.apply_translation(shift)
    # Exact zero: remove round-off of the translation on the lowest vertices.
    v = np.array(mesh.vertices)
    v[:, 2] -= v[:, 2].min()
    mesh.vertices = v
    return mesh


def _box(extents: Sequence[float], centre: Sequence[float]) -> trimesh.Trimesh:
    m = trimesh.creation.box(extents=np.asarray(extents, dtype=float))
    m.apply_translation(np.asarray(centre, dtype=float))
    return m


def _cylinder(radius: float, length: float, centre: Sequence[float], axis: str, sections: int = 32):
    """Closed cylinder with its axis along ``axis`` ('x', 'y' or 'z')."""
    m = trimesh.creation.cylinder(radius=radius, height=length, sections=sections)
    if axis == "y":
        m.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    elif axis == "x":
        m.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    m.apply_translation(np.asarray(centre, dtype=float))
    return m


def _sphere(radius: float, centre: Sequence[float], scale: Sequence[float] = (1.0, 1.0, 1.0)):
    """Closed icosphere (optionally an axis-aligned ellipsoid via ``scale``)."""
    m = trimesh.creation.icosphere(subdivisions=2, radius=radius)
    if not np.allclose(scale, 1.0):
        m.apply_transform(np.diag([*np.asarray(scale, dtype=float), 1.0]))
    m.apply_translation(np.asarray(centre, dtype=float))
    return m


def _assemble(parts: list[trimesh.Trimesh], name: str, albedo: float) -> trimesh.Trimesh:
    for p in parts:
        if not p.is_watertight:  # pragma: no cover - guards the primitive constructors
            raise RuntimeError(f"{name}: internal error, a part is not closed")
    mesh = trimesh.util.concatenate(parts)
    rest_on_ground(mesh)
    mesh.metadata = {"name": name, "albedo": _check_albedo(albedo), "n_parts": len(parts)}
    return mesh


def toy_car(
    length_m: float = 0.08,
    width_m: float = 0.04,
    height_m: float = 0.035,
    wheel_radius_m: float = 0.01,
    albedo: float = DEFAULT_CAR_ALBEDO,
) -> trimesh.Trimesh:
    """A toy car: body box + cabin box + four cylinder wheels, facing +x, resting on z = 0.

    The overall bounding box is exactly ``length_m x width_m x height_m``: the body spans the full length,
    the wheels (width ``0.2 * width_m``) are flush with the sides, the cabin top is at ``height_m``.

    Parameters
    ----------
    length_m, width_m, height_m : float
        Overall size along x (forward), y (left) and z (up) [m].
    wheel_radius_m : float
        Wheel radius [m]; wheels touch the ground. Needs ``2 * wheel_radius_m < height_m`` and
        ``length_m > 4.4 * wheel_radius_m`` (wheels fit under the body).
    albedo : float
        Grayscale diffuse albedo in [0, 1], stored in ``mesh.metadata["albedo"]``.

    Returns
    -------
    trimesh.Trimesh
        Concatenation of 6 closed parts (not one watertight solid; each part is closed).
    """
    _check_positive(length_m=length_m, width_m=width_m, height_m=height_m, wheel_radius_m=wheel_radius_m)
    L, W, H, r = float(length_m), float(width_m), float(height_m), float(wheel_radius_m)
    if 2.0 * r >= H:
        raise ValueError(f"wheel diameter {2 * r} m must be smaller than the car height {H} m")
    if L <= 4.4 * r:
        raise ValueError(f"car length {L} m too short for wheels of radius {r} m (need > {4.4 * r} m)")
    z0 = 0.5 * r  # ground clearance of the body
    z1 = z0 + 0.5 * (H - z0)  # top of the body / bottom of the cabin
    body_w = 0.8 * W
    wheel_w = 0.2 * W
    parts = [
        _box((L, body_w, z1 - z0), (0.0, 0.0, (z0 + z1) / 2)),
        _box((0.5 * L, 0.7 * W, H - z1), (-0.1 * L, 0.0, (z1 + H) / 2)),
    ]
    xw = L / 2 - 1.2 * r
    yw = W / 2 - wheel_w / 2
    for sx in (-1, 1):
        for sy in (-1, 1):
            parts.append(_cylinder(r, wheel_w, (sx * xw, sy * yw, r), axis="y"))
    return _assemble(parts, "toy_car", albedo)


def windup_toy(
    kind: Literal["robot", "chick", "frog"] = "robot",
    size_m: float = 0.05,
    albedo: float | None = None,
) -> trimesh.Trimesh:
    """A simple wind-up toy (paper §4.2.1) built from closed primitives, facing +x, resting on z = 0.

    Parameters
    ----------
    kind : {"robot", "chick", "frog"}
        ``"robot"``: box legs, torso, head, capsule arms and a ball antenna (tall);
        ``"chick"``: sphere body and head, cone beak, cylinder feet (round);
        ``"frog"``: flattened ellipsoid body, eye spheres, box legs (low and wide).
    size_m : float
        Largest bounding-box dimension of the toy [m] (scaled exactly to it).
    albedo : float, optional
        Grayscale diffuse albedo in [0, 1]; default :data:`DEFAULT_TOY_ALBEDO` ``[kind]``.

    Returns
    -------
    trimesh.Trimesh
        Concatenation of closed parts, ``metadata`` with ``name``, ``albedo``, ``n_parts``.
    """
    _check_positive(size_m=size_m)
    if kind == "robot":  # unit-height design, then scaled
        parts = [
            _box((0.18, 0.12, 0.3), (0.0, -0.1, 0.15)),  # legs
            _box((0.18, 0.12, 0.3), (0.0, 0.1, 0.15)),
            _box((0.3, 0.4, 0.35), (0.0, 0.0, 0.475)),  # torso
            _box((0.25, 0.28, 0.2), (0.0, 0.0, 0.75)),  # head
            trimesh.creation.capsule(height=0.2, radius=0.05),  # arms (axis z)
            trimesh.creation.capsule(height=0.2, radius=0.05),
            _sphere(0.05, (0.0, 0.0, 0.9)),  # antenna ball
            _cylinder(0.015, 0.06, (0.0, 0.0, 0.86), axis="z"),  # antenna stem
        ]
        parts[4].apply_translation((0.05, -0.26, 0.45))
        parts[5].apply_translation((0.05, 0.26, 0.45))
    elif kind == "chick":
        parts = [
            _sphere(0.35, (0.0, 0.0, 0.42)),  # body
            _sphere(0.2, (0.2, 0.0, 0.8)),  # head, forward
            trimesh.creation.cone(radius=0.06, height=0.15),  # beak (axis z -> +x below)
            _cylinder(0.05, 0.08, (0.05, -0.12, 0.04), axis="z"),  # feet
            _cylinder(0.05, 0.08, (0.05, 0.12, 0.04), axis="z"),
        ]
        parts[2].apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
        parts[2].apply_translation((0.37, 0.0, 0.8))
    elif kind == "frog":
        parts = [
            _sphere(0.5, (0.0, 0.0, 0.25), scale=(1.0, 0.8, 0.4)),  # flattened body
            _sphere(0.1, (0.3, -0.15, 0.42)),  # eyes
            _sphere(0.1, (0.3, 0.15, 0.42)),
            _box((0.35, 0.15, 0.1), (-0.3, -0.42, 0.05)),  # hind legs
            _box((0.35, 0.15, 0.1), (-0.3, 0.42, 0.05)),
            _box((0.15, 0.1, 0.08), (0.3, -0.4, 0.04)),  # front legs
            _box((0.15, 0.1, 0.08), (0.3, 0.4, 0.04)),
        ]
    else:
        raise ValueError(f"unknown wind-up toy kind {kind!r}; choose 'robot', 'chick' or 'frog'")
    if albedo is None:
        albedo = DEFAULT_TOY_ALBEDO[kind]
    mesh = _assemble(parts, f"windup_{kind}", albedo)
    meta = mesh.metadata
    mesh.apply_scale(float(size_m) / float(np.max(mesh.extents)))
    rest_on_ground(mesh)
    mesh.metadata = meta
    return mesh


def load_mesh(
    path: str | Path,
    scale: float = 1.0,
    albedo: float = DEFAULT_LOADED_ALBEDO,
    up_axis: Literal["z", "y"] = "z",
) -> trimesh.Trimesh:
    """Load a mesh file (OBJ, PLY, GLB/GLTF, STL, ... anything trimesh reads) as one mesh resting on z = 0.

    A multi-object file (a :class:`trimesh.Scene`) is flattened, with its scene-graph transforms applied,
    into a single mesh. The result is scaled by ``scale``, then recentred (bounding box centred at
    x = y = 0, ``min z == 0``).

    Parameters
    ----------
    path : str or pathlib.Path
        Mesh file.
    scale : float
        Uniform factor from file units to metres (e.g. 0.001 for a file in millimetres).
    albedo : float
        Grayscale diffuse albedo in [0, 1] stored in ``mesh.metadata["albedo"]``.
    up_axis : {"z", "y"}
        Up axis of the file; ``"y"`` (the glTF convention) rotates +90 degrees about x so +y becomes +z.

    Returns
    -------
    trimesh.Trimesh

    Raises
    ------
    FileNotFoundError
        The path does not exist or is not a file.
    ValueError
        The file is empty (0 bytes), cannot be parsed, or contains no triangles; or bad ``scale``/``up_axis``.
    """
    _check_positive(scale=scale)
    albedo = _check_albedo(albedo)
    if up_axis not in ("z", "y"):
        raise ValueError(f"up_axis must be 'z' or 'y', got {up_axis!r}")
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"mesh file not found: {p}")
    if not p.is_file():
        raise FileNotFoundError(f"mesh path is not a regular file: {p}")
    if p.stat().st_size == 0:
        raise ValueError(f"mesh file is empty (0 bytes): {p}")
    try:
        loaded = trimesh.load(p, process=True)
    except Exception as exc:  # trimesh raises many types for unknown / corrupt formats
        raise ValueError(f"could not read mesh file {p}: {type(exc).__name__}: {exc}") from exc
    if isinstance(loaded, trimesh.Scene):
        if len(loaded.geometry) == 0:
            raise ValueError(f"mesh file contains no geometry: {p}")
        meshes = [g for g in loaded.dump(concatenate=False) if isinstance(g, trimesh.Trimesh)]
        mesh = trimesh.util.concatenate(meshes) if meshes else None
    else:
        mesh = loaded
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        kind = type(loaded).__name__
        raise ValueError(f"mesh file contains no triangles (loaded a {kind}): {p}")
    mesh = trimesh.Trimesh(vertices=np.array(mesh.vertices), faces=np.array(mesh.faces), process=False)
    if up_axis == "y":
        mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    mesh.apply_scale(float(scale))
    rest_on_ground(mesh)
    mesh.metadata = {"name": p.stem, "albedo": albedo, "n_parts": int(mesh.body_count), "source": str(p)}
    return mesh


def mesh_at(
    mesh: trimesh.Trimesh | np.ndarray, position_m: Sequence[float] | np.ndarray, heading_rad: float
) -> np.ndarray:
    """Vertices of ``mesh`` placed at ``position_m`` with heading ``heading_rad`` (rigid transform).

    The vertices are rotated by ``heading_rad`` about +z (counter-clockwise seen from above, so the object's
    +x front ends up facing ``(cos h, sin h)``), then translated by ``(x, y, 0)`` (or ``(x, y, z)`` when
    ``position_m`` has 3 entries). Use it for per-frame vertex updates; faces are unchanged.

    Parameters
    ----------
    mesh : trimesh.Trimesh or (n, 3) ndarray
        Mesh (or its vertices) in the object frame [m].
    position_m : (2,) or (3,) array_like
        Position on the table plane [m] (optional z offset).
    heading_rad : float
        Heading [rad].

    Returns
    -------
    (n, 3) ndarray of float64
        Transformed vertices [m]; the input is not modified.
    """
    v = np.asarray(mesh.vertices if isinstance(mesh, trimesh.Trimesh) else mesh, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must have shape (n, 3), got {v.shape}")
    pos = np.asarray(position_m, dtype=np.float64).ravel()
    if pos.size not in (2, 3):
        raise ValueError(f"position_m must have 2 or 3 entries, got {pos.size}")
    t = np.zeros(3)
    t[: pos.size] = pos
    c, s = np.cos(heading_rad), np.sin(heading_rad)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return v @ rot.T + t


# ----------------------------------------------------------------------------------------------------------
# Textures
# ----------------------------------------------------------------------------------------------------------


def _smooth_noise(rng: np.random.Generator, shape: tuple[int, int], sigma_px: float) -> np.ndarray:
    """Zero-mean, unit-std Gaussian-filtered white noise (periodic boundary)."""
    n = rng.standard_normal(shape)
    if sigma_px > 0:
        n = ndimage.gaussian_filter(n, sigma_px, mode="wrap")
    n -= n.mean()
    std = n.std()
    return n / std if std > 0 else n


def _check_shape(shape: Sequence[int]) -> tuple[int, int]:
    if len(shape) != 2 or any(int(s) != s or s < 2 for s in shape):
        raise ValueError(f"shape must be two integers >= 2 (rows, cols), got {tuple(shape)!r}")
    return int(shape[0]), int(shape[1])


def printed_background(
    shape: tuple[int, int] = (512, 512),
    rng: RngLike = None,
    kind: Literal["paper", "checker", "noise"] = "paper",
    mean: float = 0.4,
) -> np.ndarray:
    """A printed tabletop background texture (paper §4.1.1/§4.2.1), values in [0, 1], row 0 at the top.

    Parameters
    ----------
    shape : (int, int)
        (rows, cols) in texels.
    rng : numpy.random.Generator, int or None
        Randomness source (an int is a seed; ``None`` means seed 0). Same seed, same texture.
    kind : {"paper", "checker", "noise"}
        ``"paper"``: low-contrast multi-scale smooth noise (std ~0.06) plus a faint printed grid every 64
        texels; ``"checker"``: soft-edged checkerboard (squares of 1/8 of the short side, +-0.1 around the
        mean) with slight noise; ``"noise"``: higher-contrast band-limited noise (sigma 4 texels, std 0.12).
    mean : float
        Target mean reflectance (before clipping to [0, 1]).

    Returns
    -------
    (rows, cols) ndarray of float64
    """
    rows, cols = _check_shape(shape)
    if not (0.0 <= mean <= 1.0):
        raise ValueError(f"mean must be in [0, 1], got {mean!r}")
    g = _as_rng(rng)
    if kind == "paper":
        tex = 0.6 * _smooth_noise(g, (rows, cols), 32.0)
        tex += 0.3 * _smooth_noise(g, (rows, cols), 8.0) + 0.1 * _smooth_noise(g, (rows, cols), 1.5)
        tex *= 0.06 / tex.std()
        rr, cc = np.mgrid[0:rows, 0:cols]
        grid = ((rr % 64) < 2) | ((cc % 64) < 2)
        tex -= 0.04 * ndimage.gaussian_filter(grid.astype(float), 0.7, mode="wrap")
    elif kind == "checker":
        sq = max(2, min(rows, cols) // 8)
        rr, cc = np.mgrid[0:rows, 0:cols]
        chk = (((rr // sq) + (cc // sq)) % 2).astype(float) * 2.0 - 1.0
        tex = 0.1 * ndimage.gaussian_filter(chk, 1.0, mode="nearest") + 0.02 * _smooth_noise(g, (rows, cols), 2.0)
    elif kind == "noise":
        tex = 0.12 * _smooth_noise(g, (rows, cols), 4.0)
    else:
        raise ValueError(f"unknown background kind {kind!r}; choose 'paper', 'checker' or 'noise'")
    tex += mean - tex.mean()
    return np.clip(tex, 0.0, 1.0)


def road_texture(
    shape: tuple[int, int] = (256, 4096),
    rng: RngLike = None,
    base: float = 0.3,
    grain_std: float = 0.08,
    patch_std: float = 0.04,
    dash_period_px: int = 256,
    dash_fraction: float = 0.5,
    marking_width_px: int = 8,
    marking_value: float = 0.9,
) -> np.ndarray:
    """An asphalt-like road texture for the speed-estimation video (paper §4.3.1), values in [0, 1].

    The long axis is x (columns): the video is made of crop windows shifted along the columns. Content:
    fine grain (white noise blurred by sigma 0.7 texel, std ``grain_std``, broadband along x), sparse bright
    aggregate specks, larger low-contrast patches (sigma 12 texels, std ``patch_std``), a dashed centre
    lane marking along x (period ``dash_period_px``, randomly phased) and two continuous edge lines.

    Parameters
    ----------
    shape : (int, int)
        (rows, cols) in texels; cols is the direction of motion.
    rng : numpy.random.Generator, int or None
        Randomness source (an int is a seed; ``None`` means seed 0).
    base : float
        Mean asphalt reflectance.
    grain_std, patch_std : float
        Standard deviations of the fine grain and of the large patches.
    dash_period_px : int
        Period of the centre dashes along x [texels].
    dash_fraction : float
        Painted fraction of each dash period, in (0, 1].
    marking_width_px : int
        Width of the lane markings across the road [texels].
    marking_value : float
        Reflectance of the paint.

    Returns
    -------
    (rows, cols) ndarray of float64
    """
    rows, cols = _check_shape(shape)
    if not (0.0 < dash_fraction <= 1.0):
        raise ValueError(f"dash_fraction must be in (0, 1], got {dash_fraction!r}")
    _check_positive(dash_period_px=dash_period_px, marking_width_px=marking_width_px)
    g = _as_rng(rng)
    tex = base + grain_std * _smooth_noise(g, (rows, cols), 0.7)
    tex += patch_std * _smooth_noise(g, (rows, cols), 12.0)
    specks = g.random((rows, cols)) < 0.01
    tex[specks] += 0.25
    paint = np.zeros((rows, cols))
    half = marking_width_px / 2.0
    r = np.arange(rows)[:, None]
    c = np.arange(cols)[None, :]
    phase = g.integers(0, dash_period_px)
    centre = (np.abs(r - (rows - 1) / 2.0) < half) & (((c + phase) % dash_period_px) < dash_fraction * dash_period_px)
    edge_off = max(rows // 10, marking_width_px)
    edges = (np.abs(r - edge_off) < half / 2) | (np.abs(r - (rows - 1 - edge_off)) < half / 2)
    paint[np.broadcast_to(centre | edges, (rows, cols))] = 1.0
    paint = ndimage.gaussian_filter(paint, 0.5, mode="wrap")
    # Worn paint: slight texture on the markings.
    tex = tex * (1.0 - paint) + paint * (marking_value + 0.03 * _smooth_noise(g, (rows, cols), 1.0))
    return np.clip(tex, 0.0, 1.0)


# ----------------------------------------------------------------------------------------------------------
# Trajectories
# ----------------------------------------------------------------------------------------------------------


def _wrap(angle: np.ndarray | float) -> np.ndarray:
    """Angle(s) wrapped to (-pi, pi]."""
    a = np.asarray(angle, dtype=np.float64)
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Object poses on the table plane at sample times.

    Parameters
    ----------
    times_s : (n,) array_like
        Strictly increasing sample times [s].
    positions_m : (n, 2) array_like
        ``(x, y)`` positions on the table plane [m] (object bounding-box centre).
    headings_rad : (n,) array_like
        Headings [rad]; 0 faces +x, counter-clockwise positive. Stored wrapped to (-pi, pi].

    Notes
    -----
    Velocities (:meth:`velocities_m_s`) are forward differences: sample ``i`` holds the velocity over
    ``[t_i, t_{i+1}]`` and the last sample repeats the previous one. The trajectory generators here set
    ``headings_rad[i]`` to the direction of that same segment, so heading and motion agree exactly.
    """

    times_s: np.ndarray
    positions_m: np.ndarray
    headings_rad: np.ndarray

    def __post_init__(self) -> None:
        t = np.array(self.times_s, dtype=np.float64).ravel()
        p = np.array(self.positions_m, dtype=np.float64)
        h = _wrap(np.array(self.headings_rad, dtype=np.float64).ravel())
        if t.size < 1:
            raise ValueError("a trajectory needs at least one sample")
        if p.shape != (t.size, 2):
            raise ValueError(f"positions_m must have shape ({t.size}, 2), got {p.shape}")
        if h.shape != (t.size,):
            raise ValueError(f"headings_rad must have shape ({t.size},), got {h.shape}")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(p)) and np.all(np.isfinite(h))):
            raise ValueError("trajectory arrays must be finite")
        if np.any(np.diff(t) <= 0):
            raise ValueError("times_s must be strictly increasing")
        for name, arr in (("times_s", t), ("positions_m", p), ("headings_rad", h)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    def __len__(self) -> int:
        return int(self.times_s.size)

    @property
    def duration_s(self) -> float:
        """Time between the first and last sample [s]."""
        return float(self.times_s[-1] - self.times_s[0])

    def velocities_m_s(self) -> np.ndarray:
        """Forward-difference velocities, shape (n, 2) [m/s] (last row repeats the previous one)."""
        if len(self) < 2:
            return np.zeros((len(self), 2))
        v = np.diff(self.positions_m, axis=0) / np.diff(self.times_s)[:, None]
        return np.vstack([v, v[-1:]])

    def speeds_m_s(self) -> np.ndarray:
        """Speeds (norms of :meth:`velocities_m_s`), shape (n,) [m/s]."""
        return np.linalg.norm(self.velocities_m_s(), axis=1)

    def at(self, t_s: float | np.ndarray) -> tuple[np.ndarray, np.ndarray | float]:
        """Pose at time(s) ``t_s`` by linear interpolation (clamped to the first/last sample outside).

        Headings are interpolated along the shortest arc (on the unwrapped angle).

        Parameters
        ----------
        t_s : float or array_like
            Query time(s) [s].

        Returns
        -------
        positions : (2,) or (..., 2) ndarray
            ``(x, y)`` [m].
        headings : float or (...) ndarray
            Heading(s) [rad] in (-pi, pi].
        """
        tq = np.asarray(t_s, dtype=np.float64)
        x = np.interp(tq, self.times_s, self.positions_m[:, 0])
        y = np.interp(tq, self.times_s, self.positions_m[:, 1])
        h = _wrap(np.interp(tq, self.times_s, np.unwrap(self.headings_rad)))
        pos = np.stack([x, y], axis=-1)
        return (pos, float(h)) if tq.ndim == 0 else (pos, h)

    def line_crossings(self, line_x_m: float) -> list[tuple[float, float]]:
        """Where the path crosses the vertical line ``x = line_x_m`` (e.g. a finish line).

        Returns
        -------
        list of (time_s, y_m)
            Crossing time [s] and position along the line [m], linearly interpolated, in time order. A
            sample lying exactly on the line counts once, when the sign of ``x - line_x_m`` changes across it.
        """
        d = self.positions_m[:, 0] - float(line_x_m)
        out: list[tuple[float, float]] = []
        for i in range(len(self) - 1):
            a, b = d[i], d[i + 1]
            if (a < 0 <= b) or (a > 0 >= b):
                f = a / (a - b)
                t = self.times_s[i] + f * (self.times_s[i + 1] - self.times_s[i])
                y = self.positions_m[i, 1] + f * (self.positions_m[i + 1, 1] - self.positions_m[i, 1])
                out.append((float(t), float(y)))
        return out


def straight_race(
    start_m: float | Sequence[float],
    end_m: float | Sequence[float],
    duration_s: float,
    n_frames: int,
    lateral_offset_m: float = 0.0,
    start_time_s: float = 0.0,
) -> Trajectory:
    """A constant-speed straight run, e.g. a toy car in its lane.

    Parameters
    ----------
    start_m, end_m : float or (2,) array_like
        Scalars: start and end ``x`` [m] of a run along the x axis, in the lane ``y = lateral_offset_m``
        (so it crosses a finish line ``x = x0`` between them). 2-vectors: start and end points ``(x, y)``
        [m]; the path is then shifted by ``lateral_offset_m`` to the left of the direction of travel.
    duration_s : float
        Time from start to end [s].
    n_frames : int
        Number of samples (>= 2), evenly spaced from ``start_time_s`` to ``start_time_s + duration_s``.
    lateral_offset_m : float
        Lane offset [m] (see ``start_m``).
    start_time_s : float
        Time of the first sample [s].

    Returns
    -------
    Trajectory
        Headings all equal to the direction of travel.
    """
    _check_positive(duration_s=duration_s)
    if int(n_frames) != n_frames or n_frames < 2:
        raise ValueError(f"n_frames must be an integer >= 2, got {n_frames!r}")
    s = np.asarray(start_m, dtype=np.float64)
    e = np.asarray(end_m, dtype=np.float64)
    if s.ndim == 0 and e.ndim == 0:
        s = np.array([float(s), float(lateral_offset_m)])
        e = np.array([float(e), float(lateral_offset_m)])
        offset = np.zeros(2)
    elif s.shape == (2,) and e.shape == (2,):
        offset = None
    else:
        raise ValueError("start_m and end_m must both be scalars (x) or both be (x, y) pairs")
    d = e - s
    length = float(np.linalg.norm(d))
    if length == 0:
        raise ValueError("start and end positions coincide; a race needs a non-zero distance")
    u = d / length
    if offset is None:
        offset = float(lateral_offset_m) * np.array([-u[1], u[0]])
    f = np.linspace(0.0, 1.0, int(n_frames))
    pos = s[None, :] + f[:, None] * d[None, :] + offset[None, :]
    times = float(start_time_s) + f * float(duration_s)
    heading = np.full(int(n_frames), np.arctan2(u[1], u[0]))
    return Trajectory(times, pos, heading)


def race_pair(
    finish_line_x_m: float = 0.0,
    lanes_y_m: tuple[float, float] = (-0.08, 0.08),
    speeds_m_s: tuple[float, float] = (0.12, 0.09),
    start_distance_m: float = 0.2,
    overrun_m: float = 0.1,
    frame_rate_hz: float = 30.0,
) -> tuple[Trajectory, Trajectory]:
    """Two toy cars racing in parallel lanes across the finish line ``x = finish_line_x_m`` (paper §4.1.1).

    Both cars start ``start_distance_m`` before the line (moving +x) at t = 0 and keep constant speeds;
    they cross the line at different times ``start_distance_m / speed`` and different positions
    ``lanes_y_m`` along it. Both trajectories share one frame clock, long enough for the slower car to get
    ``overrun_m`` past the line.

    Parameters
    ----------
    finish_line_x_m : float
        x of the finish line (the virtual boundary) [m].
    lanes_y_m : (float, float)
        Lane positions y of the two cars [m].
    speeds_m_s : (float, float)
        Constant speeds [m/s].
    start_distance_m, overrun_m : float
        Distance before the line at t = 0, and distance the slower car runs past it at the end [m].
    frame_rate_hz : float
        Sampling rate [Hz].

    Returns
    -------
    (Trajectory, Trajectory)
    """
    _check_positive(
        start_distance_m=start_distance_m, overrun_m=overrun_m, frame_rate_hz=frame_rate_hz,
        speed_0=speeds_m_s[0], speed_1=speeds_m_s[1],
    )
    duration = (start_distance_m + overrun_m) / min(speeds_m_s)
    n = int(np.ceil(duration * frame_rate_hz)) + 1
    duration = (n - 1) / frame_rate_hz
    x0 = float(finish_line_x_m) - float(start_distance_m)
    cars = tuple(
        straight_race(x0, x0 + v * duration, duration, n, lateral_offset_m=float(y))
        for v, y in zip(speeds_m_s, lanes_y_m, strict=True)
    )
    return cars[0], cars[1]


def random_smooth_path(
    rng: RngLike,
    n_frames: int,
    dt_s: float,
    bounds_m: tuple[tuple[float, float], tuple[float, float]] = ((-0.2, 0.2), (-0.2, 0.2)),
    speed_m_s: float = 0.05,
    turn_rate_std_rad_s: float = 1.5,
    correlation_time_s: float = 0.5,
    start_m: Sequence[float] | None = None,
    heading0_rad: float | None = None,
) -> Trajectory:
    """A smooth random walk at constant speed, like a wind-up toy (paper §4.2.1).

    The turn rate is white noise low-pass filtered by a Gaussian of standard deviation
    ``correlation_time_s`` and scaled to standard deviation ``turn_rate_std_rad_s``; the heading integrates
    it and every step moves exactly ``speed_m_s * dt_s`` along the current heading. A step that would leave
    ``bounds_m`` is reflected off the wall (heading mirrored: ``h -> pi - h`` at an x wall, ``h -> -h`` at a
    y wall) and retaken from the current point, so positions stay inside the bounds, the speed is exact and
    ``headings_rad[i]`` is the direction of the step from sample ``i`` to ``i + 1`` (the last sample keeps
    the last step's heading).

    Parameters
    ----------
    rng : numpy.random.Generator, int or None
        Randomness source (an int is a seed; ``None`` means seed 0).
    n_frames : int
        Number of samples (>= 2), at times ``i * dt_s``.
    dt_s : float
        Time step [s].
    bounds_m : ((xmin, xmax), (ymin, ymax))
        Region the path stays in [m]; each side must be longer than two steps.
    speed_m_s : float
        Constant speed [m/s] (>= 0).
    turn_rate_std_rad_s : float
        Standard deviation of the turn rate [rad/s].
    correlation_time_s : float
        Smoothing time scale of the turn rate [s].
    start_m : (2,) array_like, optional
        Start position [m]; default uniform in the central half of the bounds.
    heading0_rad : float, optional
        Initial heading [rad]; default uniform in [-pi, pi).

    Returns
    -------
    Trajectory
    """
    g = _as_rng(rng)
    if int(n_frames) != n_frames or n_frames < 2:
        raise ValueError(f"n_frames must be an integer >= 2, got {n_frames!r}")
    n = int(n_frames)
    _check_positive(dt_s=dt_s, correlation_time_s=correlation_time_s)
    if not (np.isfinite(speed_m_s) and speed_m_s >= 0):
        raise ValueError(f"speed_m_s must be finite and >= 0, got {speed_m_s!r}")
    b = np.asarray(bounds_m, dtype=np.float64)
    if b.shape != (2, 2) or np.any(b[:, 1] <= b[:, 0]):
        raise ValueError(f"bounds_m must be ((xmin, xmax), (ymin, ymax)) with min < max, got {bounds_m!r}")
    step = float(speed_m_s) * float(dt_s)
    if 2.0 * step >= np.min(b[:, 1] - b[:, 0]):
        raise ValueError(f"step speed*dt = {step} m is too large for bounds {bounds_m!r}")
    lo, hi = b[:, 0], b[:, 1]
    if start_m is None:
        p = lo + (hi - lo) * (0.25 + 0.5 * g.random(2))
    else:
        p = np.asarray(start_m, dtype=np.float64).reshape(2)
        if np.any(p < lo) or np.any(p > hi):
            raise ValueError(f"start_m {p} is outside bounds {bounds_m!r}")
    h = float(g.uniform(-np.pi, np.pi)) if heading0_rad is None else float(heading0_rad)
    omega = ndimage.gaussian_filter1d(g.standard_normal(n), correlation_time_s / dt_s, mode="reflect")
    std = omega.std()
    omega = omega / std * turn_rate_std_rad_s if std > 0 else np.zeros(n)

    pos = np.empty((n, 2))
    head = np.empty(n)
    pos[0] = p
    for i in range(n - 1):
        for _ in range(4):
            q = p + step * np.array([np.cos(h), np.sin(h)])
            if np.all(q >= lo) and np.all(q <= hi):
                break
            if q[0] < lo[0] or q[0] > hi[0]:
                h = np.pi - h
            if q[1] < lo[1] or q[1] > hi[1]:
                h = -h
        else:  # pragma: no cover - corner case: head to the centre
            c = (lo + hi) / 2 - p
            h = float(np.arctan2(c[1], c[0]))
            q = p + step * np.array([np.cos(h), np.sin(h)])
        head[i] = h
        pos[i + 1] = q
        p = q
        h = h + omega[i] * dt_s
    head[-1] = head[-2]
    return Trajectory(np.arange(n) * float(dt_s), pos, head)
