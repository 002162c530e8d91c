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

import functools
from dataclasses import asdict, dataclass

import numpy as np

from mincam_sim import masks as masks_mod
from mincam_sim import paper
from mincam_sim.design import checks
from mincam_sim.masks import Mask, PrintedFilm
from mincam_sim.model.geometry import Pose
from mincam_sim.model.optics import Mincam, layout, seen_whole_by_every_mixel
from mincam_sim.model.sensor import SensorModel

SPACING_M = paper.SPACING_M  # [m] distance from the centre to each mixel (paper's prototype)
D_F_M = paper.D_F_M  # [m] mask-to-detector distance
DETECTOR_SIZE_M = paper.DETECTOR_SIZE_M  # [m] detector side (48 x 48 pixels of 2.2 um)
MASK_SIZE_M = paper.MASK_SIZE_M  # [m] aperture side
FIELD_M = paper.FIELD_M  # [m] calibrated field (diameter) at the calibration depth
CALIBRATION_DEPTH_M = paper.CALIBRATION_DEPTH_M  # [m] the paper's calibration depth
DEPTH_RANGE_M = (0.35, 0.7)  # [m] working depths of the task
WORKING_RADIUS = 0.45  # objects lie within |q| <= 0.45 (90 % of the calibrated disc)
OBJECT_SIZE_RANGE_M = (0.02, 0.05)  # [m] side of the square objects
BIT_DEPTH = paper.ADC_BITS
EXPOSURE_FILL = 0.7
NAMES = ("x", "1-x", "y", "1-y")  # roles of the four mixels in Eq. 7 (left, right, top, bottom)
POSITIONS = ("left", "right", "top", "bottom")  # where each mixel sits, seen from behind the mincam
OFFSETS_M = ((-SPACING_M, 0.0), (SPACING_M, 0.0), (0.0, SPACING_M), (0.0, -SPACING_M))


class PrintedSizes:
    """What a task's size record (fields ``film_t_min``, ``film_t_max``, ``dpi``) derives: its JSON-able dict, the
    printed film and the grid of printer dots on a mask of ``MASK_SIZE_M``."""

    def as_dict(self) -> dict:
        return asdict(self)

    def film(self) -> PrintedFilm:
        return PrintedFilm(t_min=self.film_t_min, t_max=self.film_t_max, dpi=self.dpi)

    def dot_shape(self) -> tuple[int, int]:
        return self.film().grid_shape(MASK_SIZE_M, MASK_SIZE_M)


@dataclass(frozen=True)
class TrackingTask(PrintedSizes):
    """Sizes of one design run (``quick`` for the CLI's ``--quick``).

    Every field is checked on construction (the sizes' ranges: :func:`size_ranges`; the geometry, film and seed
    shared by every task: :data:`~.checks.SHARED`); a bad one is a :class:`~.checks.FieldError` naming it and its
    range.

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
    film_t_min, film_t_max : float
        The film's printable transmission range (:class:`~mincam_sim.masks.PrintedFilm`).
    decoder : {"learned", "eq7"}
        ``learned``: a cubic polynomial of :func:`features_learned`, fitted in the design loop on the training
        set and used as is at inference; ``eq7``: the paper's ratios with a cubic calibration on the physical
        sweep at 0.5 m (the baseline's protocol).
    decoder_fit : {"noiseless", "noisy"}
        ``noiseless``: the learned decoder is fitted on the noiseless read-out of the training set (as a
        calibration is) and the masks are optimised for its error on noisy read-outs; ``noisy``: fitted on
        noisy read-outs, which shrinks every prediction towards the centre when noisy frames (bright
        backgrounds) are in the training set.
    object_size_range_m : (float, float)
        Training objects' side (squares) or length (bars) [m], log-uniform.
    bar_fraction : float
        Share of training objects that are bars (``bar_width_range_m`` wide, horizontal or vertical).
    bar_width_range_m : (float, float)
        Bar widths [m].
    two_object_fraction : float
        Share of training frames with two objects on one plane (the target is the centroid of their change).
    background_radiances : tuple of float
        Background radiances [W m^-2 sr^-1] drawn uniformly per frame (0: a black plane). The background
        sets the frame's exposure (the brightest reading fills ``EXPOSURE_FILL``) and adds its shot noise to
        the change; textures are modelled by their mean.
    contrast_range, background_contrast_range : (float, float)
        Object radiance above a black plane, and above a grey one [W m^-2 sr^-1], uniform (capped at a
        radiance of 1): on a background, the objects to track stand out.
    depth_range_m : (float, float)
        Working depths [m]: the old held-out draw (:mod:`.evaluate`) spans it.
    spacing_m : float
        Distance of each mixel from the centre [m].
    d_f_m : float
        Mask-to-detector distance [m].
    suite_frames, suite_texels, suite_samples_per_texel : int
        Frames per held-out suite case, texels per side of its displays, response-map samples per texel.
    seed : int
        0 to 2^32 - 1.
    """

    train_depths_m: tuple[float, ...] = (0.35, 0.42, 0.49, 0.56, 0.63, 0.7)
    frames_per_depth: int = 256
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
    film_t_min: float = 0.02
    film_t_max: float = 0.9
    decoder: str = "learned"
    decoder_fit: str = "noiseless"
    object_size_range_m: tuple[float, float] = (0.01, 0.15)
    bar_fraction: float = 0.25
    bar_width_range_m: tuple[float, float] = (0.008, 0.02)
    two_object_fraction: float = 0.3
    background_radiances: tuple[float, ...] = (0.0, 0.0, 0.1, 0.2, 0.3, 0.45)
    contrast_range: tuple[float, float] = (0.05, 1.0)
    background_contrast_range: tuple[float, float] = (0.3, 1.0)
    depth_range_m: tuple[float, float] = DEPTH_RANGE_M
    spacing_m: float = SPACING_M
    d_f_m: float = D_F_M
    suite_frames: int = 60
    suite_texels: int = 224
    suite_samples_per_texel: int = 16
    seed: int = 0

    def __post_init__(self) -> None:
        def bad(field: str, what: str) -> None:
            checks.refuse(self, (field,), what)

        checks.check_shared(self)
        if not isinstance(self.decoder, str) or self.decoder not in FEATURES:
            bad("decoder", f"must be one of {', '.join(FEATURES)}")
        if self.decoder_fit not in ("noiseless", "noisy"):
            bad("decoder_fit", "must be 'noiseless' or 'noisy'")
        checks.check_ranges(self, size_ranges())
        for field in ("object_size_range_m", "bar_width_range_m", "contrast_range", "background_contrast_range",
                      "depth_range_m"):
            v = tuple(getattr(self, field))
            if len(v) != 2 or not all(checks.Range(0, np.inf, low_open=True).accepts(x) for x in v) or v[0] > v[1]:
                bad(field, "must be (min, max) with 0 < min <= max")
        if self.object_size_range_m[1] > 0.3:
            bad("object_size_range_m", "must stay <= 0.3 m (objects of the working field)")
        if self.bar_width_range_m[1] > 0.1:
            bad("bar_width_range_m", "must stay <= 0.1 m (bars narrower than the working field)")
        for field in ("contrast_range", "background_contrast_range"):
            if getattr(self, field)[1] > 1.0:
                bad(field, "must stay <= 1 W m^-2 sr^-1 (the display's white)")
        if not (0.1 <= self.depth_range_m[0] and self.depth_range_m[1] <= 3.0):
            bad("depth_range_m", "must lie within 0.1-3 m")
        depths = tuple(self.train_depths_m)
        if not 1 <= len(depths) <= MAX_TRAIN_DEPTHS or not all(checks.Range(0, 3).accepts(d) for d in depths):
            bad("train_depths_m", f"must be 1 to {MAX_TRAIN_DEPTHS} plane depths [m]")
        if not all(self.depth_range_m[0] - 1e-9 <= d <= self.depth_range_m[1] + 1e-9 for d in depths):
            bad("train_depths_m", f"must lie in depth_range_m {self.depth_range_m}")
        for field in ("bar_fraction", "two_object_fraction"):
            if not checks.Range(0, 1).accepts(getattr(self, field)):
                bad(field, "must be a fraction in [0, 1]")
        bg = tuple(self.background_radiances)
        if not bg or not all(checks.Range(0, 1).accepts(b) and b < 1 for b in bg):
            bad("background_radiances", "must be radiances in [0, 1) (0 = black plane)")
        n_terms = DECODER_TERMS[self.decoder]
        if self.frames_per_depth * len(depths) < n_terms:
            bad("frames_per_depth", f"x the {len(depths)} training depth(s) must give at least {n_terms} training "
                                    f"frames (the {self.decoder} decoder's cubic has {n_terms} coefficients per "
                                    "coordinate)")
        n_dots = int(np.prod(self.dot_shape()))
        checks.check_memory(self, ("frames_per_depth", "dpi"),
                            checks.memory_bytes(self.frames_per_depth * len(depths), n_dots, len(NAMES)),
                            "a training model (frames x printer dots x mixels)")
        checks.check_memory(self, ("eval_frames_per_depth", "screen_texels"),
                            checks.memory_bytes(self.eval_frames_per_depth, self.screen_texels**2),
                            "held-out frames (frames x texels^2)")
        checks.check_memory(self, ("suite_frames", "suite_texels"),
                            checks.memory_bytes(SUITE_CASES, self.suite_frames, self.suite_texels**2),
                            f"suite frames ({SUITE_CASES} cases x frames x texels^2)")

    @classmethod
    def quick(cls, seed: int = 0, **overrides) -> TrackingTask:
        params = dict(train_depths_m=(0.35, 0.42, 0.49, 0.56, 0.63, 0.7), frames_per_depth=256, strata=12,
                      grid=10, iterations=200, eval_depths=5, eval_frames_per_depth=40, screen_texels=128,
                      samples_per_texel=16, calibration_grid=9, suite_frames=24, suite_texels=160, seed=seed)
        params.update(overrides)
        return cls(**params)


    def mincam(self, masks: list[Mask]) -> Mincam:
        """:func:`mincam` with this task's spacing and ``d_f``."""
        return mincam(masks, self.spacing_m, self.d_f_m)

    def baseline_masks(self, resolution: int = 256) -> list[Mask]:
        """:func:`current_layout_masks` at this task's spacing."""
        return current_layout_masks(resolution, self.spacing_m)


def mincam(masks: list[Mask], spacing_m: float = SPACING_M, d_f_m: float = D_F_M) -> Mincam:
    """The four mixels ``spacing_m`` around the origin, looking along -z (at the plane), masks in
    :data:`POSITIONS` order (left, right, top, bottom)."""
    offsets = [(dx / SPACING_M * spacing_m, dy / SPACING_M * spacing_m) for dx, dy in OFFSETS_M]
    return layout(list(masks), offsets, list(NAMES), center=Pose((0.0, 0.0, 0.0), (0.0, 0.0, -1.0)),
                  d_f_m=d_f_m, detector_size_m=DETECTOR_SIZE_M)


def paper_masks(resolution: int = 256) -> list[Mask]:
    """The paper's hand-derived ramps x, 1 - x, y, 1 - y (exact profiles), x on the left mixel: the layout
    :func:`~mincam_sim.model.optics.cross_layout` built before 2026-12 (the design's baseline, kept so that its
    numbers stay comparable)."""
    return [masks_mod.ramp(k, resolution, MASK_SIZE_M) for k in NAMES]


def paper_masks_swapped_x(resolution: int = 256) -> list[Mask]:
    """The paper's ramps with the x pair exchanged (1 - x on the left mixel, x on the right): then, as for the
    y pair, each ramp is brightest on its own mixel's side, where that mixel sees objects nearest its axis
    (found by this design; :func:`~mincam_sim.model.optics.cross_layout` builds this layout since 2026-12)."""
    return [masks_mod.ramp(k, resolution, MASK_SIZE_M) for k in ("1-x", "x", "y", "1-y")]


def current_layout_masks(resolution: int = 256, spacing_m: float = SPACING_M) -> list[Mask]:
    """The ramps of the layout the package builds (:func:`~mincam_sim.model.optics.cross_layout` at this spacing and
    aperture), in :data:`POSITIONS` order (taken from where ``cross_layout`` puts each mixel): the baseline."""
    from mincam_sim.model.optics import cross_layout

    cam = cross_layout(spacing_m, resolution=resolution, mask_size_m=MASK_SIZE_M)
    where = {(int(np.sign(round(m.pose.position_m[0], 9))), int(np.sign(round(m.pose.position_m[1], 9)))): m
             for m in cam}
    return [where[(int(np.sign(dx)), int(np.sign(dy)))].mask for dx, dy in OFFSETS_M]


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
    some mixel does not see whole through its full aperture (:func:`~mincam_sim.model.optics.seen_whole_by_every_mixel`:
    there Eq. 7's ratio folds, and such points bend the whole cubic)."""
    half = WORKING_RADIUS * FIELD_M * CALIBRATION_DEPTH_M / CALIBRATION_DEPTH_M
    g = np.linspace(-half, half, n_per_axis)
    xy = np.array([(x, y) for y in g[::-1] for x in g])
    xy = xy[np.hypot(*xy.T) <= half + 1e-9]
    seen = seen_whole_by_every_mixel(mincam(paper_masks(2)), xy, CALIBRATION_SQUARE_M / 2, -CALIBRATION_DEPTH_M)
    return xy[seen]


CALIBRATION_SQUARE_M = paper.CALIBRATION_SQUARE_M  # [m] side of the calibration squares (as the experiments')

MAX_TRAIN_DEPTHS = 64  # training planes of one run
DECODER_TERMS = {"eq7": 10, "learned": 20}  # coefficients per coordinate of a cubic in 2 (Eq. 7) or 3 features
HELD_OUT_SCREEN_SIDE_M = 1.3 * FIELD_M  # [m] side of the held-out display at 0.5 m (.evaluate)
# the held-out suite's size (.suite.SUITE, which reads this module; a test keeps the two equal)
SUITE_CASES, SUITE_MOST_DEPTHS = 14, 4  # its cases, and the most depths one case shows
SUITE_SCREEN_SIDE_M = 2.0 * (0.6 * CALIBRATION_DEPTH_M + 0.05)  # [m] side of the suite's display at 0.5 m (.suite)


def min_texels(screen_side_m: float) -> int:
    """The fewest texels per side of a display of side ``screen_side_m`` [m] at 0.5 m whose texels are no larger
    than a calibration square (coarser texels smear the sweep's squares over shared texels, and its cubic fit
    loses rank: 4 texels per side already cannot determine its 10 coefficients)."""
    return int(np.ceil(screen_side_m / CALIBRATION_SQUARE_M - 1e-9))


@functools.lru_cache(maxsize=1)
def size_ranges() -> dict:
    """The allowed values of :class:`TrackingTask`'s numeric sizes (:class:`~.checks.Range` per field): the
    smallest values with which a run works and maxima that keep it within hours and memory."""
    from mincam_sim.budget import DEFAULT_MAP_REPLICATES
    Range = checks.Range  # noqa: N806 - the class, by its name
    spt = Range(DEFAULT_MAP_REPLICATES, 1024, integer=True,
                why=f"the response maps' {DEFAULT_MAP_REPLICATES} replicate blocks need a sample each")
    min_cal = next(n for n in range(2, 50) if len(calibration_positions(n)) >= DECODER_TERMS["eq7"])
    case_depths = SUITE_MOST_DEPTHS
    return {
        "frames_per_depth": Range(1, 20000, integer=True),
        "strata": Range(1, 64, integer=True, why="strata^2 samples per training object"),
        "grid": Range(2, 64, integer=True, why="logit nodes per mask side; a mask needs 2 to vary"),
        "iterations": Range(1, 100000, integer=True, why="Adam steps per start"),
        "learning_rate": Range(0, 10, low_open=True, why="Adam's step on the logits"),
        "eval_depths": Range(1, 100, integer=True),
        "eval_frames_per_depth": Range(1, 10000, integer=True),
        "screen_texels": Range(min_texels(HELD_OUT_SCREEN_SIDE_M), 1024, integer=True,
                               why="texels no larger than the 3 cm calibration squares"),
        "samples_per_texel": spt,
        "calibration_grid": Range(min_cal, 50, integer=True,
                                  why=f"{min_cal} gives {len(calibration_positions(min_cal))} squares in the working "
                                      f"disc, {min_cal - 1} only {len(calibration_positions(min_cal - 1))}; the "
                                      "cubic calibration has 10 coefficients"),
        "suite_frames": Range(case_depths, 10000, integer=True,
                              why=f"at least one per depth of a suite case with {case_depths} depths"),
        "suite_texels": Range(min_texels(SUITE_SCREEN_SIDE_M), 1024, integer=True,
                              why="texels no larger than the 3 cm calibration squares"),
        "suite_samples_per_texel": spt,
    }


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


def change_sigma_dn(s: SensorModel, irradiance_w_m2: np.ndarray, n_background_frames: int = 16,
                    background_w_m2: np.ndarray | float = 0.0) -> np.ndarray:
    """Noise of a background-subtracted change [DN]: the frame (background plus change ``irradiance_w_m2``)
    minus the mean of ``n_background_frames`` background readings (default: a black plane)."""
    var = (s.expected_std_dn(np.asarray(background_w_m2) + irradiance_w_m2) ** 2
           + s.expected_std_dn(background_w_m2) ** 2 / n_background_frames)
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
    "current_layout_masks",
    "random_objects",
    "read_out",
    "sensor",
    "to_field",
    "to_metres",
]
