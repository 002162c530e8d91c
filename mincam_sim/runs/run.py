"""Runs kept outside the numerics: :class:`Run` owns an output directory -- its one lock, the one identity of
each run, its per-frame stores (resume) and its atomic outputs -- and hands the simulation an identified sink;
the solvers never import it.

::

    with ms.Run("out/render") as run:
        m = run.measure(sim, frames, solver=ms.ResponseMap(), budget=ms.Budget(samples_per_texel=256))
        ch = run.measure_changes(world_sim, frames, solver=ms.StratifiedChange())

A run's identity is built here only (:func:`run_identity`): the simulation's ``identity`` (for a world from a
file, every file it names, recursively), the solver's ``identity``, the budget as requested
(``Budget.describe``), the frames (a display's content hash; a world's updates and background), the Mitsuba
variant and the library versions. Per-frame results go to ``OUT/<name>/`` as they are computed (a killed run
resumes where it stopped; a run with anything else changed is refused, naming what changed, unless
``overwrite``); the finished result is written atomically as ``OUT/<name>.npz`` (and ``.csv``), and a rerun of
the same run returns it without rendering. The directory holds one lock file (``OUT/.mincam.lock``) whatever
the number of stores in it. An in-memory measurement (``sim.measure(...)`` without a run) builds no identity.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from mincam_sim.budget import Budget
from mincam_sim.changes import Changes
from mincam_sim.errors import InputError, StoreError
from mincam_sim.measurements import NPZ_DAMAGE, Measurements
from mincam_sim.render.simulation import Simulation
from mincam_sim.render.solvers import Solver
from mincam_sim.storage import identity
from mincam_sim.storage.identity import run_key
from mincam_sim.storage.store import DirLock, StoreSink, check_identity, clear_store, lock_out_dir

#: What reading a damaged or foreign ``.npz`` result raises: a ``StoreError`` naming the file (and what is wrong
#: with it) from ``load_npz``. Such a file is computed again.
UNREADABLE_NPZ = (StoreError, *NPZ_DAMAGE)


def run_identity(sim: Simulation, frames, solver: Solver, budget: Budget, background=None) -> dict:
    """The one identity of a run: what determines its numbers (:func:`mincam_sim.storage.identity.run_identity`)."""
    from mincam_sim.render import backend

    return identity.run_identity(sim.identity(), solver.identity(), budget.describe(),
                                 sim.frames_identity(frames, background), backend.variant())


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
        self._recorded: Any = None  # the identity record_identity last recorded or checked
        #: Names of the results this run returned as they were, finished by an earlier run (nothing rendered).
        self.reused: list[str] = []
        #: Results whose finished file was damaged or unreadable (name -> what reading it raised): computed again
        #: (from the per-frame store where it holds the frames) and written anew.
        self.unreadable: dict[str, str] = {}

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
    def sink(self, name: str, identity: Any = None) -> StoreSink:
        """The per-frame store ``out_dir/name`` of a run with this ``identity`` (default: the one
        :meth:`record_identity` recorded in this run; under this run's lock: no lock of its own); its response
        maps are cached in ``out_dir/name/cache``. :meth:`measure` and :meth:`measure_changes` build the
        identity and the sink themselves."""
        identity = self._recorded if identity is None else identity
        return StoreSink(self.out_dir / name, identity, overwrite=self.overwrite, lock=self._check_open())

    def record_identity(self, identity: Any, name: str = "identity.json") -> bool:
        """Record what the directory's outputs are computed from, or check that it is unchanged
        (:func:`mincam_sim.storage.store.check_identity`): True if the same identity was recorded before.

        Raises
        ------
        StaleResultError
            A different identity is recorded (naming what changed), unless the run overwrites.
        """
        self._check_open()
        same = check_identity(self.out_dir, identity, overwrite=self.overwrite, name=name)
        self._recorded = identity
        return same

    def clear(self, name: str, extra: Sequence[str] = ()) -> None:
        """Delete the store ``out_dir/name`` (and the named ``extra`` files in it) before an overwrite."""
        self._check_open()
        clear_store(self.out_dir / name, extra=extra)

    def _finished(self, name: str, key: str, kind):
        """The finished result in ``out_dir/name.npz`` if it carries this identity key (else None); a result
        returned is named in :attr:`reused`, a damaged or unreadable file (torn, empty, foreign) in
        :attr:`unreadable` (it is computed again and replaced). Its CSV, if missing, is written again."""
        path = self.out_dir / f"{name}.npz"
        if self.overwrite or not path.is_file():
            return None
        try:
            done = kind.load_npz(path)
        except UNREADABLE_NPZ as err:
            self.unreadable[name] = f"{type(err).__name__}: {err}".rstrip(": ")
            return None
        meta = done.dp.meta if isinstance(done, Changes) else done.meta
        if meta.get("identity_key") != key:
            return None
        self.reused.append(name)
        csv = self.out_dir / f"{name}.csv"
        if not csv.is_file():
            done.save_csv(csv)
        return done

    def _open_sink(self, name: str, identity: dict, lock: DirLock) -> StoreSink:
        """The per-frame store of a run about to be computed, refused (before anything is traced) if it holds
        another run."""
        sink = StoreSink(self.out_dir / name, identity, overwrite=self.overwrite, lock=lock)
        sink.refuse_another_run()
        return sink

    # ------------------------------------------------------------------------------------------- measuring
    def measure(self, sim: Simulation, frames, solver: Solver | None = None, budget: Budget | None = None,
                name: str = "measurements") -> Measurements:
        """:meth:`~mincam_sim.render.simulation.Simulation.measure`, kept in ``out_dir/name`` (resumable) and
        ``out_dir/name.npz`` (returned as it is when this same run finished before)."""
        lock = self._check_open()
        solver, budget = sim.solver_for(solver), Budget() if budget is None else budget
        identity = run_identity(sim, frames, solver, budget)
        key = run_key(identity)
        done = self._finished(name, key, Measurements)
        if done is not None:
            return done
        sink = self._open_sink(name, identity, lock)
        m = sim.measure(frames, solver, budget, sink=sink, show_progress=self.show_progress)
        m.meta.update(identity_key=key, frames=identity["frames"])
        m.save_csv(self.out_dir / f"{name}.csv")
        m.save_npz(self.out_dir / f"{name}.npz")
        return m

    def measure_changes(self, sim: Simulation, frames, background=None, solver: Solver | None = None,
                        budget: Budget | None = None, name: str = "measurements") -> Changes:
        """:meth:`~mincam_sim.render.simulation.Simulation.measure_changes`, kept in ``out_dir/name`` (resumable)
        and ``out_dir/name.npz`` (returned as it is when this same run finished before)."""
        lock = self._check_open()
        solver, budget = sim.solver_for(solver, changes=True), Budget() if budget is None else budget
        identity = run_identity(sim, frames, solver, budget, background)
        key = run_key(identity)
        done = self._finished(name, key, Changes)
        if done is not None:
            return done
        sink = self._open_sink(name, identity, lock)
        ch = sim.measure_changes(frames, background, solver, budget, sink=sink, show_progress=self.show_progress)
        ch.dp.meta["identity_key"] = ch.p.meta["identity_key"] = key
        ch.save_csv(self.out_dir / f"{name}.csv")
        ch.save_npz(self.out_dir / f"{name}.npz")
        return ch


__all__ = ["Run", "run_identity"]
