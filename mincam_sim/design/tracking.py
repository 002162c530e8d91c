"""Task ``tracking``: four mixels 3.3 cm apart (the paper's cross, Sec. 4.2) locating one object on a plane at
an unknown depth between 0.35 and 0.7 m, with the paper's estimator (Eq. 7 ratios) and a cubic calibration.

Coordinates: the mincam sits at the origin looking along -z, the object plane is ``z = -depth_m``. Positions
are reported in *normalised field coordinates* ``q = position_m * calibration_depth / (depth_m * field_m)``:
the direction of the object, in units of the calibrated field of view (50 cm at 0.5 m, so ``|q| <= 0.5``
is the calibrated disc). A position error of 1 % is 0.01 in ``q`` (5 mm at 0.5 m, 3.5 mm at 0.35 m): the
convention of the spacing study, in which the calibration fitted at 0.5 m is scaled by ``depth / 0.5``.
Pure numpy.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .. import masks as masks_mod
from ..geometry import Pose
from ..masks import Mask, PrintedFilm
from ..optics import Mincam, layout, seen_whole_by_every_mixel
from ..sensor import SensorModel

SPACING_M = 0.033  # [m] distance from the centre to each mixel (paper's prototype)
D_F_M = 2e-3  # [m] mask-to-detector distance
DETECTOR_SIZE_M = 1e-4  # [m] detector side (48 x 48 pixels of 2.2 um)
MASK_SIZE_M = 2e-3  # [m] aperture side
FIELD_M = 0.5  # [m] calibrated field (diameter) at the calibration depth
CALIBRATION_DEPTH_M = 0.5  # [m] the paper's calibration depth
DEPTH_RANGE_M = (0.35, 0.7)  # [m] working depths of the task
WORKING_RADIUS = 0.45  # objects lie within |q| <= 0.45 (90 % of the calibrated disc)
OBJECT_SIZE_RANGE_M = (0.02, 0.05)  # [m] side of the square objects
BIT_DEPTH = 12
EXPOSURE_FILL = 0.7
NAMES = ("x", "1-x", "y", "1-y")  # roles of the four mixels in Eq. 7 (left, right, top, bottom)
POSITIONS = ("left", "right", "top", "bottom")  # where each mixel sits, seen from behind the mincam
OFFSETS_M = ((-SPACING_M, 0.0), (SPACING_M, 0.0), (0.0, SPACING_M), (0.0, -SPACING_M))


@dataclass(frozen=True)
class TrackingTask:
    """Sizes of one design run (``quick`` for the CLI's ``--quick``).

    Attributes
    ----------
    train_depths_m : tuple of float
        Depths of the training planes [m].
    frames_per_depth : int
        Training objects per depth.
    strata : int
        Samples per training object = strata^2 (stratified over the object, random detector points).
    grid : int
        Logit nodes per mask side.
    iterations, learning_rate : optimiser settings (Adam).
    eval_depths : int
        Held-out depths drawn uniformly in ``DEPTH_RANGE_M``.
    eval_frames_per_depth : int
        Held-out objects per depth.
    screen_texels : int
        Texels per side of the held-out displays (physical evaluation).
    samples_per_texel : int
        Response-map samples per texel (physical evaluation).
    calibration_grid : int
        Squares per axis of the calibration sweep at 0.5 m (clipped to the 50 cm disc).
    dpi : float
        Printer resolution [dots per inch] of the film.
    decoder : {"learned", "eq7"}
        ``learned``: a cubic polynomial of :func:`features_learned`, fitted in the design loop on the training
        depths and used as is at inference; ``eq7``: the paper's ratios with a cubic calibration on the
        physical sweep at 0.5 m (the baseline's protocol).
    seed : int
    """

    train_depths_m: tuple[float, ...] = (0.35, 0.42, 0.5, 0.6, 0.7)
    frames_per_depth: int = 160
    strata: int = 16
    grid: int = 12
    iterations: int = 400
    learning_rate: float = 0.08
    eval_depths: int = 8
    eval_frames_per_depth: int = 80
    screen_texels: int = 192
    samples_per_texel: int = 36
    calibration_grid: int = 15
    dpi: float = 600.0
    decoder: str = "learned"
    seed: int = 0

    def __post_init__(self) -> None:
        if self.decoder not in FEATURES:
            raise ValueError(f"TrackingTask.decoder must be one of {', '.join(FEATURES)}, got {self.decoder!r}")

    @classmethod
    def quick(cls, seed: int = 0) -> TrackingTask:
        return cls(train_depths_m=(0.35, 0.45, 0.57, 0.7), frames_per_depth=192, strata=12, grid=10,
                   iterations=200, eval_depths=5, eval_frames_per_depth=40, screen_texels=128,
                   samples_per_texel=16, calibration_grid=9, seed=seed)

    def as_dict(self) -> dict:
        return asdict(self)

    def film(self) -> PrintedFilm:
        return PrintedFilm(dpi=self.dpi)

    def dot_shape(self) -> tuple[int, int]:
        return self.film().grid_shape(MASK_SIZE_M, MASK_SIZE_M)


def mincam(masks: list[Mask]) -> Mincam:
    """The four mixels around the origin, looking along -z (at the plane), masks in :data:`NAMES` order."""
    return layout(list(masks), list(OFFSETS_M), list(NAMES), center=Pose((0.0, 0.0, 0.0), (0.0, 0.0, -1.0)),
                  d_f_m=D_F_M, detector_size_m=DETECTOR_SIZE_M)


def paper_masks(resolution: int = 256) -> list[Mask]:
    """The paper's hand-derived ramps x, 1 - x, y, 1 - y (exact profiles), x on the left mixel: the layout
    :func:`~mincam_sim.optics.cross_layout` built before 2026-12 (the design's baseline, kept so that its
    numbers stay comparable)."""
    return [masks_mod.ramp(k, resolution, MASK_SIZE_M) for k in NAMES]


def paper_masks_swapped_x(resolution: int = 256) -> list[Mask]:
    """The paper's ramps with the x pair exchanged (1 - x on the left mixel, x on the right): then, as for the
    y pair, each ramp is brightest on its own mixel's side, where that mixel sees objects nearest its axis
    (found by this design; :func:`~mincam_sim.optics.cross_layout` builds this layout since 2026-12)."""
    return [masks_mod.ramp(k, resolution, MASK_SIZE_M) for k in ("1-x", "x", "y", "1-y")]


def to_metres(q: np.ndarray, depth_m: float) -> np.ndarray:
    """Plane position [m] of normalised field coordinates at ``depth_m``."""
    return np.asarray(q) * FIELD_M * depth_m / CALIBRATION_DEPTH_M


def to_field(position_m: np.ndarray, depth_m: float) -> np.ndarray:
    """Normalised field coordinates of plane positions [m] at ``depth_m``."""
    return np.asarray(position_m) * CALIBRATION_DEPTH_M / (FIELD_M * depth_m)


def random_objects(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` objects: field positions uniform in the working disc, sides [m] and radiances [W m^-2 sr^-1]."""
    r = WORKING_RADIUS * np.sqrt(rng.random(n))
    phi = 2 * np.pi * rng.random(n)
    q = np.column_stack([r * np.cos(phi), r * np.sin(phi)])
    sizes = rng.uniform(*OBJECT_SIZE_RANGE_M, n)
    radiance = rng.uniform(0.5, 1.0, n)
    return q, sizes, radiance


def calibration_positions(n_per_axis: int) -> np.ndarray:
    """Square centres [m] of the calibration sweep at 0.5 m: a grid clipped to the working disc
    (``WORKING_RADIUS`` of the 50 cm field, the range in which objects are tracked), without the squares that
    some mixel does not see whole through its full aperture (:func:`~mincam_sim.optics.seen_whole_by_every_mixel`:
    there Eq. 7's ratio folds, and such points bend the whole cubic)."""
    half = WORKING_RADIUS * FIELD_M * CALIBRATION_DEPTH_M / CALIBRATION_DEPTH_M
    g = np.linspace(-half, half, n_per_axis)
    xy = np.array([(x, y) for y in g[::-1] for x in g])
    xy = xy[np.hypot(*xy.T) <= half + 1e-9]
    seen = seen_whole_by_every_mixel(mincam(paper_masks(2)), xy, CALIBRATION_SQUARE_M / 2, -CALIBRATION_DEPTH_M)
    return xy[seen]


CALIBRATION_SQUARE_M = 0.03  # [m] side of the calibration squares (paper Sec. 4.2.1)


def features(dn, xp=np):
    """Decoder inputs: the paper's Eq. 7 ratios ``dP1 / (dP1 + dP2)`` and ``dP3 / (dP3 + dP4)``, centred.

    ``dn`` is a sequence of the four mixels' changes [DN]; ``xp`` the array namespace (NumPy or Dr.Jit).
    """
    fx = dn[0] / (dn[0] + dn[1])
    fy = dn[2] / (dn[2] + dn[3])
    return 2.0 * (fx - 0.5), 2.0 * (fy - 0.5)


def features_learned(dn, xp=np):
    """Decoder inputs of the learned decoder: all four changes normalised by their sum (three independent
    ratios, so the balance between the x and y pairs, which moves with depth through the field-of-view
    offsets, is available to the decoder). Gain-free, like Eq. 7."""
    total = dn[0] + dn[1] + dn[2] + dn[3]
    return (dn[0] - dn[1]) / total, (dn[2] - dn[3]) / total, (dn[0] + dn[1] - dn[2] - dn[3]) / total


FEATURES = {"eq7": features, "learned": features_learned}


def sensor() -> SensorModel:
    """The paper's 12-bit mixel read-out (48 x 48 pixels averaged)."""
    return SensorModel.paper_prototype(bit_depth=BIT_DEPTH)


def change_sigma_dn(s: SensorModel, irradiance_w_m2: np.ndarray, n_background_frames: int = 16) -> np.ndarray:
    """Noise of a background-subtracted change [DN] on a black plane (background irradiance 0)."""
    var = s.expected_std_dn(irradiance_w_m2) ** 2 + s.expected_std_dn(0.0) ** 2 / n_background_frames
    return np.sqrt(var)


def read_out(irradiance_w_m2: np.ndarray, s: SensorModel, rng: np.random.Generator,
             n_background_frames: int = 16) -> np.ndarray:
    """Noisy change [DN] of each reading against a black plane: frames minus the mean of background frames."""
    background = s.measure(np.zeros((n_background_frames, irradiance_w_m2.shape[-1])), rng).mean(axis=0)
    return s.measure(irradiance_w_m2, rng) - background


__all__ = [
    "CALIBRATION_DEPTH_M",
    "DEPTH_RANGE_M",
    "FIELD_M",
    "NAMES",
    "POSITIONS",
    "TrackingTask",
    "calibration_positions",
    "change_sigma_dn",
    "FEATURES",
    "features",
    "features_learned",
    "mincam",
    "paper_masks",
    "paper_masks_swapped_x",
    "random_objects",
    "read_out",
    "sensor",
    "to_field",
    "to_metres",
]
