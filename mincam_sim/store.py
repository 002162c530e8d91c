"""Resumable on-disk results for long runs (pure numpy).

A run directory holds ``values.npy`` and ``stderr.npy`` (memory-mapped, one row per frame, NaN until
computed), ``done.npy`` (bool per frame) and ``run.json`` (the run's identity: a key derived from everything
that determines the numbers). Rows are flushed as soon as they are computed, so a killed run loses at most the
frame in progress; re-running with the same key skips finished frames, a different key is refused.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np


def run_key(identity: dict) -> str:
    """Stable hash of a JSON-serialisable description of a run."""
    return hashlib.sha256(json.dumps(identity, sort_keys=True, default=str).encode()).hexdigest()[:16]


class ResultStore:
    """Per-frame results of shape (n_frames, n_columns), written incrementally."""

    def __init__(self, directory: str | Path, n_frames: int, columns: list[str], identity: dict) -> None:
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.key = run_key(identity)
        info_path = self.directory / "run.json"
        shape = (int(n_frames), len(columns))
        if info_path.exists():
            info = json.loads(info_path.read_text())
            if info.get("key") != self.key or tuple(info.get("shape", ())) != shape:
                raise ValueError(
                    f"{self.directory} holds results of a different run (key {info.get('key')} vs {self.key}); "
                    "use another output directory or delete it to start over"
                )
            mode = "r+"
        else:
            info_path.write_text(json.dumps({"key": self.key, "shape": shape, "columns": columns,
                                             "identity": identity}, indent=1, default=str))
            mode = "w+"
        self.values = self._open("values.npy", shape, np.float64, mode, np.nan)
        self.stderr = self._open("stderr.npy", shape, np.float64, mode, np.nan)
        self.done = self._open("done.npy", (shape[0],), np.bool_, mode, False)
        self.columns = columns

    def _open(self, name: str, shape, dtype, mode: str, fill):
        path = self.directory / name
        if mode == "w+" or not path.exists():
            arr = np.lib.format.open_memmap(path, mode="w+", dtype=dtype, shape=shape)
            arr[...] = fill
            arr.flush()
            return arr
        return np.lib.format.open_memmap(path, mode="r+")

    def pending(self) -> np.ndarray:
        """Indices of frames not computed yet."""
        return np.flatnonzero(~np.asarray(self.done))

    def write(self, indices, values: np.ndarray, stderr: np.ndarray) -> None:
        """Store rows for ``indices`` and flush them to disk."""
        self.values[indices] = values
        self.stderr[indices] = stderr
        self.values.flush()
        self.stderr.flush()
        self.done[indices] = True
        self.done.flush()
