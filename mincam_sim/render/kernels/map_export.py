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
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from mincam_sim.render.kernels.map_tracing import ResponseMaps, _safe
from mincam_sim.render.scene.mincam_scene import geometry_meta
from mincam_sim.scene.display import Screen
from mincam_sim.storage.atomic import atomic_path

UNITS_MAP = "sr (W/m^2 averaged over the detector per W m^-2 sr^-1 of a texel's radiance)"
UNITS_PSF = "m^-2 sr (W/m^2 averaged over the detector per W/sr of a point source's intensity along the screen normal)"


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
                psf_grid: tuple[int, int] | None = None) -> Path:
    """Write the maps (and the point-source responses of ``psf_grid = (nx, ny)``) into ``out_dir`` (module
    docstring); returns the sidecar's path. Every file is written atomically."""
    out = Path(out_dir)
    (out / "maps").mkdir(parents=True, exist_ok=True)
    files = {}
    for k, name in enumerate(maps.mixel_names):
        stem = _safe(name)
        _save(out / "maps" / f"{stem}.npy", maps.weights_sr[k])
        _save(out / "maps" / f"{stem}_stderr.npy", np.sqrt(maps.variance_sr2[k]))
        files[name] = {"map": f"maps/{stem}.npy", "stderr": f"maps/{stem}_stderr.npy"}
    _save(out / "forward_matrix.npy", maps.weights_sr.reshape(len(maps.mixel_names), -1))
    sidecar = {
        "what": "response maps: a frame's measurement is (W * frame).sum() [W/m^2 averaged over the detector]",
        "units": {"map": UNITS_MAP, "frame": "W m^-2 sr^-1 (radiance of each screen texel)",
                  "measurement": "W/m^2 (irradiance averaged over the detector)", "lengths": "m"},
        "conventions": {"array": "(rows, cols), row 0 at the top of the screen, column 0 at its left as a viewer "
                                 "facing the screen sees it",
                        "forward_matrix": "(n_mixels, rows * cols): maps flattened row-major; A @ frame.ravel()"},
        "mixel_names": list(maps.mixel_names), "files": files, "forward_matrix": "forward_matrix.npy",
        "screen": {"width_m": screen.width_m, "height_m": screen.height_m, "resolution": list(screen.resolution),
                   "shape_rows_cols": list(screen.shape), "texel_size_m": list(screen.texel_size_m),
                   "position_m": list(screen.pose.position_m), "forward": list(screen.pose.forward),
                   "up": list(screen.pose.up)},
        "geometry": geometry_meta(mincam, screen),
        "source": {k: v for k, v in maps.meta.items() if k not in ("mixels", "screen")},
    }
    if psf_grid is not None:
        nx, ny = psf_grid
        _save(out / "psfs.npy", point_responses(maps, screen, (nx, ny)))
        gx, gy = psf_grid_points_m(screen, (nx, ny))
        sidecar["psfs"] = {"file": "psfs.npy", "shape": [ny, nx, len(maps.mixel_names)], "units": UNITS_PSF,
                           "points_x_m": gx[0].tolist(), "points_y_m": gy[:, 0].tolist(),
                           "what": "responses to unit point sources on the grid (screen coordinates, x right, y up): "
                                   "the map of the texel holding each point / the texel's area"}
    path = out / "maps.json"
    with atomic_path(path) as tmp:
        Path(tmp).write_text(json.dumps(sidecar, indent=1, default=str))
    return path


def _save(path: Path, array: np.ndarray) -> None:
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.save(fh, np.ascontiguousarray(array, dtype=np.float64))


__all__ = ["export_maps", "point_responses", "psf_grid_points_m"]
