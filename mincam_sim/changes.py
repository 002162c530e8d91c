"""Typed results of a change measurement: dP and P per frame with what the run did to get them (pure numpy)."""

from __future__ import annotations

import csv
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from mincam_sim.errors import StoreError
from mincam_sim.measurements import MEASUREMENTS_KEYS, Measurements, json_default, read_npz
from mincam_sim.storage.atomic import atomic_open, atomic_save_npz


@dataclass(frozen=True)
class RunInfo:
    """What a change run did, always present whatever the solver.

    Attributes
    ----------
    solver : str
        The change solver's name: ``"plain_change"`` or ``"stratified_change"``.
    seed, replicates : int
    rays_per_mixel_per_frame : int
        Rays traced per mixel per frame, the mean over the frames (a stratified pair: the frame pass and the
        lanes of the background pass traced again, those whose frame paths met a moving shape).
    spp_per_mixel_per_frame : int
        The budget's ray count per pass (after any target search).
    target_rel_stderr : float
        0 when the counts were given.
    reached_rel_stderr : float or None
        Worst relative standard error over the significant (> 3 sigma) changes; None if none was significant.
    retried_frames : tuple of int
        Frames measured again with more replicates because one replicate dominated their spread.
    heavy_tailed : tuple of (frame, mixel)
        Values whose replicates stayed dominated by one after the retry: their sigma is uncertain.
    fallbacks : tuple of str
        What the solver could not bound or guide, and what it did instead.
    guided_frames : int or None
        Stratified runs: frames whose bounces were guided.
    launches : str or None
        Stratified runs: ``"frozen"`` (recorded once, replayed) or ``"traced..."`` with the reason.
    """

    solver: str
    seed: int
    replicates: int
    rays_per_mixel_per_frame: int
    spp_per_mixel_per_frame: int
    target_rel_stderr: float
    reached_rel_stderr: float | None
    retried_frames: tuple[int, ...] = ()
    heavy_tailed: tuple[tuple[int, int], ...] = ()
    fallbacks: tuple[str, ...] = ()
    guided_frames: int | None = None
    launches: str | None = None


@dataclass
class Changes:
    """Per-frame changes ``dP = P(frame) - P(background)`` and absolute ``P``, (n_frames, n_mixels) each [W/m^2],
    with their standard errors, and the run's :class:`RunInfo`.

    ``frame_columns`` (optional) are extra per-frame columns for the CSV (e.g. each mover's offset [m], time
    [s]), name -> (n_frames,) array.
    """

    dp: Measurements
    p: Measurements
    info: RunInfo
    frame_columns: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def mixel_names(self) -> list[str]:
        return self.dp.mixel_names

    @property
    def n_frames(self) -> int:
        return self.dp.n_frames

    def save_npz(self, path: str | Path) -> Path:
        """Arrays ``irradiance_w_m2`` / ``stderr_w_m2`` (P), ``delta_irradiance_w_m2`` / ``delta_stderr_w_m2``
        (dP), (n_frames, n_mixels) each, the frame columns and the metadata as JSON."""
        path = Path(path)
        extra = {f"frame_{k}": np.asarray(v) for k, v in self.frame_columns.items()}
        atomic_save_npz(path, irradiance_w_m2=self.p.irradiance_w_m2, stderr_w_m2=self.p.stderr_w_m2,
                        delta_irradiance_w_m2=self.dp.irradiance_w_m2, delta_stderr_w_m2=self.dp.stderr_w_m2,
                        mixel_names=np.array(self.mixel_names), **extra,
                        meta_json=np.array(json.dumps({**self.dp.meta, "run_info": asdict(self.info)},
                                                      default=json_default)))
        return path

    @classmethod
    def load_npz(cls, path: str | Path) -> Changes:
        """The change run :meth:`save_npz` wrote (``StoreError`` naming the file for anything else: a torn file,
        or measurements without dP, which ``Measurements.load_npz`` reads)."""
        with read_npz(path, (*MEASUREMENTS_KEYS, "delta_irradiance_w_m2", "delta_stderr_w_m2"),
                      "Changes.save_npz") as (data, meta):
            info = meta.pop("run_info", None)
            if not isinstance(info, dict):
                raise StoreError(f"{path} is not a file written by Changes.save_npz: its metadata has no run_info "
                                 "(measurements without dP: read it with Measurements.load_npz)")
            names = [str(s) for s in data["mixel_names"]]
            columns = {k[len("frame_"):]: data[k] for k in data.files if k.startswith("frame_")}
            dp = Measurements(data["delta_irradiance_w_m2"], data["delta_stderr_w_m2"], names, dict(meta))
            p = Measurements(data["irradiance_w_m2"], data["stderr_w_m2"], names, dict(meta))
            info["retried_frames"] = tuple(info["retried_frames"])
            info["heavy_tailed"] = tuple(tuple(x) for x in info["heavy_tailed"])
            info["fallbacks"] = tuple(info["fallbacks"])
            if "estimator" in info:  # files written before 0.6.0 name the solver "estimator": "plain" | "stratified"
                info["solver"] = f"{info.pop('estimator')}_change"
            return cls(dp, p, RunInfo(**info), columns)

    def save_csv(self, path: str | Path) -> Path:
        """One row per frame: frame, the frame columns, then per mixel ``<m>_dP_w_m2``, ``<m>_dP_stderr_w_m2``,
        ``<m>_P_w_m2``, ``<m>_P_stderr_w_m2``; metadata in a ``#`` header line."""
        path = Path(path)
        with atomic_open(path, "w") as fh:
            fh.write("# " + json.dumps({"run_info": asdict(self.info)}, default=json_default) + "\n")
            writer = csv.writer(fh)
            header = ["frame", *self.frame_columns]
            for name in self.mixel_names:
                header += [f"{name}_dP_w_m2", f"{name}_dP_stderr_w_m2", f"{name}_P_w_m2", f"{name}_P_stderr_w_m2"]
            writer.writerow(header)
            for i in range(self.n_frames):
                row: list = [i, *(repr(float(np.asarray(v)[i])) for v in self.frame_columns.values())]
                for k in range(len(self.mixel_names)):
                    row += [repr(float(x[i, k])) for x in (self.dp.irradiance_w_m2, self.dp.stderr_w_m2,
                                                           self.p.irradiance_w_m2, self.p.stderr_w_m2)]
                writer.writerow(row)
        return path
