"""Runs kept outside the numerics: :class:`Run` owns an output directory -- its one lock, its identity records,
its per-frame stores (resume) and its atomic outputs -- and hands the solvers a sink; the solvers never import it.

::

    with ms.Run("out/render") as run:
        m = run.measure(sim, frames, solver=ms.ResponseMap(), budget=ms.Budget(samples_per_texel=256))
        ch = run.measure_changes(world_sim, frames, solver=ms.StratifiedChange())

Per-frame results go to ``OUT/<name>/`` as they are computed (a killed run resumes where it stopped; a run with
anything else changed is refused, naming what changed, unless ``overwrite``); the finished result is written
atomically as ``OUT/<name>.npz`` (and ``.csv``). The directory holds one lock file (``OUT/.mincam.lock``)
whatever the number of stores in it.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .budget import Budget
from .changes import Changes
from .errors import InputError
from .measurements import Measurements
from .render.simulation import Simulation
from .render.solvers import Solver
from .store import DirLock, StoreSink, check_identity, clear_store, lock_out_dir


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
    what : str
        What the directory is called in a refusal ("output directory").
    """

    def __init__(self, out_dir: str | Path, overwrite: bool = False, show_progress: bool = False,
                 what: str = "output directory") -> None:
        self.out_dir = Path(out_dir)
        self.overwrite, self.show_progress = bool(overwrite), bool(show_progress)
        self.what = what
        self._lock: DirLock | None = None

    def __enter__(self) -> Run:
        self._lock = lock_out_dir(self.out_dir, self.what)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._lock is not None:
            self._lock.release()
            self._lock = None

    def _check_open(self) -> DirLock:
        if self._lock is None:
            raise InputError("use a Run in a with-block: `with Run(out_dir) as run: run.measure(...)`")
        return self._lock

    # ------------------------------------------------------------------------------- identity, store, resume
    def sink(self, name: str) -> StoreSink:
        """The per-frame store ``out_dir/name`` for a solver's ``sink=`` (under this run's lock: no lock of its
        own); its response maps are cached in ``out_dir/name/cache``."""
        return StoreSink(self.out_dir / name, overwrite=self.overwrite, lock=self._check_open())

    def record_identity(self, identity: Any, name: str = "identity.json") -> bool:
        """Record what the directory's outputs are computed from, or check that it is unchanged
        (:func:`mincam_sim.store.check_identity`): True if the same identity was recorded before.

        Raises
        ------
        StaleResultError
            A different identity is recorded (naming what changed), unless the run overwrites.
        """
        self._check_open()
        return check_identity(self.out_dir, identity, overwrite=self.overwrite, name=name)

    def clear(self, name: str, extra: Sequence[str] = ()) -> None:
        """Delete the store ``out_dir/name`` (and the named ``extra`` files in it) before an overwrite."""
        self._check_open()
        clear_store(self.out_dir / name, extra=extra)

    # ------------------------------------------------------------------------------------------- measuring
    def measure(self, sim: Simulation, frames, solver: Solver | None = None, budget: Budget | None = None,
                name: str = "measurements") -> Measurements:
        """:meth:`~mincam_sim.render.simulation.Simulation.measure`, kept in ``out_dir/name`` (resumable) and
        ``out_dir/name.npz``."""
        m = sim.measure(frames, solver, budget, sink=self.sink(name), show_progress=self.show_progress)
        m.save_csv(self.out_dir / f"{name}.csv")
        m.save_npz(self.out_dir / f"{name}.npz")
        return m

    def measure_changes(self, sim: Simulation, frames, background=None, solver: Solver | None = None,
                        budget: Budget | None = None, name: str = "measurements") -> Changes:
        """:meth:`~mincam_sim.render.simulation.Simulation.measure_changes`, kept in ``out_dir/name`` (resumable) and
        ``out_dir/name.npz``."""
        ch = sim.measure_changes(frames, background, solver, budget, sink=self.sink(name),
                                 show_progress=self.show_progress)
        ch.save_csv(self.out_dir / f"{name}.csv")
        ch.save_npz(self.out_dir / f"{name}.npz")
        return ch


__all__ = ["Run"]
