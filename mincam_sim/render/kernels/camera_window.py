"""The ground-truth camera over a window of its pixels: where a frame can differ from its background.

A moving shape changes what a pinhole camera sees directly (its own pixels) and through direct light (its
shadows). Both lie inside the hull of the shape's box and its shadow volumes from every light
(:func:`.change_geometry.change_points_each`, the hull the change solvers aim their rays at), in the frame and in
the background, so their image lies inside the camera's image of those hulls: a perspective projection maps a hull
in front of the camera onto the hull of its projected corners. :func:`change_windows` bounds each hull's image by
a rectangle, merges those that overlap and grows them to multiples of :data:`WINDOW_STEP_PX` (so that a handful
of window sizes keep their frozen recordings); :func:`window_render` renders the camera there only, and a frame
and its background rendered with the same seed pair up lane by lane, so where the frame changes nothing their
pixels are equal bit for bit.

What the window leaves out is light that reaches a pixel outside it only by an inter-reflection off the moving
shape: on the tabletop under 1.3 % of the brightest background pixel, below the change truth's 2 % threshold,
while a full-image difference at 32 samples a pixel crossed that threshold by noise alone (paths that meet the
mover on a bounce decorrelate from the background's): the window removes those noise pixels.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from mincam_sim.render import backend

WINDOW_STEP_PX = 16  # window sides are multiples of this (or the film's side): few sizes, few frozen recordings
WINDOW_MARGIN_PX = 1.0  # the window reaches this far past the projected hull (ray offsets, pixel footprints)

Window = tuple[int, int, int, int]  # (first row, first column, rows, columns) [px]


class FilmProjection:
    """Film coordinates [px] of scene points (m, 3) [m] as a perspective ``sensor`` sees them, read from the rays
    the sensor itself casts through three film corners (so it follows Mitsuba's conventions, whatever the pose,
    field of view or aspect): column = x * width, row = y * height for the film position (x, y) in [0, 1]^2 whose
    ray passes through the point."""

    def __init__(self, sensor) -> None:
        mi = backend.mitsuba()
        size = sensor.film().size()
        self.width_px, self.height_px = int(size[0]), int(size[1])
        origins, directions = [], []
        for x, y in ((0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (0.5, 0.5)):
            ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(x, y), mi.Point2f(0.5, 0.5))
            origins.append(np.array(ray.o, dtype=float).ravel())
            directions.append(np.array(ray.d, dtype=float).ravel())
        directions = np.array(directions) / np.linalg.norm(directions, axis=1, keepdims=True)
        # the rays start on the near clipping plane: the pinhole is where their lines meet
        across = np.eye(3)[None] - directions[:, :, None] * directions[:, None, :]
        self.origin_m = np.linalg.solve(across.sum(axis=0), np.einsum("kij,kj->i", across, np.array(origins)))
        self.forward = directions[3]
        on_plane = directions[:3] / (directions[:3] @ self.forward)[:, None]  # at unit depth along forward
        self._corner = on_plane[0]
        self._axes = np.stack([on_plane[1] - on_plane[0], on_plane[2] - on_plane[0]], axis=1)  # (3, 2): x, y

    def __call__(self, points_m: np.ndarray) -> np.ndarray | None:
        """(m, 2) film coordinates (column, row) [px] of ``points_m``, or None if one of them is not in front of
        the camera (its image is unbounded)."""
        rel = np.asarray(points_m, dtype=float).reshape(-1, 3) - self.origin_m
        depth = rel @ self.forward
        if np.any(depth <= 1e-9):
            return None
        on_plane = rel / depth[:, None] - self._corner
        xy, *_ = np.linalg.lstsq(self._axes, on_plane.T, rcond=None)
        return np.stack([xy[0] * self.width_px, xy[1] * self.height_px], axis=1)


def change_windows(projection: FilmProjection, hulls: list[np.ndarray | None],
                   step_px: int = WINDOW_STEP_PX) -> tuple[Window, ...]:
    """Windows of the film that hold the image of every hull in ``hulls`` (corner points [m]; None: a change that
    reaches anywhere): each hull's image bounds grown by :data:`WINDOW_MARGIN_PX` and to sides that are multiples
    of ``step_px`` (or the film's side), kept inside the film, windows that overlap merged into the one holding
    both (movers apart keep windows of their own, so the pixels between them are not rendered). None of them
    where no hull is seen (nothing in the image can change); the whole film if a hull is unbounded or reaches
    behind the camera."""
    width, height = projection.width_px, projection.height_px
    whole = ((0, 0, height, width),)
    rects = []
    for hull in hulls:
        if hull is None:
            return whole
        film = projection(hull)
        if film is None:
            return whole
        a = np.maximum(film.min(axis=0) - WINDOW_MARGIN_PX, 0.0)
        b = np.minimum(film.max(axis=0) + WINDOW_MARGIN_PX, [width, height])
        if np.all(b > a):
            rects.append(_stepped(np.floor(a).astype(int), np.ceil(b).astype(int), (width, height), step_px))
    while overlap := next(((i, j) for i, j in combinations(range(len(rects)), 2)
                           if np.all(rects[i][0] < rects[j][1]) and np.all(rects[j][0] < rects[i][1])), None):
        i, j = overlap  # one window holding both
        rects[i] = _stepped(np.minimum(rects[i][0], rects[j][0]), np.maximum(rects[i][1], rects[j][1]),
                            (width, height), step_px)
        del rects[j]
    return tuple((int(lo[1]), int(lo[0]), int(hi[1] - lo[1]), int(hi[0] - lo[0])) for lo, hi in sorted(
        rects, key=lambda r: (int(r[0][1]), int(r[0][0]))))


def _stepped(first: np.ndarray, last: np.ndarray, film: tuple[int, int], step_px: int) -> tuple:
    """(first, one past the last) pixel (x, y) of a rectangle holding ``first`` .. ``last``, its sides grown to
    multiples of ``step_px`` (or the film's side) and kept inside the film."""
    sides = np.array([min(-(-int(n) // step_px) * step_px, full) for n, full in zip(last - first, film, strict=True)])
    starts = np.array([min(int(s), full - side) for s, side, full in zip(first, sides, film, strict=True)])
    return starts, starts + sides


def window_render(scene, sensor_index: int, spp: int, seed, origin, shape: tuple[int, int], buffers: tuple):
    """The mean radiance [W m^-2 sr^-1] of ``spp`` samples in each pixel of a ``shape`` (rows, columns) window of
    sensor ``sensor_index``'s film whose first pixel is ``origin`` (a Dr.Jit UInt32 pair: row, column), flat, row
    by row: each sample a film position uniform in its pixel, one path of the scene's integrator (what
    ``mi.render`` gives a pixel through a box filter). Lane ``i`` is sample ``i % spp`` of pixel ``i // spp``, its
    random numbers from ``seed`` and ``i`` alone, so two renders of one window pair up lane by lane. Frozen by
    :meth:`mincam_sim.render.scene.mincam_scene.MincamScene.camera_window`; ``buffers`` only keys the recording."""
    mi = backend.mitsuba()
    import drjit as dr

    sensor = scene.sensors()[sensor_index]
    size = sensor.film().size()
    rows, cols = shape
    n = rows * cols * spp
    sampler = sensor.sampler().clone()
    sampler.set_sample_count(spp)
    sampler.seed(seed, n)
    pixel = dr.arange(mi.UInt32, n) // spp
    row = pixel // cols + origin[0]
    col = pixel % cols + origin[1]
    position = (mi.Point2f(mi.Float(col), mi.Float(row)) + sampler.next_2d()) / mi.ScalarVector2f(size)
    wavelength = sampler.next_1d()
    ray, weight = sensor.sample_ray_differential(sensor.shutter_open(), wavelength, position, sampler.next_2d())
    radiance, _, _ = scene.integrator().sample(scene, sampler, ray, None, True)
    value = (weight * radiance)[0]
    return dr.block_sum(value, spp) / spp
