"""Shared pieces of the paper's experiments: the set-up, the tabletop world, calibration on the screen, the
sensor read-out and the ground truth from a pinhole camera.

Coordinates: the mincam looks straight down at a table (or straight at a screen) from ``depth_m``; scene
positions are metres in the plane it looks at, ``x`` to the viewer's right and ``y`` up in its view. On the
table (z = 0, seen from above with +y up) that is world (x, y); on the screen it is screen (x, y).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np

from .. import masks as masks_mod
from .. import objects
from ..calibration import Calibration1D, Calibration2D
from ..estimators import noise_threshold
from ..geometry import Pose
from ..mask_profiles import Band, Ramp
from ..masks import Mask
from ..optics import Mincam, layout
from ..scene.tabletop import Tabletop
from ..screen import Screen, Sweep, grid_sweep, line_sweep
from ..sensor import SensorModel

PAPER = {
    "intrusion": {"max_error_pct": 11.42, "avg_error_pct": 4.83},
    "tracking": {"max_error_pct": 6.78, "avg_error_pct": 2.82},
    "speed": {"max_error_pct": 7.55, "avg_error_pct": 2.85},
}


@dataclass
class Setup:
    """Built-in defaults resembling the paper's prototype (Sec. 3.1, 4.1.1, 4.2.1, 4.3.1).

    Attributes
    ----------
    depth_m : float
        Distance from the mincam to the table / screen [m] (a 50 cm field of view at 0.5 m).
    spacing_m : float
        Distance between neighbouring mixels [m] (paper: 3.3 cm).
    d_f_m, detector_size_m, mask_size_m : float
        Mixel geometry [m]: mask 2 mm at 2 mm gives a ~53 deg field of view, detector 0.1 mm.
    field_m : float
        Calibrated range [m]: the paper's 50 cm boundary / field of view; error rates are % of it.
    bit_depth : int
        ADC bits (paper: 12); the sensor is :meth:`SensorModel.paper_prototype` (48 x 48 pixels averaged).
    quick : bool
        Fewer frames and samples (for ``make demo`` and the tests).
    """

    depth_m: float = 0.5
    spacing_m: float = 0.033
    d_f_m: float = 2e-3
    detector_size_m: float = 1e-4
    mask_size_m: float = 2e-3
    mask_resolution: int = 256
    field_m: float = 0.5
    bit_depth: int = 12
    exposure_fill: float = 0.7
    screen_resolution: tuple[int, int] = (256, 144)
    table_light_radiance_w_m2_sr: float = 20.0
    spp: int = 1 << 23  # samples per mixel per frame on the tabletop (quick mode: half)
    camera_px: int = 160
    seed: int = 0
    quick: bool = False

    def __post_init__(self) -> None:
        for key in ("depth_m", "d_f_m", "detector_size_m", "mask_size_m", "field_m"):
            v = getattr(self, key)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"Setup.{key} must be > 0 (metres), got {v!r}")
        if not (np.isfinite(self.spacing_m) and self.spacing_m >= 0):
            raise ValueError(f"Setup.spacing_m must be >= 0 metres, got {self.spacing_m!r}")

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

    def sensor(self) -> SensorModel:
        return SensorModel.paper_prototype(bit_depth=self.bit_depth)

    def scene_to_mask(self, value_m: float, depth_m: float | None = None) -> float:
        """Normalised mask coordinate (0..1) seen, from the mincam centre, at scene coordinate ``value_m``."""
        d = self.depth_m if depth_m is None else depth_m
        return 0.5 + value_m * self.d_f_m / d / self.mask_size_m


def band_ramp(setup: Setup, kind: str, boundary_x_m: float, band_m: float) -> Mask:
    """The 1D intrusion mask (paper Fig. 3a): a ramp along the boundary ``x = boundary_x_m``, ``kind`` "y" or
    "1-y", transparent only in a band ``band_m`` wide around the boundary's image on the mask."""
    if kind not in ("y", "1-y"):
        raise ValueError(f"band ramp kind must be 'y' or '1-y', got {kind!r}")
    u0 = setup.scene_to_mask(boundary_x_m)
    half = band_m * setup.d_f_m / setup.depth_m / setup.mask_size_m / 2
    size = setup.mask_size_m
    profile = Band(Ramp(kind, size, size), (u0 - half - 0.5) * size, (u0 + half - 0.5) * size)
    return masks_mod.from_profile(profile, f"band_ramp_{kind}", setup.mask_resolution, size,
                                  kind="band_ramp", ramp=kind, boundary_x_m=boundary_x_m, band_m=band_m)


def intrusion_mincam(setup: Setup, boundary_x_m: float, band_m: float) -> Mincam:
    """Two mixels ``spacing_m`` apart along the boundary, masks y and 1 - y restricted to the boundary band."""
    s = setup.spacing_m
    return layout(
        [band_ramp(setup, "y", boundary_x_m, band_m), band_ramp(setup, "1-y", boundary_x_m, band_m)],
        [(0.0, s / 2), (0.0, -s / 2)],
        ["y", "1-y"],
        center=setup.center,
        d_f_m=setup.d_f_m,
        detector_size_m=setup.detector_size_m,
    )


def tracking_mincam(setup: Setup) -> Mincam:
    """Four mixels (x, 1 - x, y, 1 - y) ``spacing_m`` from the centre camera (paper Eq. 5, Fig. 2)."""
    s = setup.spacing_m
    res, size = setup.mask_resolution, setup.mask_size_m
    return layout(
        [masks_mod.ramp(k, res, size) for k in ("x", "1-x", "y", "1-y")],
        [(-s, 0.0), (s, 0.0), (0.0, s), (0.0, -s)],
        ["x", "1-x", "y", "1-y"],
        center=setup.center,
        d_f_m=setup.d_f_m,
        detector_size_m=setup.detector_size_m,
    )


def mincam_on_screen(mincam: Mincam, setup: Setup) -> Mincam:
    """The same mincam turned to face the calibration screen (looking along -z from the origin)."""
    mixels = []
    for m in mincam:
        local = setup.center.to_local(np.asarray(m.pose.position_m))
        world = Pose().to_world(local)
        mixels.append(m.with_pose(Pose(tuple(world), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0))))
    return Mincam(tuple(mixels), allow_overlap=mincam.allow_overlap)


@dataclass
class Readout:
    """Digital read-out (DN) of mixel irradiances with the sensor model: frames, background and threshold."""

    frames_dn: np.ndarray
    background_dn: np.ndarray
    threshold_dn: float
    sensor: SensorModel
    n_background_frames: int = 16

    @property
    def change_dn(self) -> np.ndarray:
        return self.frames_dn - self.background_dn

    def ideal_change_dn(self, frame_irradiance: np.ndarray, background_irradiance: np.ndarray) -> np.ndarray:
        """The noiseless change (no shot/read noise, no quantisation) for the same exposure."""
        return self.sensor.expected(frame_irradiance) - self.sensor.expected(background_irradiance)

    def change_sigma_dn(self, frame_irradiance, background_irradiance, mc_stderr_w_m2=None) -> np.ndarray:
        """Standard deviation of the change [DN]: sensor noise of the frame and of the averaged background,
        plus the Monte Carlo standard error of the rendered change converted to DN."""
        var = self.sensor.expected_std_dn(frame_irradiance) ** 2
        var = var + self.sensor.expected_std_dn(background_irradiance) ** 2 / self.n_background_frames
        if mc_stderr_w_m2 is not None:
            gain = self.sensor.expected(1.0) - self.sensor.expected(0.0)  # DN per W/m^2 (linear model)
            var = var + (gain * np.asarray(mc_stderr_w_m2)) ** 2
        return np.sqrt(var)


def propagate_sigma(predict, change: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Standard deviation of ``predict(change)`` (rows = frames) from independent per-value sigmas, by a
    finite-difference Jacobian (first-order propagation). Returns the shape of ``predict``'s output."""
    base = np.asarray(predict(change), dtype=float)
    var = np.zeros_like(base)
    for j in range(change.shape[1]):
        h = np.maximum(1e-3 * sigma[:, j], 1e-9)
        bumped = change.copy()
        bumped[:, j] += h
        jac = (np.asarray(predict(bumped), dtype=float) - base) / (h if base.ndim == 1 else h[:, None])
        var += (jac * (sigma[:, j] if base.ndim == 1 else sigma[:, j][:, None])) ** 2
    return np.sqrt(var)


def read_out(
    frame_irradiance: np.ndarray,
    background_irradiance: np.ndarray,
    setup: Setup,
    rng: np.random.Generator,
    n_background_frames: int = 16,
    n_sigma: float = 5.0,
) -> Readout:
    """Expose (the brightest value fills ``exposure_fill`` of the range), add noise and quantise with the
    12-bit sensor; estimate the background and the detection threshold from background-only frames."""
    peak = float(max(np.max(frame_irradiance), np.max(background_irradiance)))
    sensor = setup.sensor().auto_exposed(peak, setup.exposure_fill)
    bg_frames = sensor.measure(np.broadcast_to(background_irradiance, (n_background_frames,
                                                                        *np.shape(background_irradiance))), rng)
    background, threshold = noise_threshold(bg_frames, n_sigma=n_sigma)
    frames = sensor.measure(frame_irradiance, rng)
    return Readout(frames, background, float(threshold), sensor, n_background_frames)


def screen_sweep_1d(setup: Setup, boundary_x_m: float, n: int, square_m: float) -> Sweep:
    """White squares along the boundary line ``x = boundary_x_m`` over the calibrated range (paper Fig. 4a)."""
    half = setup.field_m / 2
    return line_sweep((boundary_x_m, -half), (boundary_x_m, half), n, square_m)


def screen_sweep_2d(setup: Setup, n_per_axis: int, square_m: float) -> Sweep:
    """White squares on a grid clipped to the 50 cm diameter field (paper Sec. 4.2.1)."""
    half = setup.field_m / 2
    sweep = grid_sweep((-half, half), (-half, half), n_per_axis, n_per_axis, square_m)
    keep = np.hypot(*sweep.positions_m.T) <= half + 1e-9
    return Sweep(sweep.positions_m[keep], square_m)


def fit_calibration_1d(observed: np.ndarray, true_m: np.ndarray, meta: dict) -> Calibration1D:
    ok = np.isfinite(observed)
    return Calibration1D.fit(observed[ok], true_m[ok], degree=3, metadata=meta)


def fit_calibration_2d(observed: np.ndarray, true_m: np.ndarray, meta: dict) -> Calibration2D:
    ok = np.all(np.isfinite(observed), axis=1)
    return Calibration2D.fit(observed[ok], true_m[ok], degree=3, metadata=meta)


# --------------------------------------------------------------------------------------------------------------
# Tabletop world and ground truth


def make_tabletop(setup: Setup, toys: dict, rng: np.random.Generator) -> Tabletop:
    background = objects.printed_background((256, 256), rng, kind="paper")
    return Tabletop(background, 1.2, toys, setup.table_light_radiance_w_m2_sr)


def world_elements(table: Tabletop) -> dict:
    """Mitsuba elements of a tabletop (built by the render layer)."""
    from ..render.elements import tabletop_elements

    return tabletop_elements(table)


def toy_updates(table: Tabletop, placements: dict) -> dict:
    """Parameter updates placing toys: ``placements[name] = (position (2,), heading)`` or None (parked)."""
    from ..render.elements import toy_updates as updates

    return updates(table, placements)


def camera_fov_deg(setup: Setup) -> float:
    """Horizontal field of view of the ground-truth camera: the calibrated field plus a margin."""
    return float(np.degrees(2 * np.arctan(0.6 * setup.field_m / setup.depth_m)))


def camera_pixel_to_table(setup: Setup, rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Table coordinates [m] of pixel centres of the centre camera looking straight down (image row 0 = +y)."""
    h, w = shape
    pitch = 2 * setup.depth_m * np.tan(np.radians(camera_fov_deg(setup)) / 2) / w
    x = (np.asarray(cols) + 0.5 - w / 2) * pitch
    y = (h / 2 - np.asarray(rows) - 0.5) * pitch
    return np.stack([x, y], axis=-1)


def change_centroid(
    image: np.ndarray, background: np.ndarray, setup: Setup, threshold: float, region: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Ground truth as in the paper: background subtraction, binary detection (|change| > threshold), the
    centroid of the detected pixels in table coordinates [m] (NaN if none). Returns (centroid, binary mask)."""
    detected = np.abs(image - background) > threshold
    if region is not None:
        detected &= region
    if not detected.any():
        return np.full(2, np.nan), detected
    rows, cols = np.nonzero(detected)
    points = camera_pixel_to_table(setup, rows, cols, image.shape)
    return points.mean(axis=0), detected


def signed_change_centroid(image: np.ndarray, background: np.ndarray, setup: Setup,
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
    points = camera_pixel_to_table(setup, rows, cols, image.shape)
    return (points * change[..., None]).sum(axis=(0, 1)) / total


STRATIFIED_SHARE = 128  # the stratified dP estimator's rays per pass: the plain budget (setup.spp) / this (issue 10)


def locate_in_world(world, frames, background, setup: Setup, rng: np.random.Generator, predict, spp: int,
                    region: np.ndarray | None = None, axis: int | None = None,
                    show_progress: bool = False) -> tuple[dict, dict, list, np.ndarray]:
    """Render dP of every frame (correlated seeds), read it out with the sensor, detect, predict positions
    with ``predict(change_dn)``, propagate the noise, and compare with the ground-truth camera.

    ``axis`` picks one coordinate (1D experiments); ``region`` restricts the ground truth (e.g. the boundary
    band). Returns (summary dict, per-frame arrays, ground-truth images, background image).
    """
    from ..calibration import error_rates
    from ..estimators import detect_change
    from ..progress import progress

    dp, _ = world.measure_changes(frames, background, spp=spp, seed=setup.seed, show_progress=show_progress,
                                  estimator="stratified")
    bg_irr = np.asarray(dp.meta["background_w_m2"])
    frame_irr = bg_irr + dp.irradiance_w_m2
    readout = read_out(frame_irr, bg_irr, setup, rng)
    detected = detect_change(readout.frames_dn, readout.background_dn, readout.threshold_dn)
    change = readout.change_dn
    predicted = predict(change)
    predicted_ideal = predict(readout.ideal_change_dn(frame_irr, bg_irr))
    sigma = propagate_sigma(predict, change, readout.change_sigma_dn(frame_irr, bg_irr, dp.stderr_w_m2))
    sigma_sensor = propagate_sigma(predict, change, readout.change_sigma_dn(frame_irr, bg_irr))

    world.update(background)
    bg_image = world.camera_image(spp=32, seed=setup.seed)
    shape = (len(frames),) if axis is not None else (len(frames), 2)
    truth, signed = np.full(shape, np.nan), np.full(shape, np.nan)
    images = []
    pick = (lambda v: v[axis]) if axis is not None else (lambda v: v)
    for i in progress(range(len(frames)), desc="ground truth", disable=not show_progress):
        world.update(frames[i])
        image = world.camera_image(spp=32, seed=setup.seed)
        centroid, mask = change_centroid(image, bg_image, setup, 0.02 * float(bg_image.max()), region)
        truth[i] = pick(centroid) if mask.sum() >= 3 else np.nan
        signed[i] = pick(signed_change_centroid(image, bg_image, setup, region))
        images.append(image)
    world.update(background)

    def finite(a):
        return np.isfinite(a) if a.ndim == 1 else np.all(np.isfinite(a), axis=1)

    ok = detected & finite(truth) & finite(predicted)
    sigma_norm = sigma if sigma.ndim == 1 else np.hypot(*sigma.T)
    with np.errstate(divide="ignore", invalid="ignore"):
        dp_rel = np.abs(dp.stderr_w_m2 / dp.irradiance_w_m2)
    summary = {
        **error_rates(predicted[ok], truth[ok], setup.field_m),
        "frames": len(frames),
        "detected_frames": int(detected.sum()),
        "ground_truth_frames": int(finite(truth).sum()),
        "missed_frames": int((finite(truth) & ~detected).sum()),
        "false_alarm_frames": int((~finite(truth) & detected).sum()),
        "noiseless": error_rates(predicted_ideal[ok], truth[ok], setup.field_m),
        "signed_centroid_vs_ground_truth": error_rates(signed[ok], truth[ok], setup.field_m),
        "vs_signed_centroid": error_rates(predicted[ok], signed[ok], setup.field_m),
        "noise_sigma_median_pct": float(100 * np.median(sigma_norm[ok]) / setup.field_m) if ok.any() else None,
        "dP_worst_rel_stderr": float(np.nanmax(dp_rel[ok])) if ok.any() else None,
        "spp_per_mixel_per_frame": spp,
        "dP_estimator": dp.meta["estimator"],
        "rays_per_mixel_per_frame": dp.meta["rays_per_mixel_per_frame"],
        "exposure_s": readout.sensor.exposure_s,
    }
    arrays = {"predicted_m": predicted, "truth_m": truth, "signed_centroid_m": signed, "detected": detected,
              "evaluated": ok, "predicted_noiseless_m": predicted_ideal, "predicted_sigma_m": sigma,
              "sensor_sigma_m": sigma_sensor, "change_dn": change, "dP_w_m2": dp.irradiance_w_m2,
              "dP_stderr_w_m2": dp.stderr_w_m2}
    return summary, arrays, images, bg_image
