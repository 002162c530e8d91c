"""Where a solver's per-frame results go: the sink protocol (pure numpy; nothing here touches a file).

A solver's plan measures its frames one row (or one chunk of rows) at a time. Before the first row the
simulation opens a :class:`FrameTable` from the :class:`FrameSink` it was given; the table says which frames are
still to do (:meth:`FrameTable.pending`: all of them, or those a killed run did not finish) and takes each row as
it comes (:meth:`FrameTable.write`). :func:`collect` is that loop. The sink is already identified: a store sink
carries the run's identity (built by :class:`mincam_sim.runs.run.Run`, the one place); the numerics never see it.

* :class:`MemorySink` (the default) keeps rows in memory: no file, no lock, no identity needed.
* :class:`mincam_sim.storage.store.StoreSink` keeps them in a :class:`~mincam_sim.storage.store.ResultStore` (resumable,
  refused when the identity differs); :class:`mincam_sim.runs.run.Run` hands one to the solver, under the run's one
  lock.

The solvers (``mincam_sim.render``) reach persistence only through this module (and content caches they are
handed): they never open a store or take a lock (``tests/core/test_layering.py`` checks it).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class FrameTable(Protocol):
    """Rows of one run, (n_frames, n_columns): what a :class:`FrameSink` opens.

    Attributes
    ----------
    values, stderr : (n_frames, n_columns) arrays
        Rows found done when the table was opened (a resumed run's), NaN elsewhere.
    """

    values: np.ndarray
    stderr: np.ndarray

    def pending(self) -> np.ndarray:
        """Indices of the frames still to measure."""

    def write(self, indices: Any, values: np.ndarray, stderr: np.ndarray) -> None:
        """Keep the rows of ``indices``."""

    def close(self) -> None:
        """Flush and release what the table holds (idempotent)."""


@runtime_checkable
class FrameSink(Protocol):
    """Where a solver's rows go.

    Attributes
    ----------
    persistent : bool
        True if the rows outlive the call (a store, identified by the run that made it).
    cache : ContentCache or None
        Where content-addressed intermediate results (response maps) may be kept and found again.
    """

    persistent: bool
    cache: Any

    def open(self, n_frames: int, columns: Sequence[str]) -> FrameTable:
        """The table of ``n_frames`` rows and these column names."""


class MemoryTable:
    """A :class:`FrameTable` in memory: every frame pending, rows kept in two arrays."""

    def __init__(self, n_frames: int, n_columns: int) -> None:
        self.values = np.full((int(n_frames), int(n_columns)), np.nan)
        self.stderr = np.full_like(self.values, np.nan)
        self.done = np.zeros(int(n_frames), dtype=bool)

    def pending(self) -> np.ndarray:
        """Indices of the frames not written yet."""
        return np.flatnonzero(~self.done)

    def write(self, indices: Any, values: np.ndarray, stderr: np.ndarray) -> None:
        """Keep the rows of ``indices``."""
        self.values[indices], self.stderr[indices] = values, stderr
        self.done[indices] = True

    def close(self) -> None:
        """Nothing to release."""


class MemorySink:
    """The default :class:`FrameSink`: rows in memory, no file, no cache."""

    persistent = False
    cache = None

    def open(self, n_frames: int, columns: Sequence[str]) -> MemoryTable:
        """A fresh :class:`MemoryTable`."""
        return MemoryTable(n_frames, len(columns))


def collect(rows: Iterable[tuple[Any, np.ndarray, np.ndarray]], table: FrameTable) -> tuple[np.ndarray, np.ndarray]:
    """Values and standard errors of every frame: the table's rows found done, then ``rows`` (``(indices, values,
    stderr)``, each written to ``table`` as it comes). The table is closed at the end, also on an error."""
    try:
        values, errors = np.array(table.values, dtype=float), np.array(table.stderr, dtype=float)
        for idx, row_values, row_errors in rows:
            values[idx], errors[idx] = row_values, row_errors
            table.write(idx, row_values, row_errors)
    finally:
        table.close()
    return values, errors


__all__ = ["FrameSink", "FrameTable", "MemorySink", "MemoryTable", "collect"]
