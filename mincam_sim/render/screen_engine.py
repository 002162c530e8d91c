"""Mixel measurements of a flat display, by three estimators of the same integral.

* ``reference``: the literal scene (mask surface, housing, detector with Mitsuba's ``irradiancemeter``,
  ``path`` integrator), one scene per mixel in millimetres around it. Slow and obviously right.
* ``fast``: the :mod:`~mincam_sim.render.mixel_sensor` plugin, rays start on the mask apertures
  (``path`` integrator, all mixels in one render).
* ``response map``: :func:`~.response_map.response_maps` traces, for every display texel, rays from detector
  points through the mask plane to points in the texel (with a visibility ray in the mincam's scene); any frame
  is then ``sum(W * frame)``, exact in expectation.

All three run over one :class:`~.mincam_scene.MincamScene` (the other mixels' bodies occlude in every form)
and return irradiance averaged over each detector [W/m^2] with its Monte Carlo standard error. This module
keeps the documented entry points: :class:`ScreenRenderer`, :func:`response_maps`, :func:`render_frames`.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from ..measurements import Measurements
from ..optics import Mincam
from ..progress import progress
from ..screen import Screen
from ..store import ResultStore
from . import backend
from .estimation import check_counts, derive_seed, replicate_mean_stderr, samples_for_target
from .estimation import worst_relative_stderr as _worst
from .mask_eval import mask_model_meta
from .mincam_scene import MincamScene, geometry_meta
from .response_map import ResponseMaps, response_maps

__all__ = [
    "ResponseMaps",
    "ScreenRenderer",
    "derive_seed",
    "geometry_meta",
    "render_frames",
    "response_maps",
    "response_maps_to_target",
    "worst_relative_stderr",
]


def _as_frames(screen: Screen, frames) -> list[np.ndarray]:
    arr = frames if isinstance(frames, np.ndarray) else None
    if arr is not None and arr.ndim == 2:
        return [screen.check_frame(arr)]
    return [screen.check_frame(f, f"frame {i}") for i, f in enumerate(frames)]


class ScreenRenderer:
    """A mincam in front of a display in a dark room, rendered with Mitsuba.

    Parameters
    ----------
    mincam : Mincam
    screen : Screen
    form : {"fast", "reference"}
        Which estimator renders frames (see module docstring).
    replicates : int
        Independent estimates per measurement whose spread gives the standard error (>= 2).
    """

    def __init__(self, mincam: Mincam, screen: Screen, form: str = "fast", replicates: int = 8) -> None:
        if form not in ("fast", "reference"):
            raise ValueError(f"form must be 'fast' or 'reference', got {form!r}")
        check_counts(1, replicates)
        self.mincam, self.screen, self.form, self.replicates = mincam, screen, form, int(replicates)
        self.scene = MincamScene.display(mincam, screen)
        if form == "fast":
            backend.require_jit("The fast mixel sensor (a Python Mitsuba plugin)")
            _ = self.scene.fast_scene
        else:
            self.scene.reference_scenes()

    def set_frame(self, frame: np.ndarray) -> None:
        """Show ``frame`` (radiance, W m^-2 sr^-1, row 0 at the top) on the display."""
        self.scene.set_frame(frame)

    def _estimates(self, spp: int, replicates: int, seed: int) -> np.ndarray:
        """(replicates, n_mixels) independent estimates, each from ``spp / replicates`` rays."""
        if self.form == "fast":
            return self.scene.fast_estimates(spp, replicates, seed)
        return self.scene.reference_estimates(spp, replicates, seed)

    def render(
        self,
        frames: np.ndarray | Iterable[np.ndarray],
        spp: int = 1 << 16,
        seed: int = 0,
        show_progress: bool = False,
    ) -> Measurements:
        """Measure every frame.

        Parameters
        ----------
        frames : (rows, cols) array or iterable of them
            Display radiance [W m^-2 sr^-1].
        spp : int
            Samples per mixel per frame (split into ``replicates`` independent estimates).
        seed : int
            Base seed. The same seed is used for every frame, so the noise of two frames is correlated and
            largely cancels in their difference; same seed, same numbers.
        show_progress : bool
            Show a progress bar over frames.
        """
        replicates = self.replicates
        check_counts(spp, replicates)
        frames = _as_frames(self.screen, frames)
        values, errors = [], []
        for frame in progress(frames, desc=f"{self.form} render", disable=not show_progress):
            self.set_frame(frame)
            mean, err = replicate_mean_stderr(self._estimates(spp, replicates, seed))
            values.append(mean)
            errors.append(err)
        meta = {
            "form": self.form,
            "estimator": "mixel_sensor_path" if self.form == "fast" else "irradiancemeter_path",
            "spp_per_mixel_per_frame": int(replicates * max(1, -(-spp // replicates))),
            "replicates": replicates,
            "seed": seed,
            "units": "W/m^2 (irradiance averaged over the detector)",
            "masks": {m.name: mask_model_meta(m.mask) for m in self.mincam},
            **backend.describe(),
            **geometry_meta(self.mincam, self.screen),
        }
        if self.form == "reference":
            meta["scene_units"] = "millimetres around each mixel (ray offsets ~0.3 um)"
        return Measurements(np.array(values), np.array(errors), self.mincam.names, meta)


MAX_SAMPLES_PER_TEXEL = 1 << 14
MAX_SPP = 1 << 28


def response_maps_to_target(
    mincam: Mincam, screen: Screen, frames: np.ndarray, target_rel_stderr: float, seed: int = 0,
    max_samples_per_texel: int = MAX_SAMPLES_PER_TEXEL,
) -> tuple[ResponseMaps, list[dict]]:
    """Response maps whose measurements of ``frames`` all reach ``target_rel_stderr`` (if the cap allows).

    Two pilots (16 and 64 samples per texel) give the empirical convergence rate ``rel ~ n^-a`` (stratified
    sampling converges faster than ``n^-1/2``); the sample count is extrapolated with it, then checked and, if
    needed, raised again assuming the plain Monte Carlo rate. Returns the maps and the trail of
    (samples_per_texel, worst relative stderr) tried.
    """
    trail: list[dict] = []

    def attempt(n: int) -> tuple[ResponseMaps, float]:
        maps = response_maps(mincam, screen, n, seed)
        rel = worst_relative_stderr(maps.measure(frames))
        trail.append({"samples_per_texel": int(maps.meta["samples_per_texel"]), "worst_rel_stderr": rel})
        return maps, rel

    n1, n2 = 16, 64
    maps, rel1 = attempt(n1)
    if not rel1 > target_rel_stderr:
        return maps, trail
    maps, rel2 = attempt(n2)
    rate = float(np.clip(np.log(rel1 / rel2) / np.log(n2 / n1), 0.5, 1.5)) if rel2 > 0 else 0.5
    n, rel = n2, rel2
    while rel > target_rel_stderr and n < max_samples_per_texel:
        exponent = rate if len(trail) == 2 else 0.5
        n = max(min(2 * n, max_samples_per_texel),
                samples_for_target(n, rel, target_rel_stderr, max_samples_per_texel, exponent))
        maps, rel = attempt(n)
    return maps, trail


def worst_relative_stderr(m: Measurements) -> float:
    """Largest stderr/value over non-zero measurements (NaN if all are zero)."""
    return _worst(m.irradiance_w_m2, m.stderr_w_m2)


def render_frames(
    mincam: Mincam,
    screen: Screen,
    frames: np.ndarray,
    form: str = "response_map",
    spp: int = 1 << 16,
    samples_per_texel: int = 64,
    target_rel_stderr: float = 0.0,
    seed: int = 0,
    replicates: int = 8,
    out_dir: str | Path | None = None,
    show_progress: bool = False,
    chunk: int = 64,
) -> tuple[Measurements, ResponseMaps | None]:
    """Measure a stack of frames with any form, optionally to a target noise, resumably.

    Parameters
    ----------
    frames : (n, rows, cols) ndarray
        Display radiance [W m^-2 sr^-1].
    form : {"response_map", "fast", "reference"}
    spp, samples_per_texel : int
        Sample counts when ``target_rel_stderr`` is 0.
    target_rel_stderr : float
        If > 0, a pilot run measures the noise and the sample count is extrapolated (variance ~ 1/samples) so
        that the worst non-zero measurement reaches this relative standard error; the reached value is in
        ``meta["reached_rel_stderr"]``.
    out_dir : path, optional
        If given, per-frame results are written as they are computed and an interrupted run resumes there.

    Returns
    -------
    (Measurements, ResponseMaps or None)
    """
    frames = np.asarray(frames, dtype=np.float64)
    if frames.ndim == 2:
        frames = frames[None]
    if form not in ("response_map", "fast", "reference"):
        raise ValueError(f"form must be 'response_map', 'fast' or 'reference', got {form!r}")
    if not (np.isfinite(target_rel_stderr) and target_rel_stderr >= 0):
        raise ValueError(f"target_rel_stderr must be >= 0 (0 = use the given sample counts), got {target_rel_stderr}")
    for i, f in enumerate(frames):
        screen.check_frame(f, f"frame {i}")
    budget: dict = {"target_rel_stderr": target_rel_stderr}
    maps = None
    renderer = None
    if form == "response_map":
        maps_path = Path(out_dir) / "response_maps.npz" if out_dir else None
        if maps_path is not None and maps_path.exists():
            maps = ResponseMaps.load_npz(maps_path)
        else:
            if target_rel_stderr > 0:
                maps, trail = response_maps_to_target(mincam, screen, frames, target_rel_stderr, seed)
                samples_per_texel = int(maps.meta["samples_per_texel"])
                budget.update(budget_trail=trail)
            else:
                maps = response_maps(mincam, screen, samples_per_texel, seed)
            if maps_path is not None:
                maps.save_npz(maps_path)
        measure = maps.measure
        meta = dict(maps.meta)
    else:
        renderer = ScreenRenderer(mincam, screen, form, replicates)
        if target_rel_stderr > 0:
            pilot_spp = replicates * 2048
            pilot = renderer.render(frames[: min(len(frames), 4)], spp=pilot_spp, seed=derive_seed(seed, "pilot"))
            rel = worst_relative_stderr(pilot)
            spp = samples_for_target(pilot_spp, rel, target_rel_stderr, MAX_SPP)
            budget.update(pilot_spp=pilot_spp, pilot_rel_stderr=rel)

        def measure(stack):
            return renderer.render(stack, spp=spp, seed=seed)

        meta = {"form": form, "seed": seed, "replicates": replicates, **backend.describe(),
                **geometry_meta(mincam, screen)}
    budget.update(spp=spp if form != "response_map" else None,
                  samples_per_texel=samples_per_texel if form == "response_map" else None)
    store = None
    if out_dir is not None:
        identity = {"form": form, "seed": seed, "replicates": replicates, "budget": budget,
                    "frames_sha256": hashlib.sha256(np.ascontiguousarray(frames).tobytes()).hexdigest()[:16],
                    "geometry": geometry_meta(mincam, screen)}
        store = ResultStore(out_dir, len(frames), mincam.names, identity)
        todo = store.pending()
    else:
        todo = np.arange(len(frames))
    values = np.full((len(frames), len(mincam)), np.nan)
    errors = np.full_like(values, np.nan)
    if store is not None:
        values[:] = store.values
        errors[:] = store.stderr
    step = chunk if form == "response_map" else 1
    batches = [todo[i : i + step] for i in range(0, len(todo), step)]
    for idx in progress(batches, desc=f"{form}: frames", disable=not show_progress, total=len(batches)):
        m = measure(frames[idx])
        values[idx], errors[idx] = m.irradiance_w_m2, m.stderr_w_m2
        if store is not None:
            store.write(idx, m.irradiance_w_m2, m.stderr_w_m2)
    result = Measurements(values, errors, mincam.names, {**meta, **budget})
    result.meta["reached_rel_stderr"] = worst_relative_stderr(result)
    return result, maps
