"""Runs kept outside the numerics: :class:`Run` owns an output directory (lock, identity, resume, atomic
outputs) and wraps a :class:`~mincam_sim.render.simulation.Simulation`; the solvers never import it.

::

    with ms.Run("out/render") as run:
        m = run.measure(sim, frames, solver=ms.ResponseMap(), budget=ms.Budget(samples_per_texel=256))
        ch = run.measure_changes(world_sim, frames, solver=ms.StratifiedChange())

Per-frame results go to ``OUT/<name>/`` as they are computed (a killed run resumes where it stopped; a run with
anything else changed is refused, naming what changed, unless ``overwrite``); the finished result is written
atomically as ``OUT/<name>.npz`` (and ``.csv``).
"""

from __future__ import annotations

from pathlib import Path

from .budget import Budget
from .changes import Changes
from .errors import InputError
from .measurements import Measurements
from .render.simulation import Simulation
from .render.solvers import Solver
from .store import DirLock


class Run:
    """An output directory for one or more measurements.

    Parameters
    ----------
    out_dir : path
        Created if needed; locked while the ``with`` block runs (a second process is refused, naming the holder).
    overwrite : bool
        Replace results of a different run instead of refusing them.
    show_progress : bool
        Progress bars on stderr.
    """

    def __init__(self, out_dir: str | Path, overwrite: bool = False, show_progress: bool = False) -> None:
        self.out_dir = Path(out_dir)
        self.overwrite, self.show_progress = bool(overwrite), bool(show_progress)
        self._lock: DirLock | None = None

    def __enter__(self) -> Run:
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self._lock = DirLock(self.out_dir, "run directory")
        return self

    def __exit__(self, *exc: object) -> None:
        if self._lock is not None:
            self._lock.release()
            self._lock = None

    def _check_open(self) -> None:
        if self._lock is None:
            raise InputError("use a Run in a with-block: `with Run(out_dir) as run: run.measure(...)`")

    def measure(self, sim: Simulation, frames, solver: Solver | None = None, budget: Budget | None = None,
                name: str = "measurements") -> Measurements:
        """:meth:`~mincam_sim.render.simulation.Simulation.measure`, kept in ``out_dir/name`` (resumable) and
        ``out_dir/name.npz``."""
        self._check_open()
        m = sim.measure(frames, solver, budget, out_dir=self.out_dir / name, overwrite=self.overwrite,
                        show_progress=self.show_progress)
        m.save_csv(self.out_dir / f"{name}.csv")
        m.save_npz(self.out_dir / f"{name}.npz")
        return m

    def measure_changes(self, sim: Simulation, frames, background=None, solver: Solver | None = None,
                        budget: Budget | None = None, name: str = "measurements") -> Changes:
        """:meth:`~mincam_sim.render.simulation.Simulation.measure_changes`, kept in ``out_dir/name`` (resumable) and
        ``out_dir/name.npz``."""
        self._check_open()
        ch = sim.measure_changes(frames, background, solver, budget, out_dir=self.out_dir / name,
                                 overwrite=self.overwrite, show_progress=self.show_progress)
        ch.save_csv(self.out_dir / f"{name}.csv")
        ch.save_npz(self.out_dir / f"{name}.npz")
        return ch
