"""Mixel measurements of a flat display, by three estimators of the same integral.

* ``reference``: the literal scene (mask surface, housing, detector with Mitsuba's ``irradiancemeter``,
  ``path`` integrator), one scene per mixel in millimetres around it. Slow and obviously right.
* ``fast``: the ``mincam_sim.render.mixel_sensor`` plugin, rays start on the mask apertures
  (``path`` integrator, all mixels in one render).
* ``response map``: :func:`response_maps` traces, for every display texel, rays from detector
  points through the mask plane to points in the texel (with a visibility ray in the mincam's scene); any frame
  is then ``sum(W * frame)``, exact in expectation.

All three run over one ``mincam_sim.render.mincam_scene.MincamScene`` (the other mixels' bodies occlude in
every form) and return irradiance averaged over each detector [W/m^2] with its Monte Carlo standard error. This module
keeps the documented entry points: :class:`ScreenRenderer`, :func:`response_maps`, :func:`render_frames`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..frames import FrameSink, collect, resolve_sink
from ..identity import StreamingHash, build_identity, fingerprint, run_key
from ..measurements import Measurements
from ..optics import Mincam
from ..progress import progress
from ..scene.display import FrameSource, Screen, as_frame_source
from ..store import ContentCache
from . import backend
from .estimation import (
    UnseenWarning,
    check_counts,
    derive_seed,
    pilot_to_target,
    replicate_mean_stderr,
    warn_target_missed,
    warn_unreached,
)
from .estimation import worst_relative_stderr as _worst
from .mask_eval import mask_model_meta
from .mincam_scene import MincamScene, geometry_meta
from .response_map import (
    FRAME_CHUNK_BYTES,
    MAX_SAMPLES_PER_TEXEL,
    ResponseMaps,
    check_radiance,
    response_maps,
    response_maps_to_target,
)

__all__ = [
    "ResponseMaps",
    "UnseenWarning",
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


DEFAULT_MAP_BLOCKS = 4  # response maps: independent blocks of samples per texel
MAX_SPP = 1 << 28


def measure_stream(maps: ResponseMaps, frames: FrameSource, indices=None, show_progress: bool = False,
                   desc: str = "frames") -> Measurements:
    """Measurements of (some of) a frame source through response maps, chunk by chunk (bounded memory)."""
    return maps.measure_source(frames, indices, show_progress=show_progress, desc=desc)


def worst_relative_stderr(m: Measurements) -> float:
    """Largest stderr/value over non-zero measurements (NaN if all are zero)."""
    return _worst(m.irradiance_w_m2, m.stderr_w_m2)


def frames_identity(frames: FrameSource, screen: Screen) -> dict:
    """What determines the frames: a generated source's description, or the content hashed as it streams
    (every frame is validated on the way)."""
    if frames.description is not None:
        return {"n": len(frames), "description": fingerprint(frames.description)}
    digest = StreamingHash()
    step = frames.chunk_size(FRAME_CHUNK_BYTES)
    for lo in range(0, len(frames), step):
        chunk = frames[lo : lo + step]
        check_radiance(chunk, np.arange(lo, lo + len(chunk)))
        digest.update(chunk)
    return {"n": len(frames), "content_sha256": digest.hexdigest()}


@dataclass
class _FramePlan:
    """What a render of frames does, its budget resolved: how a batch of frames is measured, and what the result
    says about itself."""

    form: str
    frames: FrameSource
    measure: Callable[[np.ndarray], Measurements]
    budget: dict
    provenance: dict
    meta: dict
    maps: ResponseMaps | None
    used: int  # samples per texel (maps) or per mixel per frame (rays) traced
    cap: int


def render_frames(
    mincam: Mincam,
    screen: Screen,
    frames,
    form: str = "response_map",
    spp: int = 1 << 16,
    samples_per_texel: int = 64,
    target_rel_stderr: float = 0.0,
    seed: int = 0,
    replicates: int | None = None,
    out_dir: str | Path | None = None,
    show_progress: bool = False,
    chunk: int = 64,
    overwrite: bool = False,
    sink: FrameSink | None = None,
) -> tuple[Measurements, ResponseMaps | None]:
    """Measure a stack (or a stream) of frames with any form, optionally to a target noise, resumably.

    Parameters
    ----------
    frames : (n, rows, cols) ndarray, FrameSource or list of frames
        Display radiance [W m^-2 sr^-1]. A :class:`~mincam_sim.scene.display.FrameSource` (e.g.
        ``Sweep.frame_source(screen)``) or a memory-mapped array streams in chunks: memory stays bounded
        whatever the number of frames.
    form : {"response_map", "fast", "reference"}
    spp, samples_per_texel : int
        Sample counts when ``target_rel_stderr`` is 0.
    target_rel_stderr : float
        If > 0, pilots measure the noise and the sample count is extrapolated so that the worst non-zero
        measurement reaches this relative standard error; the reached value is in ``meta["reached_rel_stderr"]``
        (a ``TargetNotReachedWarning`` when it is above the target, e.g. at the sample cap).
    replicates : int, optional
        Independent estimates whose spread gives the standard error: rays split into ``replicates`` groups
        (fast, reference; default 8), or blocks of samples per texel (response maps; default 4).
    sink : FrameSink, optional
        Takes each frame's row as it is measured (:class:`mincam_sim.frames.FrameSink`; default: in memory).
        :meth:`mincam_sim.run.Run.sink` keeps rows on disk under the run's lock and caches response maps by
        content: an interrupted run resumes there, a rerun of the same run reuses everything, a different run
        (any mask, frame, geometry, budget, seed, form or library version changed) is refused with what changed.
    out_dir, overwrite : path, bool
        Deprecated (one release): a store in ``out_dir`` (locked while written), ``overwrite`` replacing a
        different run's. Use :class:`mincam_sim.run.Run`.

    Returns
    -------
    (Measurements, ResponseMaps or None)
    """
    sink = resolve_sink(sink, out_dir, overwrite, "render_frames")
    frames, replicates = _checked_frames(screen, frames, form, target_rel_stderr, replicates)
    frames_id = frames_identity(frames, screen) if sink.persistent else None  # identity: only for a store
    if form == "response_map":
        plan = _plan_maps(mincam, screen, frames, samples_per_texel, target_rel_stderr, seed, replicates,
                          sink.cache, show_progress)
    else:
        plan = _plan_rays(mincam, screen, frames, form, spp, target_rel_stderr, seed, replicates)
    identity = _run_identity(plan, mincam, screen, seed, frames_id)
    table = sink.open(identity, len(frames), mincam.names)
    values, errors = collect(_frame_rows(plan, table.pending(), chunk, show_progress), table)
    return _measurements(plan, mincam, values, errors, frames_id, identity, target_rel_stderr), plan.maps


def _checked_frames(screen: Screen, frames, form: str, target_rel_stderr: float,
                    replicates: int | None) -> tuple[FrameSource, int]:
    """The frames as a source of the screen's shape and the replicates (default per form); bad arguments
    refused in one line each."""
    if form not in ("response_map", "fast", "reference"):
        raise ValueError(f"form must be 'response_map', 'fast' or 'reference', got {form!r}")
    if not (np.isfinite(target_rel_stderr) and target_rel_stderr >= 0):
        raise ValueError(f"target_rel_stderr must be >= 0 (0 = use the given sample counts), got {target_rel_stderr}")
    if replicates is None:
        replicates = DEFAULT_MAP_BLOCKS if form == "response_map" else 8
    frames = as_frame_source(frames)
    if tuple(frames.frame_shape) != tuple(screen.shape):
        raise ValueError(f"frames have shape {frames.frame_shape} but this screen's frames are {screen.shape} "
                         "(rows, cols)")
    return frames, replicates


def _plan_maps(mincam: Mincam, screen: Screen, frames: FrameSource, samples_per_texel: int,
               target_rel_stderr: float, seed: int, replicates: int, cache: ContentCache | None,
               show_progress: bool) -> _FramePlan:
    """Response maps (to the target noise, or at ``samples_per_texel``); frames are then products with them."""
    provenance: dict = {}
    if target_rel_stderr > 0:
        maps, trail = response_maps_to_target(mincam, screen, frames, target_rel_stderr, seed,
                                              max_samples_per_texel=MAX_SAMPLES_PER_TEXEL, cache=cache,
                                              show_progress=show_progress, replicates=replicates)
        provenance["budget_trail"] = trail
    else:
        maps = response_maps(mincam, screen, samples_per_texel, seed, cache=cache, show_progress=show_progress,
                             replicates=replicates)
    used = int(maps.meta["samples_per_texel"])
    # 4 x 8^2 and 16 x 4^2 samples per texel are different maps: the replicates are part of the budget
    budget = {"target_rel_stderr": target_rel_stderr, "samples_per_texel": used, "replicates": int(replicates)}
    return _FramePlan("response_map", frames, lambda idx: measure_stream(maps, frames, idx), budget, provenance,
                      dict(maps.meta), maps, used, MAX_SAMPLES_PER_TEXEL)


def _plan_rays(mincam: Mincam, screen: Screen, frames: FrameSource, form: str, spp: int,
               target_rel_stderr: float, seed: int, replicates: int) -> _FramePlan:
    """A ray renderer (fast or reference) at ``spp``, or at the count its pilots extrapolate to the target
    (the budget rule of every ray solver, :func:`.estimation.pilot_to_target`)."""
    renderer = ScreenRenderer(mincam, screen, form, replicates)
    provenance: dict = {}
    if target_rel_stderr > 0:
        pilot_spp = replicates * 2048
        pilot_idx = np.unique(np.linspace(0, len(frames) - 1, min(4, len(frames))).astype(int))
        pilot_frames = frames[pilot_idx]

        def pilot(samples: int):
            m = renderer.render(pilot_frames, spp=samples, seed=derive_seed(seed, "pilot"))
            return m.irradiance_w_m2, m.stderr_w_m2

        spp, trail = pilot_to_target(pilot, pilot_spp, target_rel_stderr, MAX_SPP, significance=0.0)
        provenance.update(pilot_spp=pilot_spp, pilot_trail=trail)
    budget = {"target_rel_stderr": target_rel_stderr, "spp": int(spp), "replicates": int(replicates)}
    meta = {"form": form, "seed": seed, "replicates": replicates, **backend.describe(),
            **geometry_meta(mincam, screen)}
    return _FramePlan(form, frames, lambda idx: renderer.render(frames[idx], spp=spp, seed=seed), budget,
                      provenance, meta, None, int(spp), MAX_SPP)


def _run_identity(plan: _FramePlan, mincam: Mincam, screen: Screen, seed: int, frames_id: dict | None) -> dict:
    """What determines a render's numbers (:func:`mincam_sim.identity.build_identity`, kind
    ``"display_frames"``): form, seed, resolved budget, mincam, screen and frames content, variant, versions."""
    return build_identity("display_frames", {"form": plan.form, "seed": int(seed), "budget": plan.budget,
                                             "mincam": fingerprint(mincam), "screen": fingerprint(screen),
                                             "frames": frames_id}, variant=backend.variant())


def _frame_rows(plan: _FramePlan, todo: np.ndarray, chunk: int,
                show_progress: bool) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """(frame indices, values, stderr) of ``todo``, a chunk at a time (maps) or a frame at a time (rays)."""
    step = max(1, min(chunk, plan.frames.chunk_size(FRAME_CHUNK_BYTES))) if plan.form == "response_map" else 1
    batches = [todo[i : i + step] for i in range(0, len(todo), step)]
    for idx in progress(batches, desc=f"{plan.form}: frames", disable=not show_progress, total=len(batches),
                        unit="chunk" if step > 1 else "frame"):
        m = plan.measure(idx)
        yield idx, m.irradiance_w_m2, m.stderr_w_m2


def _measurements(plan: _FramePlan, mincam: Mincam, values: np.ndarray, errors: np.ndarray,
                  frames_id: dict | None, identity: dict, target_rel_stderr: float) -> Measurements:
    """The result with what it says about itself (budget, provenance, identity key, reached noise), and the
    warnings of a missed target or an unseen measurement."""
    result = Measurements(values, errors, mincam.names, {**plan.meta, **plan.budget, **plan.provenance,
                                                         "frames": frames_id, "identity_key": run_key(identity)})
    result.meta["reached_rel_stderr"] = worst_relative_stderr(result)
    warn_target_missed(result.meta["reached_rel_stderr"], target_rel_stderr, plan.used, plan.cap)
    warn_unreached(result)
    return result
