"""The mincam set-up shared by the paper's experiments: geometry, sensor, screen and sampling defaults.

Every default lives here (or in an experiment's own parameters dataclass); a ``[setup]`` section of a
``mincam-sim reproduce --config FILE`` document overrides them, validated field by field.

Coordinates: the mincam looks straight down at a table (or straight at a screen) from ``depth_m``; scene
positions are metres in the plane it looks at, ``x`` to the viewer's right and ``y`` up in its view. On the
table (z = 0, seen from above with +y up) that is world (x, y); on the screen it is screen (x, y).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np

from mincam_sim import paper
from mincam_sim.errors import InputError
from mincam_sim.masks import DEFAULT_MASK_SIZE_M, DEFAULT_RESOLUTION
from mincam_sim.model.geometry import Pose
from mincam_sim.model.optics import DEFAULT_D_F_M, DEFAULT_DETECTOR_SIZE_M, PAPER_SPACING_M
from mincam_sim.model.sensor import SensorModel
from mincam_sim.scene.display import DEFAULT_SCREEN_RESOLUTION, Screen


@dataclass
class Setup:
    """Built-in defaults resembling the paper's prototype (Sec. 3.1, 4.1.1, 4.2.1, 4.3.1).

    Attributes
    ----------
    depth_m : float
        Distance from the mincam to the table / screen [m] (a 50 cm field of view at 0.5 m).
    spacing_m : float
        Mixel spacing [m] (paper: 3.3 cm): the intrusion pair sits ``spacing_m`` apart; the tracking cross puts
        each mixel ``spacing_m`` from the centre camera, so the two mixels of each ratio (x | 1 - x, y | 1 - y)
        are ``2 spacing_m`` (6.6 cm) apart.
    d_f_m, detector_size_m, mask_size_m : float
        Mixel geometry [m]: mask 2 mm at 2 mm gives a ~53 deg field of view, detector 0.1 mm.
    mask_resolution : int
        Texels per side of the generated masks.
    field_m : float
        Calibrated range [m]: the paper's 50 cm boundary / field of view; error rates are % of it.
    bit_depth : int
        ADC bits (paper: 12); the sensor is :meth:`~mincam_sim.model.sensor.SensorModel.paper_prototype` (48 x 48
        pixels averaged).
    exposure_fill : float
        Auto-exposure: the brightest reading fills this fraction of the ADC range, in (0, 1].
    screen_resolution : tuple of int
        Display texels (columns, rows) of the 50" 16:9 screen.
    table_light_radiance_w_m2_sr : float
        Radiance of the square area light over the table [W m^-2 sr^-1].
    spp : int
        Plain-estimator samples per mixel per frame on the tabletop (halved in quick mode); the stratified
        estimator traces ``spp / 128`` rays per mixel per pass (:mod:`.pipeline`), times each tabletop
        experiment's ``spp_fraction`` (intrusion 1, tracking 1/4: the share its numbers need).
    dp_solver : {"stratified_change", "plain_change"}
        The change solver that renders frame changes dP (both unbiased; "plain_change" is the reference).
    camera_px : int
        Pixels per side of the ground-truth camera's images (>= 8).
    seed : int
        Seed of every random choice (each experiment adds its own offset): same seed, same numbers.
    quick : bool
        Fewer frames and samples (for ``make demo`` and the tests).
    """

    depth_m: float = paper.CALIBRATION_DEPTH_M
    spacing_m: float = PAPER_SPACING_M
    d_f_m: float = DEFAULT_D_F_M
    detector_size_m: float = DEFAULT_DETECTOR_SIZE_M
    mask_size_m: float = DEFAULT_MASK_SIZE_M
    mask_resolution: int = DEFAULT_RESOLUTION
    field_m: float = paper.FIELD_M
    bit_depth: int = paper.ADC_BITS
    exposure_fill: float = 0.7
    screen_resolution: tuple[int, int] = DEFAULT_SCREEN_RESOLUTION
    table_light_radiance_w_m2_sr: float = 20.0
    spp: int = 1 << 23  # plain-estimator samples per mixel per frame on the tabletop (quick mode: half), times
    # each experiment's spp_fraction
    dp_solver: str = "stratified_change"  # rays where the change is, or "plain_change" (the reference)
    camera_px: int = 160
    seed: int = 0
    quick: bool = False

    def __post_init__(self) -> None:
        for key in ("depth_m", "d_f_m", "detector_size_m", "mask_size_m", "field_m"):
            v = getattr(self, key)
            if not (np.isfinite(v) and v > 0):
                raise InputError(f"Setup.{key} must be > 0 (metres), got {v!r}")
        if not 2 <= self.bit_depth <= 32:  # at 1 bit every change reads 0 or 1 DN: the calibration has nothing to fit
            raise InputError(f"Setup.bit_depth must be 2 to 32 bits (the paper's: 12), got {self.bit_depth!r}")
        if not self.spp >= 1:
            raise InputError(f"Setup.spp must be >= 1 samples per mixel per frame, got {self.spp!r}")
        if not self.camera_px >= 8:
            raise InputError(f"Setup.camera_px must be >= 8 pixels a side (the ground-truth camera), got "
                             f"{self.camera_px!r}")
        if not 0 < self.exposure_fill <= 1:
            raise InputError(f"Setup.exposure_fill must be in (0, 1], got {self.exposure_fill!r}")
        if self.dp_solver not in ("stratified_change", "plain_change"):
            raise InputError(f"Setup.dp_solver must be 'stratified_change' or 'plain_change', got "
                             f"{self.dp_solver!r}")
        if not (np.isfinite(self.spacing_m) and self.spacing_m >= 0):
            raise InputError(f"Setup.spacing_m must be >= 0 metres, got {self.spacing_m!r}")

    def as_dict(self) -> dict:
        return asdict(self)

    def with_(self, **kw) -> Setup:
        return replace(self, **kw)

    @property
    def center(self) -> Pose:
        """Pose of the mincam centre above the table (looking down, +y up in its view)."""
        return Pose((0.0, 0.0, self.depth_m), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0))

    def screen(self, depth_m: float | None = None) -> Screen:
        """The paper's 50" 16:9 display at ``depth_m`` (default: the set-up's depth), facing the mincam."""
        d = self.depth_m if depth_m is None else depth_m
        return Screen(resolution=self.screen_resolution, pose=Pose((0.0, 0.0, -d), (0.0, 0.0, 1.0)))

    @property
    def tabletop_spp(self) -> int:
        """Samples per mixel per frame on the tabletop (``spp``, halved in quick mode)."""
        return self.spp // 2 if self.quick else self.spp

    def sensor(self) -> SensorModel:
        return SensorModel.paper_prototype(bit_depth=self.bit_depth)

    def scene_to_mask(self, value_m: float, depth_m: float | None = None) -> float:
        """Normalised mask coordinate (0..1) seen, from the mincam centre, at scene coordinate ``value_m``."""
        d = self.depth_m if depth_m is None else depth_m
        return 0.5 + value_m * self.d_f_m / d / self.mask_size_m
