"""Flat emissive displays and the frames shown on them (pure numpy).

A screen is a rectangle of ``width_m`` x ``height_m`` whose front faces along ``pose.forward``; it emits only
from its front. Frames are arrays of radiance [W m^-2 sr^-1] of shape ``(rows, cols) = (resolution[1],
resolution[0])`` in image convention: row 0 at the top, column 0 on the left, as seen by a viewer in front of
the screen. Screen coordinates ``(x_m, y_m)`` [m] are centred on the screen, +x to the viewer's right, +y up.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np

from mincam_sim import paper
from mincam_sim.errors import InputError, is_finite_real
from mincam_sim.model.geometry import Pose, clip_polygon_halfspace

INCH_M = 0.0254  # [m]


def diagonal_to_size(diagonal_in: float, aspect: tuple[int, int] = (16, 9)) -> tuple[float, float]:
    """(width, height) [m] of a display of the given diagonal [inch] and aspect ratio."""
    a, b = aspect
    diag = diagonal_in * INCH_M
    return diag * a / np.hypot(a, b), diag * b / np.hypot(a, b)


PAPER_SCREEN_SIZE_M = diagonal_to_size(paper.SCREEN_DIAGONAL_IN, paper.SCREEN_ASPECT)  # the 50" 16:9 display
DEFAULT_SCREEN_RESOLUTION = (256, 144)  # display texels (columns, rows)
DEFAULT_DISTANCE_M = paper.CALIBRATION_DEPTH_M  # [m]


@dataclass(frozen=True)
class Screen:
    """A flat emissive display.

    Parameters
    ----------
    width_m, height_m : float
        Physical size [m].
    resolution : (int, int)
        Pixels (columns, rows) of the display, i.e. texels of the emission texture.
    pose : Pose
        Screen centre and facing direction (forward = direction of emission), up = screen up.
        Default: 0.5 m in front of a mincam at the origin that looks along -z.
    """

    width_m: float = PAPER_SCREEN_SIZE_M[0]
    height_m: float = PAPER_SCREEN_SIZE_M[1]
    resolution: tuple[int, int] = DEFAULT_SCREEN_RESOLUTION
    pose: Pose = field(default_factory=lambda: Pose((0.0, 0.0, -DEFAULT_DISTANCE_M), (0.0, 0.0, 1.0)))

    def __post_init__(self) -> None:
        for key in ("width_m", "height_m"):
            v = getattr(self, key)
            if not (is_finite_real(v) and v > 0):
                raise InputError(f"screen {key} must be a positive size in metres, got {v!r}")
        res = tuple(self.resolution)
        if len(res) != 2 or any(int(r) != r or r < 1 for r in res):
            raise InputError(f"screen resolution must be two positive integers (columns, rows), got {res!r}")
        if res[0] * res[1] > 4096 * 4096:
            raise InputError(f"screen resolution {res} is too large (max 4096 x 4096 texels)")
        object.__setattr__(self, "resolution", (int(res[0]), int(res[1])))

    @property
    def shape(self) -> tuple[int, int]:
        """Frame shape (rows, cols)."""
        return self.resolution[1], self.resolution[0]

    @property
    def texel_size_m(self) -> tuple[float, float]:
        """(width, height) of one display pixel [m]."""
        return self.width_m / self.resolution[0], self.height_m / self.resolution[1]

    @property
    def texel_area_m2(self) -> float:
        w, h = self.texel_size_m
        return w * h

    def texel_centers_m(self) -> tuple[np.ndarray, np.ndarray]:
        """Screen coordinates (x_m, y_m) [m] of every texel centre, each of frame shape."""
        cols, rows = self.resolution
        x = ((np.arange(cols) + 0.5) / cols - 0.5) * self.width_m
        y = (0.5 - (np.arange(rows) + 0.5) / rows) * self.height_m
        return np.meshgrid(x, y)

    def to_world(self, x_m, y_m) -> np.ndarray:
        """World points [m] of screen coordinates (x right, y up as seen by a viewer in front)."""
        left, up, _ = self.pose.axes()
        # Local +x of a pose is cross(up, forward); for a screen facing the viewer that is the viewer's right.
        x_m, y_m = np.broadcast_arrays(np.asarray(x_m, float), np.asarray(y_m, float))
        return np.asarray(self.pose.position_m) + x_m[..., None] * left + y_m[..., None] * up

    def from_world(self, points_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Screen coordinates (x_m, y_m) of world points projected on the screen plane."""
        local = self.pose.to_local(points_m)
        return local[..., 0], local[..., 1]

    def blank(self) -> np.ndarray:
        """An all-black frame."""
        return np.zeros(self.shape)

    def check_frame(self, frame: np.ndarray, name: str = "frame") -> np.ndarray:
        """Validate a frame (shape, finite, >= 0) and return it as float64."""
        f = np.asarray(frame, dtype=np.float64)
        if f.shape != self.shape:
            raise InputError(f"{name} has shape {f.shape} but this screen's frames are {self.shape} (rows, cols)")
        if not np.all(np.isfinite(f)):
            raise InputError(f"{name} contains NaN or infinite radiance; frames must be finite and >= 0")
        if f.min() < 0:
            raise InputError(f"{name} has negative radiance ({f.min():.3g}); displays emit >= 0 W/m^2/sr")
        if f.max() > np.finfo(np.float32).max:  # a texture holds 32-bit floats: it became inf, its sigma NaN
            raise InputError(f"{name} has radiance {f.max():.3g}, beyond a 32-bit float's largest "
                             f"({np.finfo(np.float32).max:.3g}) that the renderer holds; scale the frames down")
        return f


def coverage(screen: Screen, x0_m: float, x1_m: float, y0_m: float, y1_m: float) -> np.ndarray:
    """Fraction of each display pixel covered by the rectangle [x0, x1] x [y0, y1] (screen coords, m)."""
    cols, rows = screen.resolution
    tw, th = screen.texel_size_m
    xe = (np.arange(cols + 1) / cols - 0.5) * screen.width_m
    ye = (0.5 - np.arange(rows + 1) / rows) * screen.height_m  # top edge first
    fx = np.clip(np.minimum(xe[1:], x1_m) - np.maximum(xe[:-1], x0_m), 0, None) / tw
    fy = np.clip(np.minimum(ye[:-1], y1_m) - np.maximum(ye[1:], y0_m), 0, None) / th
    return np.outer(fy, fx)


def white_square(
    screen: Screen, center_m: tuple[float, float], size_m: float, radiance: float = 1.0
) -> np.ndarray:
    """Frame with a white square of side ``size_m`` centred at ``center_m`` (screen coords [m]) on black.

    Pixels partly covered are lit in proportion to their covered area (box filter); squares aligned with
    the pixel grid are exact.
    """
    if not (np.isfinite(size_m) and size_m > 0):
        raise InputError(f"square size_m must be > 0 metres, got {size_m!r}")
    cx, cy = center_m
    return radiance * coverage(screen, cx - size_m / 2, cx + size_m / 2, cy - size_m / 2, cy + size_m / 2)


def vertical_line(screen: Screen, x_m: float, width_m: float, radiance: float = 1.0) -> np.ndarray:
    """Frame with a full-height bright vertical band of ``width_m`` centred at ``x_m``."""
    return radiance * coverage(screen, x_m - width_m / 2, x_m + width_m / 2, -screen.height_m, screen.height_m)


@dataclass(frozen=True)
class Sweep:
    """Positions [m] (n, 2) of a white square in screen coordinates, with its side and radiance."""

    positions_m: np.ndarray
    size_m: float
    radiance: float = 1.0

    def __post_init__(self) -> None:
        try:
            positions = np.asarray(self.positions_m, dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(f"Sweep.positions_m must be (n, 2) positions [m], got {self.positions_m!r:.60}") from None
        if positions.ndim != 2 or positions.shape[1] != 2 or not np.all(np.isfinite(positions)):
            raise InputError(f"Sweep.positions_m must be finite (n, 2) positions [m], got shape {positions.shape}"
                             + ("" if np.all(np.isfinite(positions)) else " holding NaN or infinite values"))
        for key, rule, ok in (("size_m", "a positive size [m]", lambda v: v > 0),
                              ("radiance", "a radiance >= 0 W m^-2 sr^-1", lambda v: v >= 0)):
            v = getattr(self, key)
            if not (is_finite_real(v) and ok(v)):
                raise InputError(f"Sweep.{key} must be {rule}, got {v!r}")
        object.__setattr__(self, "positions_m", positions)

    def __len__(self) -> int:
        return len(self.positions_m)

    def frames(self, screen: Screen) -> Iterator[np.ndarray]:
        for p in self.positions_m:
            yield white_square(screen, tuple(p), self.size_m, self.radiance)

    def frame_stack(self, screen: Screen) -> np.ndarray:
        """All frames as one (n, rows, cols) array (memory grows with n: prefer :meth:`frame_source`)."""
        stack = np.empty((len(self), *screen.shape))
        for i, frame in enumerate(self.frames(screen)):
            stack[i] = frame
        return stack

    def frame_source(self, screen: Screen, background_w_m2_sr: float = 0.0) -> FrameSource:
        """The frames, made on demand (bounded memory whatever their number)."""
        positions = np.asarray(self.positions_m, dtype=np.float64)

        def make(i: int) -> np.ndarray:
            return white_square(screen, tuple(positions[i]), self.size_m, self.radiance) + background_w_m2_sr

        description = {"kind": "white_square_sweep", "positions_m": positions, "size_m": float(self.size_m),
                       "radiance_w_m2_sr": float(self.radiance), "background_w_m2_sr": float(background_w_m2_sr),
                       "screen_resolution": list(screen.resolution), "screen_size_m": [screen.width_m, screen.height_m]}
        return FrameSource(len(self), screen.shape, make, description)


class FrameSource:
    """A sequence of frames (radiance [W m^-2 sr^-1], (rows, cols) each) produced on demand.

    Long sweeps and videos stream through the renderer chunk by chunk instead of living in memory as one
    stack. ``description`` (JSON-friendly, arrays allowed) determines the frames completely: it is what a run's
    identity records for generated frames; sources wrapping arrays are identified by their content.

    Parameters
    ----------
    n : int
        Number of frames.
    frame_shape : (rows, cols)
    make : callable
        ``make(i) -> (rows, cols)`` array for frame ``i``.
    description : dict or None
        What the frames are; ``None`` means "identify by content" (hashed as they stream).
    """

    def __init__(self, n: int, frame_shape: tuple[int, int], make: Callable[[int], np.ndarray],
                 description: dict | None = None) -> None:
        self.n, self.frame_shape, self._make, self.description = int(n), tuple(frame_shape), make, description
        self._array: np.ndarray | None = None  # set by from_array: chunks are then slices of it

    @classmethod
    def from_array(cls, frames: np.ndarray) -> FrameSource:
        """Wrap an (n, rows, cols) array (a memory map streams from disk)."""
        arr = frames if frames.ndim == 3 else np.asarray(frames)[None]
        source = cls(arr.shape[0], arr.shape[1:], lambda i: np.asarray(arr[i], dtype=np.float64), None)
        source._array = arr
        return source

    def __len__(self) -> int:
        return self.n

    @property
    def shape(self) -> tuple[int, int, int]:
        return (self.n, *self.frame_shape)

    @property
    def nbytes_per_frame(self) -> int:
        return 8 * self.frame_shape[0] * self.frame_shape[1]

    def __getitem__(self, index) -> np.ndarray:
        """Frame ``i`` (rows, cols), or a stack (k, rows, cols) for a slice or an index array."""
        if isinstance(index, int | np.integer):
            if not -self.n <= index < self.n:
                raise IndexError(f"frame {index} out of range (0..{self.n - 1})")
            return np.asarray(self._make(int(index) % self.n), dtype=np.float64)
        idx = np.arange(self.n)[index]
        if self._array is not None:
            if len(idx) and np.all(np.diff(idx) == 1):  # a contiguous chunk: a view, no copy
                return np.asarray(self._array[idx[0] : idx[-1] + 1], dtype=np.float64)
            return np.asarray(self._array[idx], dtype=np.float64)
        out = np.empty((len(idx), *self.frame_shape))
        for j, i in enumerate(idx):
            out[j] = self._make(int(i))
        return out

    def __iter__(self) -> Iterator[np.ndarray]:
        for i in range(self.n):
            yield self[i]

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        stack = self[:]
        return stack if dtype is None else stack.astype(dtype)

    def chunk_size(self, budget_bytes: int = 1 << 27) -> int:
        """Frames per chunk so that one chunk stays under ``budget_bytes`` (at least 1)."""
        return max(1, min(self.n, budget_bytes // self.nbytes_per_frame))


def as_frame_source(frames) -> FrameSource:
    """A :class:`FrameSource` from a source, an (n, rows, cols) / (rows, cols) array, or a list of frames."""
    if isinstance(frames, FrameSource):
        return frames
    what = "frames must be radiance images [W m^-2 sr^-1]: an (n, rows, cols) array, a list of (rows, cols) arrays"
    if isinstance(frames, np.ndarray):
        if frames.dtype.kind not in "biuf":
            raise InputError(f"{what} of real numbers, got an array of {frames.dtype}")
        if frames.ndim not in (2, 3):
            raise InputError(f"{what}, got an array of shape {frames.shape}")
        return FrameSource.from_array(frames if frames.ndim == 3 else frames[None])
    if isinstance(frames, str | bytes) or not hasattr(frames, "__iter__"):
        raise InputError(f"{what} or a FrameSource, got {type(frames).__name__}")
    try:
        stack = [np.asarray(f) for f in frames]
    except (TypeError, ValueError) as err:  # a ragged nested list
        raise InputError(f"{what}: {err}") from None
    if not stack:
        raise InputError(f"{what}; got no frame (an empty list)")
    shapes = {f.shape for f in stack}
    if len(shapes) > 1 or stack[0].ndim != 2:
        raise InputError(f"{what}, each of one (rows, cols) shape; got shapes {sorted(shapes)[:4]}")
    if any(f.dtype.kind not in "biuf" for f in stack):
        raise InputError(f"{what} of real numbers, got {sorted({str(f.dtype) for f in stack})}")
    return FrameSource.from_array(np.stack(stack).astype(np.float64, copy=False))


def line_sweep(
    start_m: tuple[float, float], end_m: tuple[float, float], n: int, size_m: float, radiance: float = 1.0
) -> Sweep:
    """``n`` square positions evenly spaced from ``start_m`` to ``end_m`` (a 1D sweep along a boundary)."""
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise InputError(f"a sweep needs an integer n >= 1 positions, got {n!r}")
    t = np.linspace(0.0, 1.0, n)[:, None]
    pos = (1 - t) * np.asarray(start_m, float) + t * np.asarray(end_m, float)
    return Sweep(pos, size_m, radiance)


def grid_sweep(
    x_range_m: tuple[float, float],
    y_range_m: tuple[float, float],
    nx: int,
    ny: int,
    size_m: float,
    radiance: float = 1.0,
) -> Sweep:
    """Square positions on an ``nx`` x ``ny`` grid (row-major, y from top to bottom) for 2D calibration."""
    if any(isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 1 for k in (nx, ny)):
        raise InputError(f"a grid sweep needs integers nx, ny >= 1, got {nx!r}, {ny!r}")
    xs = np.linspace(*x_range_m, nx)
    ys = np.linspace(*y_range_m, ny)[::-1]
    gx, gy = np.meshgrid(xs, ys)
    return Sweep(np.column_stack([gx.ravel(), gy.ravel()]), size_m, radiance)


def _polygon_area_m2(poly_m: np.ndarray) -> float:
    """Area [m^2] of a planar polygon (k, 3) [m] (0 for fewer than 3 vertices)."""
    if len(poly_m) < 3:
        return 0.0
    return 0.5 * float(np.linalg.norm(np.sum(np.cross(poly_m, np.roll(poly_m, -1, axis=0)), axis=0)))


def screen_polygon_local_m(screen: Screen, mixel) -> np.ndarray:
    """The screen rectangle's corners (4, 3) [m] in ``mixel``'s local frame (x left, y up, z forward)."""
    hw, hh = screen.width_m / 2, screen.height_m / 2
    corners = screen.to_world(np.array([-hw, hw, hw, -hw]), np.array([-hh, -hh, hh, hh]))
    return mixel.pose.to_local(corners)


def visible_screen_polygon_local_m(screen: Screen, mixel) -> np.ndarray:
    """The part of the screen (polygon (k, 3) [m], mixel's local frame) that some detector point sees.

    A point ``p`` beyond the mask plane (``z > d_f (1 + 1e-9)``) is seen by some detector point through the aperture iff
    ``|x| <= tx z - s/2`` and ``|y| <= ty z - s/2`` (``tx, ty`` from
    :meth:`~mincam_sim.model.optics.Mixel.half_fov_tan`, ``s`` the detector side): the union of the detector points'
    view
    pyramids, whose apex lies at ``z = s / (2 tx)`` (slightly narrower than the pyramid of the widest rays from the
    origin). Mask transmission is ignored.
    """
    poly = screen_polygon_local_m(screen, mixel)
    tx, ty = mixel.half_fov_tan()
    half_s = mixel.detector_size_m / 2
    # strictly beyond the mask: a screen lying on the mask plane is seen by no ray that crosses the mask
    poly = clip_polygon_halfspace(poly, np.array([0.0, 0.0, 1.0]), -mixel.d_f_m * (1 + 1e-9))
    for normal in ((-1.0, 0.0, tx), (1.0, 0.0, tx), (0.0, -1.0, ty), (0.0, 1.0, ty)):
        poly = clip_polygon_halfspace(poly, np.array(normal), -half_s)
    return poly


def visible_screen_area_m2(screen: Screen, mixel) -> float:
    """Area [m^2] of the part of the screen that some detector point of ``mixel`` sees through its aperture
    (:func:`visible_screen_polygon_local_m`; mask transmission and the other mixels' bodies ignored)."""
    return _polygon_area_m2(visible_screen_polygon_local_m(screen, mixel))


def screen_in_body_polygon_local_m(screen: Screen, mixel, tolerance_m: float = 1e-12) -> np.ndarray:
    """The part of the screen (polygon (k, 3) [m], local frame) inside the mixel's body box, shrunk by
    ``tolerance_m`` on every side so that a screen touching a face (e.g. lying on the mask) is not counted."""
    poly = screen_polygon_local_m(screen, mixel)
    hw, hh = mixel.mask.width_m / 2, mixel.mask.height_m / 2
    for normal, offset in (((1.0, 0.0, 0.0), hw), ((-1.0, 0.0, 0.0), hw), ((0.0, 1.0, 0.0), hh),
                           ((0.0, -1.0, 0.0), hh), ((0.0, 0.0, 1.0), 0.0), ((0.0, 0.0, -1.0), mixel.d_f_m)):
        poly = clip_polygon_halfspace(poly, np.array(normal), offset - tolerance_m)
    return poly


def check_visible(screen: Screen, mixels) -> None:
    """Raise ``ValueError`` if a mixel is behind the screen, if the screen passes through a mixel's body, or if
    a mixel sees none of the screen through its aperture.

    Exact: the screen rectangle, as a polygon in each mixel's local frame, is clipped by the half-spaces of the
    mixel's view (:func:`visible_screen_polygon_local_m`: beyond the mask plane, inside the union of the
    detector points' view pyramids through the aperture) and, separately, by its body box (detector plane to
    mask plane, of the mask's width x height). The set-up is refused when the visible part has no area or the
    part inside the body has some. Mask transmission and the other mixels' bodies are not considered.
    """
    normal = screen.pose.axes()[2]
    screen_area_m2 = screen.width_m * screen.height_m
    for mixel in mixels:
        offset = np.asarray(mixel.pose.position_m) - np.asarray(screen.pose.position_m)
        if float(offset @ normal) <= 0:
            raise InputError(
                f"mixel {mixel.name!r} at {mixel.pose.position_m} m is behind the screen or in its plane; "
                "displays emit only from their front: move the mixel in front of the screen (along the screen's "
                f"forward {screen.pose.forward}) or turn the screen round"
            )
        tol_m = 1e-9 * min(mixel.mask.width_m, mixel.mask.height_m, mixel.d_f_m)
        inside = screen_in_body_polygon_local_m(screen, mixel, tol_m)
        if _polygon_area_m2(inside) > 0:
            raise InputError(
                f"the screen passes through mixel {mixel.name!r}'s body (the {mixel.mask.width_m * 1e3:g} x "
                f"{mixel.mask.height_m * 1e3:g} x {mixel.d_f_m * 1e3:g} mm housing from its detector to its mask, "
                f"at {mixel.pose.position_m} m): move the screen (or the mixel) so that the screen lies beyond "
                "the mask"
            )
        visible = visible_screen_polygon_local_m(screen, mixel)
        if _polygon_area_m2(visible) <= 1e-14 * screen_area_m2:
            tx, ty = mixel.half_fov_tan()
            raise InputError(
                f"the screen lies entirely outside mixel {mixel.name!r}'s field of view "
                f"(+/-{np.degrees(np.arctan(tx)):.1f} x +/-{np.degrees(np.arctan(ty)):.1f} deg about its forward "
                f"{mixel.pose.forward}, beyond its mask at {mixel.d_f_m * 1e3:g} mm): point the mixel at the "
                "screen or move the screen in front of it"
            )
