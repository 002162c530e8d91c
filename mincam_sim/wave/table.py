"""A mixel's response tabulated over its field of view, for the renderer."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from mincam_sim.errors import InputError, is_finite_real
from mincam_sim.model.optics import Mixel
from mincam_sim.wave.geometric import geometric_response, open_fraction
from mincam_sim.wave.propagation import _response_1d
from mincam_sim.wave.response import (
    WaveInfo,
    _axis_setup,
    _check_solver_sizes,
    _uniform_value,
    angular_response,
    check_fresnel_number,
)
from mincam_sim.wave.sampling import dot_pitch_m, separable_axis
from mincam_sim.wave.spectrum import DEFAULT_WAVELENGTHS_M, _check_wavelengths, silicon_qe, spectral_weights

TABLE_MEMORY_LIMIT_BYTES = 8 * 2**30  # [B] the most memory one response table may take while it is built


TABLE_BYTES_PER_CELL = 256  # [B] peak memory per (tan_x, tan_y) cell while a table is built (~19 float64 measured)


def table_memory_bytes(n_tan: int) -> float:
    """[B] the memory :func:`response_table` takes (at its peak) for ``n_tan`` points per axis."""
    return float(TABLE_BYTES_PER_CELL) * float(n_tan) ** 2


@dataclass(frozen=True, eq=False)
class ResponseTable:
    """A mixel's response tabulated on a (tan_x, tan_y) grid, for rendering.

    Attributes
    ----------
    tan_x, tan_y : (nx,), (ny,) ndarray
        Ascending grid of direction tangents (physical mask coordinates).
    wave, geometric, open : (ny, nx) ndarray
        Wave response (spectrally weighted), the ray model's response, and the open-aperture fraction.
    meta : dict
        How it was computed.
    """

    tan_x: np.ndarray
    tan_y: np.ndarray
    wave: np.ndarray
    geometric: np.ndarray
    open: np.ndarray
    meta: dict = field(default_factory=dict)

    def directional_weight(self, min_open: float = 1e-3) -> np.ndarray:
        """``wave / open`` where the aperture is open (>= ``min_open``), else 0.

        A ray through the aperture with direction ``t`` carries this weight instead of ``T(x_m)``: averaged
        over the detector points it is multiplied by ``open(t)``, which gives back ``wave(t)``.
        """
        return np.where(self.open >= min_open, self.wave / np.maximum(self.open, min_open), 0.0)

    def fingerprint_parts(self) -> dict:
        from mincam_sim.storage.identity import array_digest

        return {"tan_x": array_digest(self.tan_x), "tan_y": array_digest(self.tan_y),
                "wave": array_digest(self.wave), "meta": self.meta}


def response_table(
    mixel: Mixel,
    wavelengths_m: Sequence[float] = DEFAULT_WAVELENGTHS_M,
    n_tan: int | None = None,
    qe: Callable[[np.ndarray], np.ndarray] | None = silicon_qe,
    max_cells: int | None = None,
    workers: int = 2,
) -> ResponseTable:
    """Tabulate the mixel's wave response over its whole field of view (``|tan| <= half_fov_tan``).

    Parameters
    ----------
    mixel : Mixel
        The mixel (mask, ``d_f_m``, detector size).
    wavelengths_m : sequence of float
        Distinct wavelengths [m], combined with :func:`~mincam_sim.wave.spectral_weights`.
    n_tan : int, optional
        Points per axis (default: 513 for one-axis masks, whose 1D factors are solved on 129 points and
        interpolated, see ``_table_separable``; 33 for 2D masks, whose cost is one 2D propagation per point).
        Its ``n_tan**2`` arrays take about ``TABLE_BYTES_PER_CELL`` ``* n_tan**2`` bytes while it is
        built (besides the solver's own grids, ~0.25 GB for one-axis masks), at most
        ``TABLE_MEMORY_LIMIT_BYTES``: a larger ``n_tan`` is refused before any work.
    qe : callable or None
        Quantum efficiency curve for the spectral weights (``None``: band widths only).
    max_cells : int, optional
        Cap on grid cells per axis of the solver.
    workers : int
        Threads for the 2D FFTs.

    Returns
    -------
    ResponseTable

    Notes
    -----
    The renderer reads the table bilinearly: its spacing must resolve the response's angular detail (about
    ``min(detector, period) / d_f``); a 2D table is therefore only as good as its ``n_tan`` allows.
    """
    axis = separable_axis(mixel.mask)
    if n_tan is None:
        n_tan = 513 if axis is not None else 33
    if not is_finite_real(n_tan) or int(n_tan) != n_tan or n_tan < 3:
        raise InputError(f"n_tan must be an integer >= 3 points per axis, got {n_tan!r}")
    n_tan = int(n_tan)
    if table_memory_bytes(n_tan) > TABLE_MEMORY_LIMIT_BYTES:
        most = int((TABLE_MEMORY_LIMIT_BYTES / TABLE_BYTES_PER_CELL) ** 0.5)
        raise InputError(f"n_tan = {n_tan} points per axis would make a response table of about "
                         f"{table_memory_bytes(n_tan) / 2**30:.3g} GiB (at most {TABLE_MEMORY_LIMIT_BYTES / 2**30:g} "
                         f"GiB): lower n_tan to at most {most} (or leave it out: 513 for one-axis masks, 33 for 2D)")
    _check_solver_sizes(max_cells, workers)
    lam = _check_wavelengths(wavelengths_m)
    check_fresnel_number(mixel, lam)
    hx, hy = mixel.half_fov_tan()
    tx = np.linspace(-hx, hx, n_tan)
    ty = np.linspace(-hy, hy, n_tan)
    gx, gy = np.meshgrid(tx, ty)
    pts = np.column_stack([gx.ravel(), gy.ravel()])
    if axis is not None:  # one-axis masks: each axis on a few wavelength levels, interpolated
        wave, info = _table_separable(mixel, axis, tx, ty, wavelengths_m, qe, max_cells or (1 << 16))
    else:
        detail = min(mixel.detector_size_m, dot_pitch_m(mixel.mask) or np.inf) / mixel.d_f_m
        step = float(tx[1] - tx[0])
        if step > detail / 2:
            warnings.warn(
                f"mixel {mixel.name!r}: the wave table's step {step:.3g} in tan is coarser than half the "
                f"response's angular detail ({detail:.3g} = min(detector, dot pitch) / d_f); rendering reads it "
                f"bilinearly and smooths that detail away: raise n_tan to {int(np.ceil(2 * 2 * hx / detail)) + 1} "
                "(one 2D solve per direction, ~2 s each at 4096^2 cells on 2 cores)", UserWarning, stacklevel=2)
        wave, info = angular_response(mixel, pts, wavelengths_m, "wave", qe, "2d", max_cells, workers,
                                      return_info=True)
        wave = wave.reshape(gy.shape)
    geometric = geometric_response(mixel, pts).reshape(gy.shape)
    opened = open_fraction(mixel, pts).reshape(gy.shape)
    meta = {"n_tan": n_tan, "wavelengths_m": list(map(float, lam)),
            "qe": getattr(qe, "__name__", "custom") if qe is not None else None, **info.as_dict()}
    return ResponseTable(tx, ty, wave, geometric, opened, meta)


def _lagrange_basis(nodes: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Lagrange basis polynomials of ``nodes`` at ``x``: (len(nodes), len(x))."""
    out = np.ones((len(nodes), len(x)))
    for j, nj in enumerate(nodes):
        for m, nm in enumerate(nodes):
            if m != j:
                out[j] *= (x - nm) / (nj - nm)
    return out


def _table_separable(mixel, axis, tx, ty, wavelengths_m, qe, max_cells, n_solve: int = 129, levels: int = 5):
    """Product table of a one-axis mask from 1D factors solved on ``n_solve`` tangents x ``levels`` wavelengths.

    The factor along x needs the wavelength :func:`axis_wavelength` ``lambda sqrt(s)``, ``s = (1 + tx^2 + ty^2)
    / (1 + tx^2)`` in [1, 1 + max ty^2]; it is solved at ``levels`` Chebyshev points of s, interpolated in s by
    the polynomial through them and in t by a cubic spline. The smooth part of the response (the mask, its
    Talbot contrast) interpolates to < 1e-5; the coherent ripple of the far rim oscillates with wavelength
    (its phase ~ pi rho^2 / (lambda d_f) moves by 2 pi for a 0.2 % change of lambda at rho = 1 mm) and is
    smoothed by the interpolation in s: table and direct solves differ by up to ~1e-3 (tested).
    """
    from scipy.interpolate import CubicSpline

    lam = _check_wavelengths(wavelengths_m)
    weights = spectral_weights(lam, qe)
    gx, gy = np.meshgrid(tx, ty)
    total = np.zeros(gx.shape)
    info = WaveInfo("separable", lam.tolist(), weights.tolist())
    for lam_i, w_i in zip(lam, weights, strict=True):
        factors = []
        for k, (grid, other) in enumerate(((tx, ty), (ty, tx))):
            solve = np.linspace(grid[0], grid[-1], min(n_solve, len(grid)))
            s_max = 1.0 + float(np.max(other**2))
            nodes = 1.0 + (s_max - 1.0) * 0.5 * (1 - np.cos(np.pi * (np.arange(levels) + 0.5) / levels))
            sampling, amp = _axis_setup(mixel, axis, k, float(lam_i), float(np.max(np.abs(grid))), max_cells)
            tt = np.tile(solve, levels)
            ll = np.repeat(float(lam_i) * np.sqrt(nodes), len(solve))
            r = _response_1d(amp, sampling, mixel.d_f_m, mixel.detector_size_m, ll, tt).reshape(levels, len(solve))
            r_grid = CubicSpline(solve, r, axis=1)(grid) if len(solve) < len(grid) else r  # (levels, len(grid))
            t_axis, t_other = (gx, gy) if k == 0 else (gy, gx)
            s_needed = (1 + t_axis**2 + t_other**2) / (1 + t_axis**2)
            col = np.searchsorted(grid, t_axis)  # t_axis values are grid values exactly
            basis = _lagrange_basis(nodes, s_needed.ravel())  # (levels, points)
            factors.append(np.sum(basis * r_grid[:, col.ravel()], axis=0).reshape(gx.shape))
            info.dx_m.append(sampling.dx_m)
            info.cells.append(sampling.n_domain)
        total += w_i * factors[0] * factors[1]
    return total * _uniform_value(mixel.mask, axis), info
