"""The held-out suite of a design report: a fixed list of cases outside the training set, each evaluated in the
physical simulator (response maps of the masks as printed,
:meth:`mincam_sim.render.simulation.Simulation.response_maps`) with the 12-bit sensor, for the designed masks
and, beside them, the baseline: the paper's ramps in the layout the package builds
(:func:`mincam_sim.model.optics.cross_layout`) with Eq. 7 and the cubic calibration on a sweep of 3 cm squares at
0.5 m on a black plane (the experiments' protocol).

Every frame's target is the centroid of the *change* (radiance change times area, over all its objects,
mapped to normalised field coordinates through the direction of the 3D centroid: :mod:`.tracking`), which for
one object is its centre. A background (grey or textured) is a static scene: each frame is the background with
the objects painted over it; the read-out is the frame minus the mean of 16 background frames, both noisy, at
an exposure at which the case's brightest reading fills ``EXPOSURE_FILL`` of the range. So a background that
fills the exposure shortens it and adds its shot noise to the change.

The frame numbers come from the case's own seed; the geometry of the frames does not depend on the masks.
Pure numpy apart from the response maps (render floor).
"""

from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass

import numpy as np

from mincam_sim.design import tracking as tr
from mincam_sim.estimation.calibration import Calibration2D, ExtrapolationWarning
from mincam_sim.model.geometry import Pose
from mincam_sim.model.optics import Mincam
from mincam_sim.progress import progress
from mincam_sim.scene.display import Screen, coverage

N_BACKGROUND_FRAMES = 16
TILT_DEG = 18.0  # the tilted case: plane rotated about the vertical axis


@dataclass(frozen=True)
class Case:
    """One held-out case.

    Attributes
    ----------
    name : str
        Short key (``design.json``, figure).
    description : str
        What it holds out, in words.
    depths_m : tuple of float
        Plane depths [m] (frames cycle through them).
    shape : {"square", "disc", "bar"}
        Object shape (bars: ``size`` long, ``bar_width_m`` wide, horizontal or vertical at random).
    size_range_m : (float, float)
        Side, diameter or bar length [m], uniform.
    n_objects : int
        Objects per frame (non-overlapping; the target is the centroid of their change).
    radiance_range : (float, float)
        Object radiance [W m^-2 sr^-1], uniform.
    background : {"black", "grey", "texture"}
        The plane around the objects.
    background_radiance : float
        Mean background radiance [W m^-2 sr^-1] (``grey``, ``texture``).
    tilt_deg : float
        Rotation of the plane about the vertical axis through its centre [deg].
    """

    name: str
    description: str
    depths_m: tuple[float, ...] = (0.4, 0.5, 0.6, 0.7)
    shape: str = "square"
    size_range_m: tuple[float, float] = (0.02, 0.05)
    n_objects: int = 1
    radiance_range: tuple[float, float] = (0.5, 1.0)
    background: str = "black"
    background_radiance: float = 0.0
    tilt_deg: float = 0.0
    bar_width_m: float = 0.01


SUITE: tuple[Case, ...] = (
    Case("reference", "squares 2-5 cm, black plane, 0.4-0.7 m (the old training distribution)"),
    Case("at_0.5m", "squares 2-5 cm at the calibration depth only", depths_m=(tr.CALIBRATION_DEPTH_M,)),
    Case("size_1cm", "squares 1 cm", size_range_m=(0.009, 0.011)),
    Case("size_10cm", "squares 9-11 cm", size_range_m=(0.09, 0.11)),
    Case("size_14cm", "squares 13-15 cm", size_range_m=(0.13, 0.15)),
    Case("discs", "discs 3-8 cm across", shape="disc", size_range_m=(0.03, 0.08)),
    Case("bars", "bars 1 cm wide, 6-12 cm long", shape="bar", size_range_m=(0.06, 0.12)),
    Case("two_objects", "two squares 2-6 cm, target the centroid of the change", size_range_m=(0.02, 0.06),
         n_objects=2),
    Case("grey_background", "squares 2-5 cm of radiance 0.8-1 on a uniform grey plane of 0.3",
         radiance_range=(0.8, 1.0), background="grey", background_radiance=0.3),
    Case("textured_background", "squares 2-5 cm of radiance 0.8-1 on a textured plane of mean 0.3 (+-50 %)",
         radiance_range=(0.8, 1.0), background="texture", background_radiance=0.3),
    Case("dim", "squares 2-5 cm of radiance 0.05-0.1 (low contrast) on black", radiance_range=(0.05, 0.1)),
    Case("depth_0.3m", "squares 2-5 cm at 0.3 m (nearer than the working range)", depths_m=(0.3,)),
    Case("depth_0.8m", "squares 2-5 cm at 0.8 m (farther than the working range)", depths_m=(0.8,)),
    Case("tilt_18deg", "squares 2-5 cm on a plane at 0.5 m tilted 18 deg", depths_m=(0.5,), tilt_deg=TILT_DEG),
)


def case_names() -> list[str]:
    return [c.name for c in SUITE]


# ---------------------------------------------------------------------------------------------------------
# Frames


def suite_screen(depth_m: float, texels: int, tilt_deg: float = 0.0) -> Screen:
    """A display covering every mixel's whole field of view at ``depth_m`` (so a background fills it)."""
    side = 2.0 * (0.6 * depth_m + 0.05)
    t = np.deg2rad(tilt_deg)
    return Screen(side, side, (texels, texels), Pose((0.0, 0.0, -depth_m), (np.sin(t), 0.0, np.cos(t))))


def q_of_world(points_m: np.ndarray) -> np.ndarray:
    """Normalised field coordinates of the directions of world points (mincam at the origin, looking along -z)."""
    p = np.asarray(points_m, dtype=np.float64)
    return tr.to_field(p[..., :2], -p[..., 2])


def _screen_point_of_q(screen: Screen, q: np.ndarray) -> np.ndarray:
    """Screen coordinates (n, 2) [m] where the directions of field positions ``q`` meet the screen plane."""
    d = np.column_stack([np.asarray(q) * tr.FIELD_M / tr.CALIBRATION_DEPTH_M, -np.ones(len(q))])
    centre = np.asarray(screen.pose.position_m)
    normal = np.asarray(screen.pose.axes()[2])
    s = (centre @ normal) / (d @ normal)
    x, y = screen.from_world(d * s[:, None])
    return np.column_stack([x, y])


def _disc(screen: Screen, cx: float, cy: float, diameter_m: float, sub: int = 4) -> np.ndarray:
    """Fraction of each texel inside a disc (``sub x sub`` samples per texel, only near the disc)."""
    cols, rows = screen.resolution
    tw, th = screen.texel_size_m
    x, y = screen.texel_centers_m()
    out = np.zeros(screen.shape)
    near = np.hypot(x - cx, y - cy) <= diameter_m / 2 + np.hypot(tw, th)
    offs = (np.arange(sub) + 0.5) / sub - 0.5
    for ox in offs:
        for oy in offs:
            out[near] += np.hypot(x[near] + ox * tw - cx, y[near] + oy * th - cy) <= diameter_m / 2
    return out / sub**2


def object_coverage(screen: Screen, shape: str, centre_m: np.ndarray, size_m: float, horizontal: bool,
                    bar_width_m: float) -> np.ndarray:
    """Per-texel coverage (rows, cols) of one object centred at ``centre_m`` (screen coordinates [m])."""
    cx, cy = centre_m
    if shape == "square":
        h = size_m / 2
        return coverage(screen, cx - h, cx + h, cy - h, cy + h)
    if shape == "disc":
        return _disc(screen, cx, cy, size_m)
    if shape == "bar":
        hx, hy = (size_m / 2, bar_width_m / 2) if horizontal else (bar_width_m / 2, size_m / 2)
        return coverage(screen, cx - hx, cx + hx, cy - hy, cy + hy)
    raise ValueError(f"Case.shape must be square, disc or bar, got {shape!r}")


def background_image(case: Case, screen: Screen, rng: np.random.Generator) -> np.ndarray:
    """The plane's radiance (rows, cols) without objects: black, uniform grey, or a smooth random texture of
    mean ``background_radiance`` and +-50 % amplitude (features ~4 cm)."""
    if case.background == "black":
        return np.zeros(screen.shape)
    if case.background == "grey":
        return np.full(screen.shape, case.background_radiance)
    if case.background != "texture":
        raise ValueError(f"Case.background must be black, grey or texture, got {case.background!r}")
    nodes = max(4, int(round(screen.width_m / 0.04)))
    coarse = rng.uniform(-1.0, 1.0, (nodes, nodes))
    rows, cols = screen.shape
    ry, rx = np.linspace(0, nodes - 1, rows), np.linspace(0, nodes - 1, cols)
    along_x = np.array([np.interp(rx, np.arange(nodes), r) for r in coarse])
    fine = np.array([np.interp(ry, np.arange(nodes), c) for c in along_x.T]).T
    fine /= np.abs(fine).max()
    return case.background_radiance * (1.0 + 0.5 * fine)


def change_centroid_q(screen: Screen, frame: np.ndarray, background: np.ndarray) -> np.ndarray:
    """Target of a frame: normalised field coordinates (2,) of the centroid of its change ``frame - background``
    (radiance change times texel area, in world coordinates, then the direction of that point)."""
    change = np.asarray(frame, dtype=np.float64) - background
    total = change.sum()
    if not (np.isfinite(total) and total != 0):
        raise ValueError("a suite frame must differ from its background (its change sums to zero)")
    world = screen.to_world(*screen.texel_centers_m())
    return q_of_world(np.tensordot(change / total, world, axes=([0, 1], [0, 1])))


@dataclass
class CaseFrames:
    """The frames of one case at one screen: ``frames`` (n, rows, cols) and ``background`` (rows, cols)
    radiances, targets ``q`` (n, 2) in field units."""

    screen: Screen
    depth_m: float
    frames: np.ndarray
    background: np.ndarray
    q: np.ndarray


def draw_case(case: Case, n_frames: int, texels: int, seed: int) -> list[CaseFrames]:
    """Frames of ``case`` (``n_frames`` over its depths), from a seed of the case's own."""
    rng = np.random.default_rng([seed, 271, sum(map(ord, case.name))])
    blocks = []
    per_depth = np.array_split(np.arange(n_frames), len(case.depths_m))
    for depth, idx in zip(case.depths_m, per_depth, strict=True):
        screen = suite_screen(depth, texels, case.tilt_deg)
        bg = background_image(case, screen, rng)
        frames, targets = [], []
        for _ in idx:
            while True:
                r = tr.WORKING_RADIUS * np.sqrt(rng.random(case.n_objects))
                phi = 2 * np.pi * rng.random(case.n_objects)
                q = np.column_stack([r * np.cos(phi), r * np.sin(phi)])
                sizes = rng.uniform(*case.size_range_m, case.n_objects)
                centres = _screen_point_of_q(screen, q)
                sep = np.hypot(*(centres[:, None] - centres[None]).transpose(2, 0, 1))
                far = sep[np.triu_indices(case.n_objects, 1)]
                if np.all(far > 0.75 * (sizes.max() + case.bar_width_m)):  # no overlap (any orientation)
                    break
            radiance = rng.uniform(*case.radiance_range, case.n_objects)
            horizontal = rng.random(case.n_objects) < 0.5
            frame = bg.copy()
            for j in range(case.n_objects):
                cov = object_coverage(screen, case.shape, centres[j], sizes[j], bool(horizontal[j]),
                                      case.bar_width_m)
                frame = frame * (1 - cov) + radiance[j] * cov
            frames.append(frame)
            targets.append(change_centroid_q(screen, frame, bg))
        blocks.append(CaseFrames(screen, float(depth), np.array(frames), bg, np.array(targets)))
    return blocks


# ---------------------------------------------------------------------------------------------------------
# Read-out and decoding


def read_change(irr_w_m2: np.ndarray, bg_irr_w_m2: np.ndarray, s, rng: np.random.Generator) -> np.ndarray:
    """Noisy changes (n, 4) [DN]: each frame's reading minus the mean of ``N_BACKGROUND_FRAMES`` background
    readings (both with the sensor's noise)."""
    background = s.measure(np.tile(bg_irr_w_m2, (N_BACKGROUND_FRAMES, 1)), rng).mean(axis=0)
    return s.measure(irr_w_m2, rng) - background


def change_sigma_dn(s, irr_w_m2: np.ndarray, bg_irr_w_m2: np.ndarray) -> np.ndarray:
    """Expected noise [DN] of :func:`read_change` (shot, read and rounding noise of both terms)."""
    return np.sqrt(s.expected_std_dn(irr_w_m2) ** 2 + s.expected_std_dn(bg_irr_w_m2) ** 2 / N_BACKGROUND_FRAMES)


class Eq7Calibration:
    """The experiments' protocol: Eq. 7 ratios, cubic fitted on a sweep of 3 cm squares at 0.5 m on black
    (the sweep's own exposure, noisy read-out); applied at any depth (field units are angular)."""

    def __init__(self, maps_at_half_m, screen: Screen, task: tr.TrackingTask, rng: np.random.Generator):
        xy = tr.calibration_positions(task.calibration_grid)
        frames = np.stack([coverage(screen, x - tr.CALIBRATION_SQUARE_M / 2, x + tr.CALIBRATION_SQUARE_M / 2,
                                    y - tr.CALIBRATION_SQUARE_M / 2, y + tr.CALIBRATION_SQUARE_M / 2)
                           for x, y in xy])
        irr = maps_at_half_m.measure(frames).irradiance_w_m2
        s = tr.sensor().auto_exposed(float(irr.max()), tr.EXPOSURE_FILL)
        dn = read_change(irr, np.zeros(irr.shape[1]), s, rng)
        obs = np.column_stack(tr.features(dn.T))
        ok = np.all(np.isfinite(obs), axis=1)
        self.n_squares = int(ok.sum())
        self.cal = Calibration2D.fit(obs[ok], xy[ok], degree=3,
                                     metadata={"task": "tracking suite", "depth_m": tr.CALIBRATION_DEPTH_M})

    def __call__(self, dn: np.ndarray) -> np.ndarray:
        obs = np.column_stack(tr.features(np.asarray(dn).T))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ExtrapolationWarning)
            with np.errstate(divide="ignore", invalid="ignore"):
                pred_m = self.cal.apply(obs)
        return tr.to_field(pred_m, tr.CALIBRATION_DEPTH_M)


@dataclass
class Entry:
    """A mincam of the suite: its masks in :data:`~.tracking.POSITIONS` order, and ``decoder`` (a
    :class:`~.decoder.Decoder`), or None for the experiments' Eq. 7 + cubic calibration."""

    label: str
    cam: Mincam
    decoder: object = None
    readings: str | None = None  # reuse another entry's readings (same masks)


def _row(err_pct: np.ndarray, noiseless_pct: np.ndarray, exposure_s: float, snr: float) -> dict:
    ok = np.isfinite(err_pct)
    return {"avg_error_pct": float(np.mean(err_pct[ok])) if ok.any() else float("nan"),
            "max_error_pct": float(np.max(err_pct[ok])) if ok.any() else float("nan"),
            "rms_error_pct": float(np.sqrt(np.mean(err_pct[ok] ** 2))) if ok.any() else float("nan"),
            "noiseless_avg_error_pct": float(np.nanmean(noiseless_pct)),
            "n": int(ok.sum()), "n_without_estimate": int((~ok).sum()),
            "exposure_s": exposure_s, "median_change_snr": snr}


def evaluate_suite(entries: list[Entry], task: tr.TrackingTask, n_frames: int, texels: int,
                   samples_per_texel: int, cases: tuple[Case, ...] = SUITE, baseline: str | None = None,
                   show_progress: bool = False) -> dict:
    """Evaluate every entry on every case; ``baseline`` names the entry each case's ratio is taken against.

    Returns ``{"cases": [{name, description, setup, rows: {label: row}, "ratio_to_baseline": {label: r}}],
    "errors": {case: {label: (n,) errors [%]}}}`` (``errors`` for figures and the NumPy archive).
    """
    from mincam_sim.budget import Budget
    from mincam_sim.render.simulation import Simulation

    maps_cache: dict = {}
    budget = Budget(samples_per_texel=samples_per_texel, seed=task.seed + 7)

    def maps(entry: Entry, screen: Screen):
        key = (entry.readings or entry.label, screen.width_m, screen.resolution, tuple(screen.pose.forward),
               tuple(screen.pose.position_m))
        if key not in maps_cache:
            maps_cache[key] = Simulation(entry.cam, screen=screen).response_maps(budget)
        return maps_cache[key]

    drawn = {c.name: draw_case(c, n_frames, texels, task.seed) for c in cases}
    cal_screen = suite_screen(tr.CALIBRATION_DEPTH_M, texels)
    calibrations = {e.label: Eq7Calibration(maps(e, cal_screen), cal_screen, task,
                                            np.random.default_rng([task.seed, 41]))
                    for e in entries if e.decoder is None}
    out, errors = [], {}
    for case in progress(cases, desc="held-out suite", disable=not show_progress, unit="case"):
        rows, errors[case.name] = {}, {}
        for e in entries:
            decode = e.decoder if e.decoder is not None else calibrations[e.label]
            irr, bg_irr, q = [], [], []
            for block in drawn[case.name]:
                m = maps(e, block.screen)
                irr.append(m.measure(block.frames).irradiance_w_m2)
                bg_irr.append(np.broadcast_to(m.measure(block.background).irradiance_w_m2,
                                              (len(block.frames), len(e.cam))))
                q.append(block.q)
            irr, bg_irr, q = np.concatenate(irr), np.concatenate(bg_irr), np.concatenate(q)
            s = tr.sensor().auto_exposed(float(irr.max()), tr.EXPOSURE_FILL)
            rng = np.random.default_rng([task.seed, 43, sum(map(ord, case.name))])
            dn = np.concatenate([read_change(irr[i:i + 1], bg_irr[i], s, rng) for i in range(len(irr))])
            exact = s.expected(irr) - s.expected(bg_irr)
            snr = float(np.median(np.abs(exact) / change_sigma_dn(s, irr, bg_irr)))
            with np.errstate(divide="ignore", invalid="ignore"):
                err = 100 * np.hypot(*(decode(dn) - q).T)
                err0 = 100 * np.hypot(*(decode(exact) - q).T)
            rows[e.label] = _row(err, err0, s.exposure_s, snr)
            errors[case.name][e.label] = err
        ratio = ({k: v["avg_error_pct"] / rows[baseline]["avg_error_pct"] for k, v in rows.items()}
                 if baseline else {})
        setup = {k: v for k, v in asdict(case).items() if k not in ("name", "description")}
        out.append({"name": case.name, "description": case.description, "setup": setup, "n_frames": n_frames,
                    "rows": rows, "ratio_to_baseline": ratio})
    return {"cases": out, "errors": errors, "baseline": baseline,
            "calibration_squares": {k: c.n_squares for k, c in calibrations.items()}}


def table(suite: dict, labels: list[str] | None = None) -> str:
    """A plain-text table of the suite's average errors [% of field] (and ratios to the baseline)."""
    labels = labels or list(suite["cases"][0]["rows"])
    head = f"{'case':<20}" + "".join(f"{lab[:22]:>24}" for lab in labels)
    lines = [head]
    for c in suite["cases"]:
        cells = []
        for lab in labels:
            r = c["rows"][lab]
            ratio = c["ratio_to_baseline"].get(lab)
            tail = f" ({ratio:.2f}x)" if ratio is not None and lab != suite["baseline"] else ""
            cells.append(f"{r['avg_error_pct']:>8.2f}{tail:<9} /{r['max_error_pct']:>5.1f}")
        lines.append(f"{c['name']:<20}" + "".join(f"{x:>24}" for x in cells))
    return "\n".join(lines)


__all__ = ["SUITE", "Case", "CaseFrames", "Entry", "Eq7Calibration", "case_names", "change_centroid_q",
           "change_sigma_dn", "draw_case", "evaluate_suite", "object_coverage", "q_of_world", "read_change",
           "suite_screen", "table"]
