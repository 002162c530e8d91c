"""The ground truth of the tabletop experiments, as in the paper: a pinhole camera at the mincam's centre
looking straight down, background subtraction, binary detection and the centroid of the detected pixels."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..render import scene_dicts
from .setup import Setup


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
