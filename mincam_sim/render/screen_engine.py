# TEMPORARY: deleted after the callers are ported
"""The old display entry points, thin wrappers over the solvers (``mincam_sim.render.solvers``) behind
:class:`~.simulation.Simulation`, kept only while callers outside ``render/`` are ported. New code uses
``Simulation(mincam, screen=...).measure(frames, solver, budget)``."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from ..budget import Budget
from ..errors import InputError
from ..frames import FrameSink
from ..measurements import Measurements
from ..optics import Mincam
from ..scene.display import FrameSource, Screen
from . import backend
from .estimation import UnseenWarning, derive_seed
from .estimation import worst_relative_stderr as _worst
from .mincam_scene import geometry_meta
from .response_map import ResponseMaps, response_maps
from .simulation import Simulation
from .solvers import Aperture, Reference, ResponseMap
from .solvers.response_map import DEFAULT_MAP_BLOCKS, maps_to_target

__all__ = ["DEFAULT_MAP_BLOCKS", "ResponseMaps", "ScreenRenderer", "UnseenWarning", "derive_seed", "frames_identity",
           "geometry_meta", "measure_stream", "render_frames", "response_maps", "response_maps_to_target",
           "worst_relative_stderr"]

_SOLVERS = {"response_map": ResponseMap, "fast": Aperture, "reference": Reference}


def _solver(form: str):
    if form not in _SOLVERS:
        raise ValueError(f"form must be 'response_map', 'fast' or 'reference', got {form!r}")
    return _SOLVERS[form]()


class ScreenRenderer:
    """TEMPORARY: ``Simulation(mincam, screen=screen).measure(frames, Aperture() | Reference(), Budget(...))``."""

    def __init__(self, mincam: Mincam, screen: Screen, form: str = "fast", replicates: int = 8) -> None:
        if form not in ("fast", "reference"):
            raise ValueError(f"form must be 'fast' or 'reference', got {form!r}")
        self.mincam, self.screen, self.form, self.replicates = mincam, screen, form, int(replicates)
        self.sim = Simulation(mincam, screen=screen)
        self.scene = self.sim.display_scene()
        _solver(form).prepare(self.scene)

    def set_frame(self, frame: np.ndarray) -> None:
        self.scene.set_frame(frame)

    def render(self, frames: np.ndarray | Iterable[np.ndarray], spp: int = 1 << 16, seed: int = 0,
               show_progress: bool = False) -> Measurements:
        arr = frames if isinstance(frames, np.ndarray) else None
        frames = [frames] if arr is not None and arr.ndim == 2 else list(frames)
        return self.sim.measure(np.stack([self.screen.check_frame(f) for f in frames]), _solver(self.form),
                                Budget(spp=int(spp), replicates=self.replicates, seed=int(seed)),
                                show_progress=show_progress)


def measure_stream(maps: ResponseMaps, frames: FrameSource, indices=None, show_progress: bool = False,
                   desc: str = "frames") -> Measurements:
    """Measurements of (some of) a frame source through response maps, chunk by chunk (bounded memory)."""
    return maps.measure_source(frames, indices, show_progress=show_progress, desc=desc)


def worst_relative_stderr(m: Measurements) -> float:
    """Largest stderr/value over non-zero measurements (NaN if all are zero)."""
    return _worst(m.irradiance_w_m2, m.stderr_w_m2)


def frames_identity(frames: FrameSource, screen: Screen) -> dict:
    """TEMPORARY: ``Simulation.frames_identity``."""
    return Simulation.frames_identity(_ScreenOnly(screen), frames)


class _ScreenOnly:
    kind = "display"

    def __init__(self, screen: Screen) -> None:
        self.screen = screen

    def frame_source(self, frames):
        return Simulation.frame_source(self, frames)


def response_maps_to_target(mincam: Mincam, screen: Screen, frames, target_rel_stderr: float, seed: int = 0,
                            max_samples_per_texel: int | None = None, cache=None, show_progress: bool = False,
                            replicates: int = 4) -> tuple[ResponseMaps, list[dict]]:
    """TEMPORARY: the ResponseMap solver's target search (``solvers.response_map.maps_to_target``)."""
    from .response_map import MAX_SAMPLES_PER_TEXEL

    cap = MAX_SAMPLES_PER_TEXEL if max_samples_per_texel is None else max_samples_per_texel
    return maps_to_target(Simulation(mincam, screen=screen), frames, target_rel_stderr, seed, cap, cache,
                          show_progress, replicates)


def render_frames(mincam: Mincam, screen: Screen, frames, form: str = "response_map", spp: int = 1 << 16,
                  samples_per_texel: int = 64, target_rel_stderr: float = 0.0, seed: int = 0,
                  replicates: int | None = None, out_dir: str | Path | None = None, show_progress: bool = False,
                  chunk: int = 64, overwrite: bool = False,
                  sink: FrameSink | None = None) -> tuple[Measurements, ResponseMaps | None]:
    """TEMPORARY: ``Simulation(mincam, screen=screen).measure(frames, solver, Budget(...))`` (``out_dir``: through
    :class:`mincam_sim.run.Run`)."""
    if not (np.isfinite(target_rel_stderr) and target_rel_stderr >= 0):
        raise ValueError(f"target_rel_stderr must be >= 0 (0 = use the given sample counts), got {target_rel_stderr}")
    solver = _solver(form)
    sim = Simulation(mincam, screen=screen)
    budget = Budget(spp=int(spp), samples_per_texel=int(samples_per_texel), target_rel_stderr=target_rel_stderr,
                    replicates=replicates, seed=int(seed))
    if out_dir is not None:
        raise InputError("out_dir= is gone: keep results with `with mincam_sim.Run(out_dir) as run: "
                         "run.measure(...)` (or run.measure_changes)")
    if sink is not None and getattr(sink, "persistent", False) and getattr(sink, "identity", 0) is None:
        sink.identity = _identity(sim, frames, solver, budget, None)
    m = sim.measure(frames, solver, budget, sink=sink, show_progress=show_progress)
    return m, m.maps


def _identity(sim, frames, solver, budget, background) -> dict:
    """TEMPORARY: the identity ``mincam_sim.run.Run`` builds, for an old caller's unidentified store sink."""
    from ..identity import run_identity

    return run_identity(sim.identity(), solver.identity(), budget.describe(), sim.frames_identity(frames, background),
                        backend.variant())
