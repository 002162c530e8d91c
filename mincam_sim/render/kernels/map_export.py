"""Response maps and point-source responses out, as plain NumPy arrays with a JSON sidecar, for other tools.

:func:`export_maps` writes, in ``out_dir``:

* ``maps/<mixel>.npy``: the mixel's response map ``W`` (rows, cols) [sr = W/m^2 on the detector per
  W m^-2 sr^-1 of texel radiance], float64, row 0 at the top of the screen, column 0 at its left as a viewer
  facing it sees it: a frame's measurement is ``(W * frame).sum()`` [W/m^2 averaged over the detector];
* ``maps/<mixel>_stderr.npy``: each weight's Monte Carlo standard error (zeros for an exact model);
* ``forward_matrix.npy``: every map flattened, (n_mixels, rows * cols): ``A @ frame.ravel()`` measures a frame;
* ``psfs.npy`` (with a point-source grid): (ny, nx, n_mixels) responses to unit point sources at the grid's points
  [W/m^2 on the detector per W/sr of the source's intensity along the screen's normal]: the map of the texel that
  holds the point divided by the texel's area (a source smaller than a texel, the map constant over the texel);
* ``maps.json``: units, conventions, the screen (size, resolution, pose, texel size), every mixel (pose, d_f,
  detector, mask), the grid's positions, and what made the maps (solver, samples, seed, versions).

A folder holds one export: an export into a folder that holds an earlier one removes the earlier export's files
that it does not write itself (the maps of mixels no longer there, ``psfs.npy`` without a grid), identified by
what the earlier ``maps.json`` lists, and only by the names this module writes; no other file is touched. While
an export writes, ``.maps_export_pending.json`` lists every file it or the earlier export may have left, and
``maps.json`` (written last) is absent: an export that is interrupted leaves no sidecar describing a mixed
folder, and the next export removes what the interrupted one left. Several processes exporting into one folder
hold its lock around the export (:func:`~mincam_sim.storage.store.lock_out_dir`: ``mincam-sim export-maps``
does).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from mincam_sim.model.optics import check_mixel_file_names, mixel_file_stem
from mincam_sim.render.kernels.map_tracing import ResponseMaps
from mincam_sim.render.scene.mincam_scene import geometry_meta
from mincam_sim.scene.display import Screen
from mincam_sim.storage.atomic import atomic_path, atomic_write_json, remove_files

UNITS_MAP = "sr (W/m^2 averaged over the detector per W m^-2 sr^-1 of a texel's radiance)"
UNITS_PSF = "m^-2 sr (W/m^2 averaged over the detector per W/sr of a point source's intensity along the screen normal)"
SIDECAR = "maps.json"
FORWARD_MATRIX = "forward_matrix.npy"
PSFS = "psfs.npy"
#: Written before an export touches anything, removed once its ``maps.json`` is written: every file the export
#: and the earlier one may have left in the folder, for the next export to remove if this one is interrupted.
PENDING = ".maps_export_pending.json"


def psf_grid_points_m(screen: Screen, grid: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Screen coordinates (x right, y up) [m] of an ``nx x ny`` point grid at the centres of equal cells of the
    screen, each (ny, nx), row 0 at the top."""
    nx, ny = grid
    x = ((np.arange(nx) + 0.5) / nx - 0.5) * screen.width_m
    y = (0.5 - (np.arange(ny) + 0.5) / ny) * screen.height_m
    return np.meshgrid(x, y)


def point_responses(maps: ResponseMaps, screen: Screen, grid: tuple[int, int]) -> np.ndarray:
    """(ny, nx, n_mixels) responses to unit point sources on the grid [m^-2 sr]: the weight of the texel that holds
    each point divided by the texel's area."""
    gx, gy = psf_grid_points_m(screen, grid)
    cols, rows = screen.resolution
    j = np.clip(np.floor((gx / screen.width_m + 0.5) * cols).astype(int), 0, cols - 1)
    i = np.clip(np.floor((0.5 - gy / screen.height_m) * rows).astype(int), 0, rows - 1)
    return np.moveaxis(maps.weights_sr[:, i, j], 0, -1) / screen.texel_area_m2


def export_maps(maps: ResponseMaps, mincam, screen: Screen, out_dir: str | Path,
                psf_grid: tuple[int, int] | None = None, say: Callable[[str], None] | None = None) -> Path:
    """Write the maps (and the point-source responses of a grid) into a folder as one complete export.

    Parameters
    ----------
    maps : ResponseMaps
        The mixels' response maps over ``screen``.
    mincam : Mincam
        The mincam the maps are of (its geometry goes into ``maps.json``).
    screen : Screen
        The screen the maps are over.
    out_dir : str or Path
        The folder (created if needed); where several processes may export into it, the caller holds its lock
        (:func:`~mincam_sim.storage.store.lock_out_dir`).
    psf_grid : tuple of int, optional
        ``(nx, ny)``: also write ``psfs.npy``, the responses to unit point sources on that grid.
    say : callable, optional
        Told, in one line, which files of an earlier export this one removed (nothing is said otherwise).

    Returns
    -------
    Path
        The sidecar ``maps.json``.

    Raises
    ------
    StoreError
        A file of the earlier export cannot be removed (naming it).

    Notes
    -----
    Every file is written atomically; the files of an earlier export in the folder that this one does not write
    are removed (module docstring), so the folder never mixes two exports.
    """
    check_mixel_file_names(maps.mixel_names)
    out = Path(out_dir)
    (out / "maps").mkdir(parents=True, exist_ok=True)
    files = {}
    for name in maps.mixel_names:
        stem = mixel_file_stem(name)
        files[name] = {"map": f"maps/{stem}.npy", "stderr": f"maps/{stem}_stderr.npy"}
    writes = {rel for entry in files.values() for rel in entry.values()} | {FORWARD_MATRIX}
    if psf_grid is not None:
        writes.add(PSFS)
    earlier = earlier_export_files(out)
    # before anything changes: what an interrupted export would leave, for the next one to remove
    atomic_write_json(out / PENDING, {"what": "files an unfinished export of response maps may have left here; "
                                              "the next export removes those it does not write",
                                      "files": sorted(earlier | writes)}, indent=1)
    removed = _remove(out, [SIDECAR, *sorted(earlier - writes)])
    for k, name in enumerate(maps.mixel_names):
        _save(out / files[name]["map"], maps.weights_sr[k])
        _save(out / files[name]["stderr"], np.sqrt(maps.variance_sr2[k]))
    _save(out / FORWARD_MATRIX, maps.weights_sr.reshape(len(maps.mixel_names), -1))
    sidecar = {
        "what": "response maps: a frame's measurement is (W * frame).sum() [W/m^2 averaged over the detector]",
        "units": {"map": UNITS_MAP, "frame": "W m^-2 sr^-1 (radiance of each screen texel)",
                  "measurement": "W/m^2 (irradiance averaged over the detector)", "lengths": "m"},
        "conventions": {"array": "(rows, cols), row 0 at the top of the screen, column 0 at its left as a viewer "
                                 "facing the screen sees it",
                        "forward_matrix": "(n_mixels, rows * cols): maps flattened row-major; A @ frame.ravel()"},
        "mixel_names": list(maps.mixel_names), "files": files, "forward_matrix": FORWARD_MATRIX,
        "screen": {"width_m": screen.width_m, "height_m": screen.height_m, "resolution": list(screen.resolution),
                   "shape_rows_cols": list(screen.shape), "texel_size_m": list(screen.texel_size_m),
                   "position_m": list(screen.pose.position_m), "forward": list(screen.pose.forward),
                   "up": list(screen.pose.up)},
        "geometry": geometry_meta(mincam, screen),
        "source": {k: v for k, v in maps.meta.items() if k not in ("mixels", "screen")},
    }
    if psf_grid is not None:
        nx, ny = psf_grid
        _save(out / PSFS, point_responses(maps, screen, (nx, ny)))
        gx, gy = psf_grid_points_m(screen, (nx, ny))
        sidecar["psfs"] = {"file": PSFS, "shape": [ny, nx, len(maps.mixel_names)], "units": UNITS_PSF,
                           "points_x_m": gx[0].tolist(), "points_y_m": gy[:, 0].tolist(),
                           "what": "responses to unit point sources on the grid (screen coordinates, x right, y up): "
                                   "the map of the texel holding each point / the texel's area"}
    path = out / SIDECAR
    with atomic_path(path) as tmp:
        Path(tmp).write_text(json.dumps(sidecar, indent=1, default=str))
    _remove(out, [PENDING])
    stale = [rel for rel in removed if rel != SIDECAR]
    if stale and say is not None:
        say(f"removed {len(stale)} file{'s' if len(stale) > 1 else ''} of the earlier export in {out} that this "
            f"export does not write: {_listing(stale)}")
    return path


def earlier_export_files(out_dir: str | Path) -> set[str]:
    """The files (paths relative to ``out_dir``) that an earlier export wrote there: those its ``maps.json`` lists
    and, when an export was interrupted, those its pending list names; only names this module writes
    (``maps/<mixel>.npy``, ``maps/<mixel>_stderr.npy``, ``forward_matrix.npy``, ``psfs.npy``) are taken. An
    unreadable or foreign file lists nothing."""
    out = Path(out_dir)
    listed: list[object] = []
    sidecar = _read_json(out / SIDECAR)
    if isinstance(sidecar, dict):
        entries = sidecar.get("files")
        for entry in entries.values() if isinstance(entries, dict) else ():
            listed += entry.values() if isinstance(entry, dict) else ()
        psfs = sidecar.get("psfs")
        listed += [sidecar.get("forward_matrix"), psfs.get("file") if isinstance(psfs, dict) else None]
    pending = _read_json(out / PENDING)
    if isinstance(pending, dict) and isinstance(pending.get("files"), list):
        listed += pending["files"]
    return {rel for rel in listed if isinstance(rel, str) and _is_export_name(rel)}


def _is_export_name(rel: str) -> bool:
    """True for a name this module writes: ``forward_matrix.npy``, ``psfs.npy``, ``maps/<stem>.npy`` with a stem
    as ``mincam_sim.model.optics.mixel_file_stem`` makes it (letters, digits, ``-``, ``_``)."""
    if rel in (FORWARD_MATRIX, PSFS):
        return True
    folder, _, name = rel.partition("/")
    stem = name.removesuffix(".npy")
    return folder == "maps" and name.endswith(".npy") and bool(stem) and mixel_file_stem(stem) == stem


def _read_json(path: Path) -> object:
    try:
        return json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        return None


def _remove(out: Path, rels: Iterable[str]) -> list[str]:
    """Delete these files of ``out`` (names relative to it) where they are; return those deleted."""
    removed = remove_files([out / rel for rel in rels], f"a file of the earlier export in {out} that this export "
                           "replaces", "delete it by hand or choose another folder")
    return [path.relative_to(out).as_posix() for path in removed]


def _listing(rels: list[str], limit: int = 6) -> str:
    shown = ", ".join(rels[:limit])
    return shown if len(rels) <= limit else f"{shown} and {len(rels) - limit} more"


def _save(path: Path, array: np.ndarray) -> None:
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.save(fh, np.ascontiguousarray(array, dtype=np.float64))


__all__ = ["earlier_export_files", "export_maps", "point_responses", "psf_grid_points_m"]
