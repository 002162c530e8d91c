"""Tasks as data: a scene distribution, a target, a metric with its direction, a decoder family and a held-out
suite, for tasks whose scenes are flat objects (or textured planes) on planes facing a four-mixel cross.

A task here is a :class:`TaskSpec` record (pure data: :mod:`.counting` and :mod:`.depth` are two of them); the
machinery that trains and measures masks for any such record is :mod:`.scene_design`. Every scene is a sum of
uniform rectangles ("atoms") on planes at known depths, so every mixel's reading is linear in its mask
(``E_k = A_k @ T_k``, :func:`mincam_sim.render.gradients.differentiable.design_matrix`) and linear in the atoms'
radiances: a frame's row is the sum of its atoms' rows times their radiance.

Coordinates are those of :mod:`.tracking`: the mincam at the origin looking along -z, planes at ``z = -depth_m``,
lateral positions drawn in normalised field coordinates (``|q| <= radius``, 1 = the 50 cm field at 0.5 m) and
converted to metres at the plane's depth. Pure numpy apart from the traced rows (render floor, imported late).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from mincam_sim.design import tracking as tr
from mincam_sim.design.checks import Range, check_memory, check_ranges, check_shared, memory_bytes
from mincam_sim.design.optimise import TrainingFrames
from mincam_sim.errors import ConfigError
from mincam_sim.estimation.polynomial import poly_terms
from mincam_sim.masks import Mask
from mincam_sim.model.optics import Mincam

SHAPES = ("square", "bar", "texture")


@dataclass(frozen=True)
class Distribution:
    """The scenes of a training set or of one held-out case.

    Attributes
    ----------
    depths_m : tuple of float
        Plane depths [m]; frame ``i`` lies on ``depths_m[i % len(depths_m)]``.
    counts : tuple of int
        Objects per frame, drawn uniformly from these (``texture``: ignored, one textured plane).
    size_range_m : (float, float)
        Side of the squares, or length of the bars [m], uniform.
    contrast_range : (float, float)
        Radiance of the objects (of the texture's patches) above the black plane [W m^-2 sr^-1], uniform.
    radius : float
        Object centres lie within ``|q| <= radius`` in normalised field coordinates (0.45: the tracking disc).
    shape : {"square", "bar", "texture"}
        ``bar``: ``bar_width_m`` wide, horizontal or vertical at random; ``texture``: a plane covering every
        mixel's field of view, tiled with square patches of side ``texture_patch_m`` of random radiance.
    bar_width_m, texture_patch_m : float
        [m].
    texture_fraction : float
        Share of frames (of a ``square`` or ``bar`` distribution) that are a textured plane instead of objects.
    """

    depths_m: tuple[float, ...]
    counts: tuple[int, ...] = (1,)
    size_range_m: tuple[float, float] = (0.05, 0.05)
    contrast_range: tuple[float, float] = (0.5, 1.0)
    radius: float = 0.45
    shape: str = "square"
    bar_width_m: float = 0.01
    texture_patch_m: float = 0.05
    texture_fraction: float = 0.0

    def __post_init__(self) -> None:
        def bad(field: str, what: str) -> None:
            raise ConfigError(f"Distribution.{field} {what}, got {getattr(self, field)!r}")

        if not self.depths_m or not all(np.isfinite(d) and 0.1 <= d <= 3.0 for d in self.depths_m):
            bad("depths_m", "must be plane depths in 0.1-3 m")
        if not self.counts or not all(int(c) == c and 0 <= c <= 8 for c in self.counts):
            bad("counts", "must be object counts 0-8")
        for field in ("size_range_m", "contrast_range"):
            v = tuple(getattr(self, field))
            if len(v) != 2 or not all(np.isfinite(v)) or not 0 < v[0] <= v[1]:
                bad(field, "must be (min, max) with 0 < min <= max")
        if self.contrast_range[1] > 1.0:
            bad("contrast_range", "must stay <= 1 W m^-2 sr^-1 (the display's white)")
        if not 0 < self.radius <= 0.5:
            bad("radius", "must be a field radius in (0, 0.5]")
        if self.shape not in SHAPES:
            bad("shape", f"must be one of {', '.join(SHAPES)}")
        if not 0 <= self.texture_fraction <= 1:
            bad("texture_fraction", "must be a fraction in [0, 1]")
        if not (0 < self.bar_width_m <= 0.1 and 0 < self.texture_patch_m <= 0.2):
            bad("bar_width_m", "and texture_patch_m must be 0-0.1 m and 0-0.2 m")


@dataclass(frozen=True)
class Case:
    """One held-out case: a short key, what it holds out in words, and its scenes."""

    name: str
    description: str
    scenes: Distribution


TARGETS = ("count", "log_depth")
OUTPUTS = ("count", "exp")
METRICS = {"accuracy_pct": False, "abs_rel_error_pct": True}  # metric -> lower is better


def features_raw(dn, xp=np):
    """Decoder inputs of a counting decoder: the four changes in units of the 12-bit range (not gain-free: a
    count needs the absolute level, at the task's fixed exposure)."""
    full = 2.0**tr.BIT_DEPTH - 1
    return tuple(d / full for d in dn)


FEATURES = {"raw": features_raw, "normalised": tr.features_learned}


@dataclass(frozen=True)
class TaskSpec:
    """A design task as data.

    Attributes
    ----------
    name, description : str
    train : Distribution
        The training scenes (its ``depths_m`` are the training planes).
    suite : tuple of Case
        The held-out suite: fixed cases outside (or at the edges of) the training distribution.
    target : {"count", "log_depth"}
        What the decoder regresses per frame (``log_depth``: ln of the plane's depth [ln m]).
    features : str
        Key of :data:`FEATURES`: the decoder's inputs from the four changes.
    degree : int
        Total degree of the decoder's polynomial.
    output : {"count", "exp"}
        The decoder's answer from its regression: ``count`` rounds and clips to ``[0, max(counts)]``,
        ``exp`` turns a log depth into metres.
    metric : str
        Key of :data:`METRICS` (its direction there).
    error_cap : float, optional
        The optimiser's robust loss: a frame's squared error counts at most ``error_cap**2`` [target units].
    starts : tuple of str
        Starting masks of the multi-start: ``ramps`` (the paper's, tracking layout), ``grey`` (mid grey with a
        small seeded perturbation), ``random`` (logits N(0, 1), seeded).
    decoder_family : str
        The decoder, in words (``design.json``).
    frames_per_depth : (int, int)
        Training frames per training plane of a ``--quick`` run and of a full one.
    grid : int
        Logit nodes per mask side (fewer nodes: smoother masks, less room to fit the training frames' own
        samples).
    learning_rate : float
        Adam's step on the logits.
    """

    name: str
    description: str
    train: Distribution
    suite: tuple[Case, ...]
    target: str
    features: str
    degree: int
    output: str
    metric: str
    error_cap: float | None
    starts: tuple[str, ...]
    decoder_family: str
    frames_per_depth: tuple[int, int] = (96, 192)
    grid: int = 8
    learning_rate: float = 0.08

    def __post_init__(self) -> None:
        if self.target not in TARGETS or self.output not in OUTPUTS or self.metric not in METRICS:
            raise ConfigError(f"TaskSpec {self.name!r}: target must be one of {TARGETS}, output one of {OUTPUTS}, "
                              f"metric one of {tuple(METRICS)}")
        if self.features not in FEATURES:
            raise ConfigError(f"TaskSpec {self.name!r}: features must be one of {', '.join(FEATURES)}")
        if not self.suite or len({c.name for c in self.suite}) != len(self.suite):
            raise ConfigError(f"TaskSpec {self.name!r}: the suite needs cases with distinct names")

    @property
    def lower_is_better(self) -> bool:
        return METRICS[self.metric]

    @property
    def max_count(self) -> int:
        return int(max(self.train.counts))

    def as_dict(self) -> dict:
        d = asdict(self)
        d["lower_is_better"] = self.lower_is_better
        return d


#: The allowed values of :class:`Sizes`' run sizes (the geometry, film and seed: :data:`~.checks.SHARED`).
SIZE_RANGES = {"frames_per_depth": Range(2, 20000, integer=True), "strata": Range(2, 64, integer=True),
               "grid": Range(2, 64, integer=True), "iterations": Range(2, 100000, integer=True),
               "learning_rate": Range(0, 10, low_open=True, why="Adam's step on the logits"),
               "suite_frames": Range(2, 10000, integer=True)}


@dataclass(frozen=True)
class Sizes(tr.PrintedSizes):
    """Sizes and geometry of one run of a scene task (``quick`` for the CLI's ``--quick``).

    Attributes
    ----------
    frames_per_depth : int
        Training frames per training plane.
    strata : int
        Samples per object = strata^2 (texture patches: ``max(3, strata // 3)``^2).
    grid : int
        Logit nodes per mask side.
    iterations, learning_rate : Adam's settings, per start.
    suite_frames : int
        Frames per held-out case.
    dpi, film_t_min, film_t_max : the film (:class:`~mincam_sim.masks.PrintedFilm`).
    spacing_m, d_f_m : float
        Distance of each mixel from the centre, mask-to-detector distance [m] (the paper's cross).
    seed : int
    """

    frames_per_depth: int = 160
    strata: int = 12
    grid: int = 10
    iterations: int = 200
    learning_rate: float = 0.08
    suite_frames: int = 60
    dpi: float = 600.0
    film_t_min: float = 0.02
    film_t_max: float = 0.9
    spacing_m: float = tr.SPACING_M
    d_f_m: float = tr.D_F_M
    seed: int = 0

    def __post_init__(self) -> None:
        check_shared(self)
        check_ranges(self, SIZE_RANGES)

    @classmethod
    def quick(cls, seed: int = 0, **overrides) -> Sizes:
        params = dict(frames_per_depth=96, strata=8, grid=8, iterations=120, suite_frames=80, seed=seed)
        params.update(overrides)
        return cls(**params)


    def mincam(self, masks: list[Mask]) -> Mincam:
        return tr.mincam(masks, self.spacing_m, self.d_f_m)


#: [B] one traced sample takes while a plane's samples are traced (Dr.Jit's lanes and numpy's bins; measured: 200
#: B at 2.4 M samples a call, more per sample on small calls).
TRACED_SAMPLE_BYTES = 200.0


def check_sizes_fit(spec: TaskSpec, sizes: Sizes) -> None:
    """Refuse ``sizes`` whose arrays would not fit in memory (:data:`~.checks.MEMORY_LIMIT_BYTES`), naming the
    fields: the training model and a held-out case's model (frames x printer dots x the four mixels, float64), and
    the samples of a training plane traced at once (its frames x the most objects a frame holds x ``strata``^2)."""
    dots = int(np.prod(sizes.dot_shape()))
    n_train = sizes.frames_per_depth * len(spec.train.depths_m)
    check_memory(sizes, ("frames_per_depth", "dpi"), memory_bytes(n_train, dots, len(tr.NAMES)),
                 f"a training model ({n_train} frames x {dots} printer dots x {len(tr.NAMES)} mixels)")
    check_memory(sizes, ("suite_frames", "dpi"), memory_bytes(sizes.suite_frames, dots, len(tr.NAMES)),
                 f"a held-out case's model ({sizes.suite_frames} frames x {dots} printer dots x {len(tr.NAMES)} "
                 "mixels)")
    samples = sizes.frames_per_depth * max(1, max(spec.train.counts)) * sizes.strata**2
    check_memory(sizes, ("frames_per_depth", "strata"), samples * TRACED_SAMPLE_BYTES,
                 f"{samples} traced samples of a training plane at once (frames x objects x strata^2)")


@dataclass
class Frames:
    """Drawn frames: the atoms per plane (:class:`TrainingFrames`, what the tracers and the idealised model read)
    and each frame's labels."""

    planes: TrainingFrames
    count: np.ndarray  # (n,) objects per frame (textured planes: 0)
    depth_m: np.ndarray  # (n,) the frame's plane depth [m]
    patch: list | None = None  # per plane, (n_atoms,) bool: the atom is a texture patch (traced with fewer samples)

    def targets(self, target: str) -> np.ndarray:
        """(n, 1) regression targets."""
        if target == "count":
            return self.count.astype(np.float64)[:, None]
        return np.log(self.depth_m)[:, None]

    def __len__(self) -> int:
        return len(self.count)


def _objects(dist: Distribution, depth_m: float, n: int, rng: np.random.Generator) -> list[tuple]:
    """``n`` non-overlapping objects (cx, cy, w, h, radiance) [m, m, m, m, W m^-2 sr^-1] on a plane at
    ``depth_m`` (rejection: 50 tries, then the last draw)."""
    for _ in range(50):
        r = dist.radius * np.sqrt(rng.random(n))
        phi = 2 * np.pi * rng.random(n)
        q = np.column_stack([r * np.cos(phi), r * np.sin(phi)])
        xy = tr.to_metres(q, depth_m)
        dims = []
        for _i in range(n):
            length = rng.uniform(*dist.size_range_m)
            if dist.shape == "bar":
                dims.append((length, dist.bar_width_m) if rng.random() < 0.5 else (dist.bar_width_m, length))
            else:
                dims.append((length, length))
        reach = [0.75 * max(w, h) for w, h in dims]
        if all(np.hypot(*(xy[i] - xy[j])) > reach[i] + reach[j] for i in range(n) for j in range(i)):
            break
    return [(xy[i, 0], xy[i, 1], dims[i][0], dims[i][1], rng.uniform(*dist.contrast_range)) for i in range(n)]


def _texture(dist: Distribution, depth_m: float, rng: np.random.Generator) -> list[tuple]:
    """Square patches of random radiance tiling a plane that covers every mixel's field of view."""
    half = 0.6 * depth_m + 0.05
    n = int(np.ceil(2 * half / dist.texture_patch_m))
    c = (np.arange(n) + 0.5) * dist.texture_patch_m - n * dist.texture_patch_m / 2
    p = dist.texture_patch_m
    return [(x, y, p, p, rng.uniform(*dist.contrast_range)) for y in c for x in c]


def draw_frames(dist: Distribution, n_frames: int, seed) -> Frames:
    """``n_frames`` frames of ``dist`` from the generator seeded with ``seed`` (an int or a sequence)."""
    from mincam_sim.render.gradients.differentiable import SquareScenes

    rng = np.random.default_rng(seed)
    depths = np.asarray(dist.depths_m, dtype=np.float64)
    per_plane: list[list] = [[] for _ in depths]
    frame_atoms, counts, depth_index = [], [], []
    patch: list[list] = [[] for _ in depths]
    for i in range(n_frames):
        di = i % len(depths)
        textured = dist.shape == "texture" or (dist.texture_fraction > 0 and rng.random() < dist.texture_fraction)
        if textured:
            objs, count = _texture(dist, depths[di], rng), 0
        else:
            count = int(rng.choice(dist.counts))
            objs = _objects(dist, depths[di], count, rng) if count else []
        atoms = []
        for cx, cy, w, h, radiance in objs:
            per_plane[di].append((cx, cy, w, h))
            patch[di].append(textured)
            atoms.append((di, len(per_plane[di]) - 1, radiance))
        frame_atoms.append(atoms)
        counts.append(count)
        depth_index.append(di)
    planes = [SquareScenes(float(d), np.array(a)[:, :2], np.array(a)[:, 2], 1.0, np.array(a)[:, 3]) if a else None
              for d, a in zip(depths, per_plane, strict=True)]
    frames = TrainingFrames(planes, frame_atoms, np.zeros(n_frames), np.array(depth_index))
    return Frames(frames, np.array(counts), depths[np.array(depth_index)], [np.array(p, dtype=bool) for p in patch])


def frame_rows(samples, atom_frame: np.ndarray, atom_radiance: np.ndarray, n_frames: int,
               dot_shape: tuple[int, int]) -> np.ndarray:
    """Per-frame rows (n_frames, D) [W/m^2 per unit transmission] from the traced samples of unit-radiance
    atoms: each atom's samples binned per printer dot (as
    :func:`~mincam_sim.render.gradients.differentiable.design_matrix`), times its radiance, into its frame's row
    (no per-atom matrix: a textured plane holds hundreds of atoms)."""
    from mincam_sim.render.gradients import autodiff

    detach = autodiff.namespace().detach
    h, w = dot_shape
    u = np.asarray(detach(samples.u), dtype=np.float64)
    v = np.asarray(detach(samples.v), dtype=np.float64)
    g = np.asarray(detach(samples.weight), dtype=np.float64)
    col = np.clip(np.floor(u * w).astype(np.int64), 0, w - 1)
    row = np.clip(np.floor(v * h).astype(np.int64), 0, h - 1)
    atom = np.arange(len(g)) // samples.per_frame
    flat = atom_frame[atom] * (h * w) + row * w + col
    a = np.bincount(flat, weights=g * atom_radiance[atom], minlength=n_frames * h * w) / samples.per_frame
    return a.reshape(n_frames, h * w)


def traced_rows(sizes: Sizes, frames: Frames, seed: int) -> list[np.ndarray]:
    """The physical linear model: per mixel the frames' rows (n_frames, D) [W/m^2 per unit transmission],
    traced through the mincam's geometry (Monte Carlo, ``seed``), binned per printer dot. Objects get
    ``strata``^2 samples, texture patches ``max(3, strata // 3)``^2."""
    from mincam_sim.render.gradients import differentiable as dz

    dots = sizes.dot_shape()
    n_frames = len(frames)
    cam = sizes.mincam(tr.paper_masks(8))  # the geometry; masks are the design variables
    bodies = dz.bodies_scene(cam)
    owners = _atom_owners(frames)
    out = [np.zeros((n_frames, int(np.prod(dots)))) for _ in cam]
    for i, sc in enumerate(frames.planes.atoms):
        if sc is None:
            continue
        is_patch = frames.patch[i] if frames.patch is not None else np.zeros(len(sc), dtype=bool)
        for part, strata in ((~is_patch, sizes.strata), (is_patch, max(3, sizes.strata // 3))):
            if not part.any():
                continue
            sub = dz.SquareScenes(sc.depth_m, sc.centers_m[part], sc.sizes_m[part], 1.0, sc.heights_m[part])
            frame_of, radiance = owners[i][0][part], owners[i][1][part]
            part_seed = seed * 1000 + 2 * i + int(part is is_patch)
            for k in range(len(cam)):
                smp = dz.mixel_samples(cam, k, sub, strata=strata, seed=part_seed, bodies=bodies)
                out[k] += frame_rows(smp, frame_of, radiance, n_frames, dots)
    return out


def _atom_owners(frames: Frames) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per plane, each atom's frame and radiance."""
    owners = [(np.zeros(len(sc) if sc is not None else 0, dtype=np.int64),
               np.zeros(len(sc) if sc is not None else 0)) for sc in frames.planes.atoms]
    for f, atoms in enumerate(frames.planes.frame_atoms):
        for di, ai, radiance in atoms:
            owners[di][0][ai] = f
            owners[di][1][ai] = radiance
    return owners


@dataclass
class SceneDecoder:
    """``output(poly(features(dn)) @ coefficients.T)``: the task's answer from the four changes [DN].

    Attributes
    ----------
    features : str
        Key of :data:`FEATURES`.
    degree : int
    coefficients : (1, n_terms) ndarray
    output : {"count", "exp"}
    max_count : int
        Counts are clipped to ``[0, max_count]``.
    """

    features: str
    degree: int
    coefficients: np.ndarray
    output: str
    max_count: int = 3

    def regress(self, dn: np.ndarray) -> np.ndarray:
        """The regression (n,) before the output transform; NaN where a feature is undefined."""
        dn = np.asarray(dn, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            terms = np.stack(poly_terms(*FEATURES[self.features](list(dn.T)), degree=self.degree), axis=-1)
            return terms @ self.coefficients[0]

    def __call__(self, dn: np.ndarray) -> np.ndarray:
        """Counts (rounded, clipped; -1 where undefined) or depths [m] (NaN where undefined), (n,)."""
        r = self.regress(dn)
        if self.output == "count":
            return np.where(np.isfinite(r), np.clip(np.rint(np.nan_to_num(r)), 0, self.max_count), -1.0)
        with np.errstate(over="ignore", invalid="ignore"):
            return np.exp(r)

    def as_dict(self) -> dict:
        return {"kind": "mincam_sim.design.SceneDecoder", "features": self.features, "degree": self.degree,
                "coefficients": np.asarray(self.coefficients).tolist(), "output": self.output,
                "max_count": self.max_count}


def fit_decoder(spec: TaskSpec, dn: np.ndarray, targets: np.ndarray) -> SceneDecoder:
    """Least-squares polynomial of the task's features on read-outs ``dn`` (n, 4) [DN] and ``targets`` (n, 1);
    frames with an undefined feature are left out."""
    with np.errstate(divide="ignore", invalid="ignore"):
        terms = np.stack(poly_terms(*FEATURES[spec.features](list(np.asarray(dn, dtype=np.float64).T)),
                                    degree=spec.degree), axis=-1)
    ok = np.all(np.isfinite(terms), axis=1)
    coef = np.linalg.lstsq(terms[ok], targets[ok, 0], rcond=None)[0][None, :]
    return SceneDecoder(spec.features, spec.degree, coef, spec.output, spec.max_count)


def score(spec: TaskSpec, predicted: np.ndarray, frames: Frames) -> np.ndarray:
    """Per-frame score: 1/0 for a right/wrong count (``accuracy_pct`` averages it x 100) or ``|d' - d| / d``
    capped at 1 (an undefined depth counts 1) for ``abs_rel_error_pct``."""
    if spec.metric == "accuracy_pct":
        return (predicted == frames.count).astype(np.float64)
    err = np.abs(predicted - frames.depth_m) / frames.depth_m
    return np.where(np.isfinite(err), np.minimum(err, 1.0), 1.0)


def metric(spec: TaskSpec, per_frame: np.ndarray) -> float:
    """The task's metric [%] from per-frame scores."""
    return float(100 * np.mean(per_frame))


__all__ = ["FEATURES", "METRICS", "SHAPES", "Case", "Distribution", "Frames", "SceneDecoder", "Sizes", "TaskSpec",
           "draw_frames", "features_raw", "fit_decoder", "frame_rows", "metric", "score", "traced_rows"]
