"""Where a solver's per-frame results go: the sink protocol (pure numpy; nothing here touches a file).

A solver measures its frames one row (or one chunk of rows) at a time. Before the first row it opens a
:class:`FrameTable` from the :class:`FrameSink` it was given, passing what determines its numbers (its identity,
built with :func:`mincam_sim.identity.build_identity`); the table says which frames are still to do
(:meth:`FrameTable.pending`: all of them, or those a killed run did not finish) and takes each row as it comes
(:meth:`FrameTable.write`). :func:`collect` is that loop.

* :class:`MemorySink` (the default) keeps rows in memory: no file, no lock, no identity needed.
* :class:`mincam_sim.store.StoreSink` keeps them in a :class:`~mincam_sim.store.ResultStore` (resumable,
  refused when the identity differs); :class:`mincam_sim.run.Run` hands one to the solver, under the run's one
  lock.

The solvers (``mincam_sim.render``) reach persistence only through this module (and content caches they are
handed): they never open a store or take a lock (``tests/core/test_layering.py`` checks it). The deprecated ``out_dir=``
of the old entry points is :func:`resolve_sink`'s one call into :mod:`mincam_sim.store`.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from .errors import InputError


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
        True if the rows outlive the call: the solver then fingerprints everything its numbers depend on (its
        frames' content included) for :meth:`open`; False: the identity is not looked at.
    cache : ContentCache or None
        Where content-addressed intermediate results (response maps) may be kept and found again.
    """

    persistent: bool
    cache: Any

    def open(self, identity: Any, n_frames: int, columns: Sequence[str]) -> FrameTable:
        """The table for a run with this identity, ``n_frames`` rows and these column names."""


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
    """The default :class:`FrameSink`: rows in memory, no file, no identity, no cache."""

    persistent = False
    cache = None

    def open(self, identity: Any, n_frames: int, columns: Sequence[str]) -> MemoryTable:
        """A fresh :class:`MemoryTable` (``identity`` is not looked at)."""
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


def resolve_sink(sink: FrameSink | None, out_dir: str | Path | None, overwrite: bool, where: str) -> FrameSink:
    """The sink a solver writes to: ``sink``, or a :class:`MemorySink`; or, for the deprecated ``out_dir=`` of the
    old entry points (kept for one release), a store in ``out_dir`` that locks it while the rows are written.

    Raises
    ------
    InputError
        Both ``sink`` and ``out_dir`` given.
    """
    if out_dir is None:
        return MemorySink() if sink is None else sink
    if sink is not None:
        raise InputError(f"{where}: give sink= or out_dir=, not both (out_dir= is deprecated: use mincam_sim.Run)")
    warnings.warn(f"{where}(out_dir=...) is deprecated and goes in the next release: keep results with "
                  "`with mincam_sim.Run(out_dir) as run: run.measure(...)` (or pass sink=run.sink(name))",
                  DeprecationWarning, stacklevel=3)
    from .store import StoreSink  # the one store-opening helper, shared with mincam_sim.run

    return StoreSink(out_dir, overwrite=overwrite)


__all__ = ["FrameSink", "FrameTable", "MemorySink", "MemoryTable", "collect", "resolve_sink"]
