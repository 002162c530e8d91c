"""The ground truth of the tabletop experiments: a pinhole camera at the mincam's centre looking straight down.

Two definitions, both from that camera: the paper's (Sec. 4.1.1, 4.2.1), the centroid of the **object**, from
the silhouette of the object's mesh projected into the camera (``GroundTruthCamera.object_centroid``); and
the centroid of the **change** (background subtraction, binary detection, the centroid of the detected pixels,
``GroundTruthCamera.change_centroid``), which also takes in the object's shadow. The experiments render the
change where the movers and their shadows can be seen only
(:meth:`mincam_sim.render.simulation.Simulation.camera_changes`): a whole-image difference at 32 samples a pixel
detected noise pixels where paths that met a mover on a bounce decorrelated from the background's."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mincam_sim.experiments.setup import Setup
from mincam_sim.render.scene import scene_dicts


@dataclass(frozen=True)
class GroundTruthCamera:
    """A square pinhole camera at height ``depth_m`` over the table, looking straight down (image row 0 = +y).

    Parameters
    ----------
    depth_m : float
        Height above the table [m].
    fov_deg : float
        Full horizontal (= vertical) field of view [deg].
    pixels : int
        Pixels per side.
    """

    depth_m: float
    fov_deg: float
    pixels: int

    @classmethod
    def for_setup(cls, setup: Setup) -> GroundTruthCamera:
        """The calibrated field plus a 20 % margin, ``setup.camera_px`` pixels per side."""
        fov = float(np.degrees(2 * np.arctan(0.6 * setup.field_m / setup.depth_m)))
        return cls(setup.depth_m, fov, setup.camera_px)

    @property
    def half_extent_m(self) -> float:
        """Half the side of the table area the image covers [m]."""
        return float(self.depth_m * np.tan(np.radians(self.fov_deg) / 2))

    def pixel_to_table(self, rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
        """Table coordinates [m] (..., 2) of pixel centres."""
        h, w = shape
        pitch = 2 * self.half_extent_m / w
        x = (np.asarray(cols) + 0.5 - w / 2) * pitch
        y = (h / 2 - np.asarray(rows) - 0.5) * pitch
        return np.stack([x, y], axis=-1)

    def scene_dict(self, setup: Setup, spp: int = 32) -> dict:
        """The Mitsuba sensor of this camera at the set-up's centre."""
        return scene_dicts.pinhole_camera(setup.center.matrix(), self.fov_deg, self.pixels, self.pixels, spp=spp)

    def change_centroid(self, image: np.ndarray, background: np.ndarray, threshold: float,
                        region: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Background subtraction, binary detection (|change| > threshold), the centroid of the detected pixels
        in table coordinates [m] (NaN if none). Returns (centroid, binary mask)."""
        detected = np.abs(image - background) > threshold
        if region is not None:
            detected &= region
        if not detected.any():
            return np.full(2, np.nan), detected
        rows, cols = np.nonzero(detected)
        return self.pixel_to_table(rows, cols, image.shape).mean(axis=0), detected

    def signed_change_centroid(self, image: np.ndarray, background: np.ndarray,
                               region: np.ndarray | None = None) -> np.ndarray:
        """Intensity-weighted centroid of the *signed* change (what Eq. 4/7 estimate: brightening of the object
        minus darkening of its shadow), in table coordinates [m]; NaN if the net change is zero."""
        change = image - background
        if region is not None:
            change = np.where(region, change, 0.0)
        total = change.sum()
        if total == 0:
            return np.full(2, np.nan)
        rows, cols = np.indices(image.shape)
        points = self.pixel_to_table(rows, cols, image.shape)
        return (points * change[..., None]).sum(axis=(0, 1)) / total

    def project_to_table(self, points_m: np.ndarray) -> np.ndarray:
        """Where the camera (at height ``depth_m`` over the origin) sees world points (n, 3) [m]: the table
        point (n, 2) [m] on the same ray (a point at height z is seen ``depth / (depth - z)`` further out)."""
        p = np.asarray(points_m, dtype=np.float64)
        height = self.depth_m - p[:, 2]
        if np.any(height <= 0):
            raise ValueError("object points at or above the ground-truth camera's height cannot be projected")
        return p[:, :2] * (self.depth_m / height)[:, None]

    def object_mask(self, vertices_m: np.ndarray, faces: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
        """The pixels (boolean image of ``shape``) whose centres the object covers in this camera: every
        triangle of the mesh (vertices (n, 3) [m] in the world, faces (m, 3)) projected, pixel centres inside
        any projected triangle set. A closed mesh's projection is its silhouette, so this is an object-only
        mask: no shadow, no shading, whatever the light."""
        h, w = shape
        pitch = 2 * self.half_extent_m / w
        xy = self.project_to_table(vertices_m)
        # continuous pixel coordinates: col c has its centre at x = (c + 0.5 - w/2) pitch (pixel_to_table)
        u = xy[:, 0] / pitch + w / 2 - 0.5
        v = h / 2 - 0.5 - xy[:, 1] / pitch
        tri_u, tri_v = u[faces], v[faces]  # (m, 3)
        c0 = np.clip(np.ceil(tri_u.min(1)), 0, w).astype(int)
        c1 = np.clip(np.floor(tri_u.max(1)), -1, w - 1).astype(int)
        r0 = np.clip(np.ceil(tri_v.min(1)), 0, h).astype(int)
        r1 = np.clip(np.floor(tri_v.max(1)), -1, h - 1).astype(int)
        nc, nr = np.maximum(c1 - c0 + 1, 0), np.maximum(r1 - r0 + 1, 0)
        count = nc * nr
        mask = np.zeros(shape, dtype=bool)
        if count.sum() == 0:
            return mask
        tri = np.repeat(np.arange(len(faces)), count)
        local = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
        cols = c0[tri] + local % nc[tri]
        rows = r0[tri] + local // nc[tri]
        (ua, ub, uc), (va, vb, vc) = tri_u[tri].T, tri_v[tri].T
        # barycentric signs (either orientation): inside or on an edge of the projected triangle
        d1 = (cols - ub) * (va - vb) - (ua - ub) * (rows - vb)
        d2 = (cols - uc) * (vb - vc) - (ub - uc) * (rows - vc)
        d3 = (cols - ua) * (vc - va) - (uc - ua) * (rows - va)
        inside = ~(((d1 < 0) | (d2 < 0) | (d3 < 0)) & ((d1 > 0) | (d2 > 0) | (d3 > 0)))
        mask[rows[inside], cols[inside]] = True
        return mask

    def object_centroid(self, meshes: list[tuple[np.ndarray, np.ndarray]], shape: tuple[int, int],
                        region: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The paper's ground truth: the centroid of the *object* as this camera sees it (the union of the
        silhouettes of ``meshes``, each (world vertices [m], faces), within ``region``) in table coordinates
        [m] (NaN if it covers no pixel centre). Returns (centroid, mask)."""
        mask = np.zeros(shape, dtype=bool)
        for vertices, faces in meshes:
            mask |= self.object_mask(vertices, faces, shape)
        if region is not None:
            mask &= region
        if not mask.any():
            return np.full(2, np.nan), mask
        rows, cols = np.nonzero(mask)
        return self.pixel_to_table(rows, cols, shape).mean(axis=0), mask
