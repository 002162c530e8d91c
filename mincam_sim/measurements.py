"""Mixel measurements with their Monte Carlo standard errors and metadata (pure numpy).

Values are the irradiance averaged over each detector, in W/m^2 (multiply by the detector area for the
radiant power in W: :meth:`Measurements.power_w`).
"""

from __future__ import annotations

import csv
import json
import tokenize
import zipfile
import zlib
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mincam_sim.errors import MincamError, StoreError
from mincam_sim.storage.atomic import atomic_open, atomic_save_npz

#: What reading a damaged ``.npz`` raises (numpy and zipfile; found by cutting a result short at every length and
#: changing bytes in it): an empty file ``EOFError``, one cut short ``zipfile.BadZipFile``, a changed byte
#: ``BadZipFile`` (CRC), ``ValueError``, ``KeyError``, ``NotImplementedError`` (a compression method),
#: ``tokenize.TokenError`` or ``SyntaxError`` (an array's header); a file holding objects ``ValueError`` (never
#: unpickled).
NPZ_DAMAGE = (OSError, ValueError, KeyError, EOFError, NotImplementedError, SyntaxError, zipfile.BadZipFile,
              zlib.error, tokenize.TokenError)


@dataclass
class Measurements:
    """Per-frame, per-mixel measurements.

    Attributes
    ----------
    irradiance_w_m2 : (n_frames, n_mixels) ndarray
        Mean irradiance on each detector [W/m^2].
    stderr_w_m2 : (n_frames, n_mixels) ndarray
        Monte Carlo standard error of each value [W/m^2].
    mixel_names : list of str
    meta : dict
        Variant, seed, samples, form, geometry ... (JSON-serialisable).
    maps : ResponseMaps or None
        The response maps a :class:`~mincam_sim.render.solvers.ResponseMap` solver measured through (None for
        other solvers, and once saved: not written to the npz).
    stderr_dof : (n_frames, n_mixels) ndarray or None
        Degrees of freedom of each standard error where the solver knows them per value (a response map's:
        ``map_tracing.effective_dof``; ``inf`` where nothing spread); None
        otherwise (a ray solver's are its replicates - 1), and once saved.
    """

    irradiance_w_m2: np.ndarray
    stderr_w_m2: np.ndarray
    mixel_names: list[str]
    meta: dict = field(default_factory=dict)
    maps: Any = field(default=None, repr=False, compare=False)
    stderr_dof: Any = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        self.irradiance_w_m2 = np.atleast_2d(np.asarray(self.irradiance_w_m2, dtype=np.float64))
        self.stderr_w_m2 = np.atleast_2d(np.asarray(self.stderr_w_m2, dtype=np.float64))
        if self.irradiance_w_m2.shape != self.stderr_w_m2.shape:
            raise ValueError("irradiance and stderr must have the same shape (n_frames, n_mixels)")
        if self.irradiance_w_m2.shape[1] != len(self.mixel_names):
            raise ValueError(f"{self.irradiance_w_m2.shape[1]} columns but {len(self.mixel_names)} mixel names")
        bad = ~(self.stderr_w_m2 >= 0)  # negative or NaN
        if bad.any():
            i, k = np.argwhere(bad)[0]
            raise ValueError(f"stderr_w_m2 must be standard errors >= 0 W/m^2 (not NaN), got "
                             f"{self.stderr_w_m2[i, k]!r} at frame {i}, mixel {self.mixel_names[k]!r} "
                             f"({int(bad.sum())} such value(s)); pass the Monte Carlo standard error, not a signed "
                             "difference")

    @property
    def n_frames(self) -> int:
        return self.irradiance_w_m2.shape[0]

    def relative_stderr(self) -> np.ndarray:
        """``stderr / |value|`` (inf where the value is 0)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.stderr_w_m2 / np.abs(self.irradiance_w_m2)

    def power_w(self, detector_areas_m2) -> np.ndarray:
        """Radiant power on each detector [W] = irradiance x detector area."""
        return self.irradiance_w_m2 * np.asarray(detector_areas_m2, dtype=np.float64)[None, :]

    def save_npz(self, path: str | Path) -> Path:
        """Write arrays + JSON metadata to an ``.npz`` file."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_save_npz(
            path,
            irradiance_w_m2=self.irradiance_w_m2,
            stderr_w_m2=self.stderr_w_m2,
            mixel_names=np.array(self.mixel_names),
            meta_json=np.array(json.dumps(self.meta, default=json_default)),
        )
        return path

    @classmethod
    def load_npz(cls, path: str | Path) -> Measurements:
        """The measurements :meth:`save_npz` wrote (``StoreError`` naming the file for anything else)."""
        with read_npz(path, MEASUREMENTS_KEYS, "Measurements.save_npz") as (data, meta):
            return cls(data["irradiance_w_m2"], data["stderr_w_m2"], [str(s) for s in data["mixel_names"]], meta)

    def frame_columns(self) -> dict[str, np.ndarray]:
        """Per-frame columns known from ``meta``: ``time_s`` (``meta["frame_times_s"]``) and the frame's position
        (``meta["frame_positions_m"]``, one (x, y[, z]) per frame: ``position_x_m``, ``position_y_m`` ...)."""
        cols: dict[str, np.ndarray] = {}
        times = self.meta.get("frame_times_s")
        if times is not None and len(times) == self.n_frames:
            cols["time_s"] = np.asarray(times, dtype=np.float64).reshape(-1)
        pos = self.meta.get("frame_positions_m")
        if pos is not None and len(pos) == self.n_frames:
            arr = np.asarray(pos, dtype=np.float64).reshape(self.n_frames, -1)
            for j in range(min(arr.shape[1], 3)):
                cols[f"position_{'xyz'[j]}_m"] = arr[:, j]
        return cols

    def save_csv(self, path: str | Path) -> Path:
        """Write one row per frame: frame, [time_s,] [position_x_m, position_y_m,] <mixel>_w_m2,
        <mixel>_stderr_w_m2 ...; metadata in a ``#`` header (:meth:`frame_columns` says where the time and
        position come from: the square's centre on the screen [m] for sweeps)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        extra = self.frame_columns()
        with atomic_open(path, "w") as fh:
            fh.write("# " + json.dumps(self.meta, default=json_default) + "\n")
            writer = csv.writer(fh)
            header = ["frame", *extra]
            for name in self.mixel_names:
                header += [f"{name}_w_m2", f"{name}_stderr_w_m2"]
            writer.writerow(header)
            for i in range(self.n_frames):
                row: list = [i, *(repr(float(v[i])) for v in extra.values())]
                for k in range(len(self.mixel_names)):
                    row += [repr(float(self.irradiance_w_m2[i, k])), repr(float(self.stderr_w_m2[i, k]))]
                writer.writerow(row)
        return path


MEASUREMENTS_KEYS = ("irradiance_w_m2", "stderr_w_m2", "mixel_names", "meta_json")


@contextmanager
def read_npz(path: str | Path, keys: Sequence[str], writer: str) -> Iterator[tuple[Any, dict]]:
    """The arrays of an npz file that ``writer`` wrote, and its ``meta_json`` parsed, checked before use.

    Raises
    ------
    FileNotFoundError
        No file at ``path``.
    StoreError
        The file is torn, empty or not an npz, lacks one of ``keys``, its metadata is not a JSON object, or its
        arrays do not fit one another (the message names the file, what is wrong and which writer it expects).
    """
    path = Path(path)
    what = f"{path} is not a file written by {writer}"
    try:
        data = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise
    except NPZ_DAMAGE as err:
        raise StoreError(f"{what}: it cannot be read as an npz ({type(err).__name__}: {err})") from None
    with data:
        try:
            files = set(data.files)
            missing = [k for k in keys if k not in files]
            if missing:
                held = ", ".join(sorted(files)) or "nothing"
                raise StoreError(f"{what}: it lacks {', '.join(missing)} (it holds {held})")
            meta = json.loads(str(data["meta_json"])) if "meta_json" in keys else {}
            if not isinstance(meta, dict):
                raise StoreError(f"{what}: its meta_json is not a JSON object")
        except NPZ_DAMAGE as err:
            if isinstance(err, StoreError):
                raise
            raise StoreError(f"{what}: an array of it cannot be read ({type(err).__name__}: {err})") from None
        try:
            yield data, meta
        except (*NPZ_DAMAGE, TypeError) as err:
            if isinstance(err, MincamError):
                raise
            raise StoreError(f"{what}: its contents do not fit together ({type(err).__name__}: {err})") from None


def json_default(obj):
    """``json.dumps(default=...)`` for numpy scalars and arrays and paths."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj)}")
