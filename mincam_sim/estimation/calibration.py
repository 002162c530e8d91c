"""Calibration of observed relative positions to true positions. Pure numpy.

The paper (Sec. 4.1.1, 4.2.1) maps the observed relative position ``x_obs`` in [0, 1] to the true position
with a 3rd-degree polynomial fitted on a calibration sweep (a white square displayed at known positions), and
extends it to 2D for tracking. Here:

* :class:`Calibration1D`: ``true_m = f(observed)``, f a polynomial of degree ``degree`` (default 3).
* :class:`Calibration2D`: ``(x_m, y_m) = (f_x(u, v), f_y(u, v))`` with full bivariate polynomials of total
  degree <= ``degree`` (10 coefficients each for degree 3), fitted by least squares.

Inputs are centred and scaled to [-1, 1] over the fitted range before building the polynomial basis (the
conditioning of the least-squares problem no longer depends on where the data lie). True positions are in
metres. Both classes save to and load from plain JSON. Applying a calibration outside the range it was fitted
on (1D: the observed interval; 2D: the convex hull of the observed points) still evaluates the polynomial but
warns once per calibration with :class:`ExtrapolationWarning`, and ``apply(..., return_extrapolated=True)``
(or ``outside_range``) returns the mask of such points. A fit that is not one-to-one over its range (1D: not
monotonic; 2D: the Jacobian determinant changes sign in the hull) warns with
:class:`NonMonotonicCalibrationWarning` (property ``monotonic``).

The paper's error rates are in :mod:`mincam_sim.estimation.metrics`.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from mincam_sim.errors import InputError
from mincam_sim.storage.atomic import atomic_write_text

_RANGE_TOLERANCE = 1e-9  # relative to the fitted range: points this close to its boundary are not flagged


class ExtrapolationWarning(UserWarning):
    """A calibration was applied outside the range of the points it was fitted on."""


class NonMonotonicCalibrationWarning(UserWarning):
    """A fitted calibration is not one-to-one over its fitted range: different observations map to one position."""


_MONOTONIC_GRID = 2001  # derivative samples over the fitted range (1D); 2D uses a 61 x 61 grid in the hull


def _finite_pairs(observed: np.ndarray, true: np.ndarray, drop_nonfinite: bool, what: str) -> tuple:
    row_axes = tuple(range(1, observed.ndim))
    ok = np.all(np.isfinite(observed), axis=row_axes) & np.all(np.isfinite(true), axis=row_axes)
    n_bad = int(np.count_nonzero(~ok))
    if n_bad:
        if not drop_nonfinite:
            raise ValueError(
                f"{what}: {n_bad} of {ok.size} calibration points have NaN/inf values (e.g. frames where no "
                "change was detected); remove them or pass drop_nonfinite=True"
            )
        warnings.warn(f"{what}: dropped {n_bad} of {ok.size} calibration points with NaN/inf", stacklevel=3)
    return observed[ok], true[ok]


def _check_enough_points(n_points: int, n_coefficients: int, degree: int, what: str) -> None:
    if n_points < n_coefficients:
        raise ValueError(
            f"{what}: {n_points} calibration points cannot determine the {n_coefficients} coefficients of a "
            f"degree-{degree} polynomial; use at least {n_coefficients} points (many more is better) "
            "or a lower degree"
        )
    if n_points == n_coefficients:
        warnings.warn(
            f"{what}: {n_points} points for {n_coefficients} coefficients: the polynomial interpolates them "
            "exactly and the rms residual (0) says nothing about the calibration error; use more points",
            stacklevel=3,
        )


def _lstsq(basis: np.ndarray, targets: np.ndarray, what: str) -> tuple[np.ndarray, float]:
    coefficients, _, rank, _ = np.linalg.lstsq(basis, targets, rcond=None)
    if rank < basis.shape[1]:
        raise ValueError(
            f"{what}: the calibration points do not determine all {basis.shape[1]} coefficients "
            f"(rank {rank}); spread the calibration positions over the range (2D: not all on one line) or "
            "lower the degree"
        )
    residual = targets - basis @ coefficients
    return coefficients, float(np.sqrt(np.mean(residual**2)))


def _warn_extrapolation(calibration: Calibration1D | Calibration2D, n_outside: int, n_total: int) -> None:
    if n_outside and not calibration._warned_extrapolation:
        calibration._warned_extrapolation = True
        warnings.warn(
            f"{type(calibration).__name__}.apply: {n_outside} of {n_total} points lie outside the fitted "
            "range and are extrapolated (this warning is shown once per calibration; use "
            "return_extrapolated=True for the mask)",
            ExtrapolationWarning,
            stacklevel=3,
        )


def _write_json(path: str | Path, payload: dict[str, Any]) -> None:
    atomic_write_text(path, json.dumps(payload, indent=2) + "\n")


def _read_json(path: str | Path, kind: str) -> dict[str, Any]:
    try:
        payload = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise InputError(f"{path}: cannot read a {kind} JSON file ({err}); give a file written by "
                         f"{kind}.to_json") from None
    if not isinstance(payload, dict) or payload.get("kind") != kind:
        got = payload.get("kind") if isinstance(payload, dict) else type(payload).__name__
        raise InputError(f"{path}: expected a JSON file with kind={kind!r}, got kind={got!r}")
    return payload


def _checked_payload(payload: Any, kind: str, keys: tuple[str, ...]) -> dict[str, Any]:
    """``payload`` when it is a mapping holding ``keys``; otherwise one InputError naming what is missing."""
    if not isinstance(payload, dict):
        raise InputError(f"{kind}.from_dict needs a dict (from to_dict), got {type(payload).__name__}")
    missing = [k for k in keys if k not in payload]
    if missing:
        raise InputError(f"{kind} data lacks {', '.join(missing)}: give what {kind}.to_dict / to_json wrote")
    return payload


def _checked_calibration_numbers(kind: str, degree: Any, n_coefficients: int, expected: int,
                                 ranges: np.ndarray, values: np.ndarray) -> None:
    """Refuse (InputError) a loaded calibration whose degree, coefficient count, fitted range or numbers cannot
    be those of a fit: it would evaluate to nonsense (a zero-width range divides by zero)."""
    if isinstance(degree, bool) or not isinstance(degree, int) or degree < 0:
        raise InputError(f"{kind} data: degree must be an integer >= 0, got {degree!r}")
    if n_coefficients != expected:
        raise InputError(f"{kind} data: a degree-{degree} calibration has {expected} coefficients, got "
                         f"{n_coefficients}")
    if not (np.all(np.isfinite(values)) and np.all(np.isfinite(ranges)) and np.all(ranges[..., 1] > ranges[..., 0])):
        raise InputError(f"{kind} data: coefficients must be finite and each fitted range (min, max) must have "
                         f"min < max, got ranges {ranges.tolist()}")


# ------------------------------------------------------------------------------------------------ 1D
@dataclass
class Calibration1D:
    """Polynomial map from observed relative position to true position [m].

    ``true_m = sum_k coefficients[k] * u**k`` with ``u = (observed - centre) / half_width`` and
    ``centre``, ``half_width`` the midpoint and half-width of ``fit_range``.

    Attributes
    ----------
    degree : int
    coefficients : numpy.ndarray, shape (degree + 1,)
        Power-basis coefficients in the scaled variable ``u`` [m], lowest order first.
    fit_range : (float, float)
        Smallest and largest observed value used in the fit.
    rms_residual_m : float
        Root-mean-square residual of the fit [m].
    n_points : int
    metadata : dict
        Free-form JSON-serialisable information (units, set-up, date...).
    """

    degree: int
    coefficients: np.ndarray
    fit_range: tuple[float, float]
    rms_residual_m: float
    n_points: int
    metadata: dict = field(default_factory=dict)
    _warned_extrapolation: bool = field(default=False, repr=False, compare=False)

    @classmethod
    def fit(
        cls,
        observed: ArrayLike,
        true_m: ArrayLike,
        degree: int = 3,
        metadata: dict | None = None,
        drop_nonfinite: bool = False,
    ) -> Calibration1D:
        """Least-squares fit of ``true_m = f(observed)``.

        Parameters
        ----------
        observed : array_like, shape (n,)
            Observed relative positions (e.g. :func:`mincam_sim.estimation.estimators.intrusion_position`).
        true_m : array_like, shape (n,)
            True positions [m].
        degree : int
            Polynomial degree (the paper uses 3); needs ``n >= degree + 1`` distinct points.
        metadata : dict, optional
            Stored as is (must be JSON-serialisable to save).
        drop_nonfinite : bool
            Drop points with NaN/inf (with a warning) instead of raising.
        """
        if isinstance(degree, bool) or not isinstance(degree, int | np.integer) or degree < 0:
            raise ValueError(f"degree must be an integer >= 0, got {degree!r}")
        obs = np.asarray(observed, dtype=np.float64)
        true = np.asarray(true_m, dtype=np.float64)
        if obs.ndim != 1 or obs.shape != true.shape:
            raise ValueError(
                f"Calibration1D.fit: observed and true_m must be 1D arrays of equal length, got shapes "
                f"{obs.shape} and {true.shape}"
            )
        obs, true = _finite_pairs(obs, true, drop_nonfinite, "Calibration1D.fit")
        _check_enough_points(obs.size, degree + 1, degree, "Calibration1D.fit")
        lo, hi = float(obs.min()), float(obs.max())
        if not hi > lo:
            raise ValueError("Calibration1D.fit: all observed values are equal; a calibration needs a spread")
        metadata = dict(metadata or {})
        calibration = cls(int(degree), np.zeros(degree + 1), (lo, hi), 0.0, int(obs.size), metadata)
        basis = np.vander(calibration._scaled(obs), degree + 1, increasing=True)
        coefficients, rms = _lstsq(basis, true, "Calibration1D.fit")
        calibration.coefficients = coefficients
        calibration.rms_residual_m = rms
        if not calibration.monotonic:
            warnings.warn(
                f"Calibration1D.fit: the degree-{degree} polynomial is not monotonic over the fitted range "
                f"[{lo:.6g}, {hi:.6g}], so different observations map to the same position; the calibration "
                "points are too noisy or too few for this degree, or the observed position folds (check "
                "`monotonic` before trusting it)",
                NonMonotonicCalibrationWarning,
                stacklevel=2,
            )
        return calibration

    @property
    def monotonic(self) -> bool:
        """True if the polynomial is strictly monotonic over ``fit_range`` (its derivative keeps one sign on a
        fine grid; a degree-0 map is not)."""
        derivative = np.polynomial.polynomial.polyder(np.asarray(self.coefficients, dtype=np.float64))
        slope = np.polynomial.polynomial.polyval(np.linspace(-1.0, 1.0, _MONOTONIC_GRID), derivative)
        return bool(np.all(slope > 0) or np.all(slope < 0))

    def outside_range(self, observed: ArrayLike) -> np.ndarray:
        """Boolean mask of finite ``observed`` values outside ``fit_range`` (what :meth:`apply` extrapolates);
        no warning."""
        with np.errstate(invalid="ignore"):
            u = self._scaled(np.asarray(observed, dtype=np.float64))
            return np.isfinite(u) & (np.abs(u) > 1.0 + _RANGE_TOLERANCE)

    def _scaled(self, observed: np.ndarray) -> np.ndarray:
        lo, hi = self.fit_range
        return (observed - 0.5 * (lo + hi)) / (0.5 * (hi - lo))

    def apply(
        self, observed: ArrayLike, return_extrapolated: bool = False
    ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Predicted true position [m] (same shape as ``observed``; NaN in gives NaN out).

        With ``return_extrapolated=True`` returns ``(predicted_m, extrapolated)``, the boolean mask of finite
        inputs outside ``fit_range``. Extrapolation also warns once per calibration.
        """
        obs = np.asarray(observed, dtype=np.float64)
        u = self._scaled(obs)
        predicted = np.polynomial.polynomial.polyval(u, np.asarray(self.coefficients, dtype=np.float64))
        extrapolated = self.outside_range(obs)
        _warn_extrapolation(self, int(np.count_nonzero(extrapolated)), int(obs.size))
        return (predicted, extrapolated) if return_extrapolated else predicted

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-serialisable representation."""
        return {
            "kind": "Calibration1D",
            "degree": self.degree,
            "basis": "powers of u = (observed - centre) / half_width over fit_range, lowest order first",
            "coefficients": [float(c) for c in self.coefficients],
            "fit_range": [float(v) for v in self.fit_range],
            "rms_residual_m": float(self.rms_residual_m),
            "n_points": int(self.n_points),
            "units": {"observed": "relative (dimensionless)", "true": "m"},
            "metadata": self.metadata,
        }

    @classmethod
    def from_dict(cls, payload: dict[str, Any]) -> Calibration1D:
        """Inverse of :meth:`to_dict`; data that cannot be a fit's (missing keys, a coefficient count that is not
        ``degree + 1``, an empty or non-finite range) is an InputError."""
        payload = _checked_payload(payload, "Calibration1D",
                                   ("degree", "coefficients", "fit_range", "rms_residual_m", "n_points"))
        try:
            coefficients = np.asarray(payload["coefficients"], dtype=np.float64).reshape(-1)
            fit_range = np.asarray(payload["fit_range"], dtype=np.float64).reshape(2)
            rms, n_points = float(payload["rms_residual_m"]), int(payload["n_points"])
        except (TypeError, ValueError) as err:
            raise InputError(f"Calibration1D data: coefficients must be numbers, fit_range two numbers, "
                             f"rms_residual_m a number and n_points an integer ({err})") from None
        degree = payload["degree"]
        _checked_calibration_numbers("Calibration1D", degree, coefficients.size,
                                     degree + 1 if isinstance(degree, int) else -1, fit_range, coefficients)
        return cls(degree, coefficients, (float(fit_range[0]), float(fit_range[1])), rms, n_points,
                   dict(payload.get("metadata", {})))

    def to_json(self, path: str | Path) -> None:
        """Write :meth:`to_dict` to ``path`` (floats round-trip exactly)."""
        _write_json(path, self.to_dict())

    @classmethod
    def from_json(cls, path: str | Path) -> Calibration1D:
        """Load a calibration written by :meth:`to_json`."""
        return cls.from_dict(_read_json(path, "Calibration1D"))


# ------------------------------------------------------------------------------------------------ 2D
def bivariate_exponents(degree: int) -> list[tuple[int, int]]:
    """Exponents ``(i, j)`` of the monomials ``u**i v**j`` with ``i + j <= degree``, total degree first."""
    return [(total - j, j) for total in range(degree + 1) for j in range(total + 1)]


def _cross(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _convex_hull(points: np.ndarray) -> np.ndarray:
    """Counter-clockwise convex hull vertices of 2D points (Andrew's monotone chain)."""
    pts = np.unique(points, axis=0)
    if len(pts) < 3:
        return pts

    def half(sequence: np.ndarray) -> list[np.ndarray]:
        chain: list[np.ndarray] = []
        for p in sequence:
            while len(chain) >= 2 and _cross(chain[-1] - chain[-2], p - chain[-2]) <= 0:
                chain.pop()
            chain.append(p)
        return chain

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def _outside_hull(points: np.ndarray, hull: np.ndarray, tolerance: float) -> np.ndarray:
    """True for points farther than ``tolerance`` outside the convex polygon ``hull`` (counter-clockwise)."""
    edges = np.roll(hull, -1, axis=0) - hull
    lengths = np.linalg.norm(edges, axis=1)
    rel = points[:, np.newaxis, :] - hull[np.newaxis, :, :]
    signed_distance = (edges[:, 0] * rel[..., 1] - edges[:, 1] * rel[..., 0]) / lengths  # > 0 inside
    return np.any(signed_distance < -tolerance, axis=1)


@dataclass
class Calibration2D:
    """Bivariate polynomial map from observed relative ``(x, y)`` to true ``(x_m, y_m)``.

    ``true[:, c] = sum_k coefficients[k, c] * u**i_k * v**j_k`` with ``(i_k, j_k) = exponents[k]`` and ``u``,
    ``v`` the observed coordinates centred and scaled to [-1, 1] over the fitted bounding box.

    Attributes
    ----------
    degree : int
        Total degree of the polynomials.
    exponents : list of (int, int)
    coefficients : numpy.ndarray, shape (n_terms, 2)
        Coefficients [m] for the true x (column 0) and y (column 1).
    fit_box : numpy.ndarray, shape (2, 2)
        ``[[x_min, x_max], [y_min, y_max]]`` of the observed points (used for scaling).
    fit_hull : numpy.ndarray, shape (n_vertices, 2)
        Convex hull of the observed points; outside it ``apply`` flags extrapolation.
    rms_residual_m : numpy.ndarray, shape (2,)
        Root-mean-square residual of x and y [m].
    n_points : int
    metadata : dict
    """

    degree: int
    exponents: list[tuple[int, int]]
    coefficients: np.ndarray
    fit_box: np.ndarray
    fit_hull: np.ndarray
    rms_residual_m: np.ndarray
    n_points: int
    metadata: dict = field(default_factory=dict)
    _warned_extrapolation: bool = field(default=False, repr=False, compare=False)

    @classmethod
    def fit(
        cls,
        obs_xy: ArrayLike,
        true_xy_m: ArrayLike,
        degree: int = 3,
        metadata: dict | None = None,
        drop_nonfinite: bool = False,
    ) -> Calibration2D:
        """Least-squares fit of ``true_xy_m = f(obs_xy)``.

        Parameters
        ----------
        obs_xy : array_like, shape (n, 2)
            Observed relative positions (e.g. :func:`mincam_sim.estimation.estimators.track_4`).
        true_xy_m : array_like, shape (n, 2)
            True positions [m].
        degree : int
            Total degree (default 3: 10 coefficients per coordinate, so at least 10 points, not all on a conic
            or line; a grid of 4 x 4 or more is advisable).
        metadata : dict, optional
        drop_nonfinite : bool
            Drop points with NaN/inf (with a warning) instead of raising.
        """
        if isinstance(degree, bool) or not isinstance(degree, int | np.integer) or degree < 0:
            raise ValueError(f"degree must be an integer >= 0, got {degree!r}")
        obs = np.asarray(obs_xy, dtype=np.float64)
        true = np.asarray(true_xy_m, dtype=np.float64)
        if obs.ndim != 2 or obs.shape[1] != 2 or obs.shape != true.shape:
            raise ValueError(
                f"Calibration2D.fit: obs_xy and true_xy_m must both have shape (n, 2), got {obs.shape} and {true.shape}"
            )
        obs, true = _finite_pairs(obs, true, drop_nonfinite, "Calibration2D.fit")
        exponents = bivariate_exponents(int(degree))
        _check_enough_points(len(obs), len(exponents), degree, "Calibration2D.fit")
        box = np.stack([obs.min(axis=0), obs.max(axis=0)], axis=1)
        if np.any(box[:, 1] <= box[:, 0]):
            raise ValueError("Calibration2D.fit: observed x or y values are all equal; spread the points")
        calibration = cls(
            int(degree),
            exponents,
            np.zeros((len(exponents), 2)),
            box,
            _convex_hull(obs),
            np.zeros(2),
            len(obs),
            dict(metadata or {}),
        )
        basis = calibration._basis(obs)
        coefficients, _ = _lstsq(basis, true, "Calibration2D.fit")
        calibration.coefficients = coefficients
        calibration.rms_residual_m = np.sqrt(np.mean((true - basis @ coefficients) ** 2, axis=0))
        if not calibration.monotonic:
            warnings.warn(
                "Calibration2D.fit: the fitted map folds over inside the convex hull of the calibration points "
                "(its Jacobian determinant changes sign), so different observations map to the same position; "
                "the points are too noisy or too few for this degree (check `monotonic` before trusting it)",
                NonMonotonicCalibrationWarning,
                stacklevel=2,
            )
        return calibration

    def jacobian_determinant(self, obs_xy: ArrayLike) -> np.ndarray:
        """``det d(x_m, y_m) / d(obs_x, obs_y)`` at the given observed points [m^2 per unit^2], shape (n,)."""
        obs = np.atleast_2d(np.asarray(obs_xy, dtype=np.float64))
        uv = self._scaled(obs)
        half_width = 0.5 * (self.fit_box[:, 1] - self.fit_box[:, 0])
        du = np.zeros((len(obs), 2))
        dv = np.zeros((len(obs), 2))
        for k, (i, j) in enumerate(self.exponents):
            if i:
                du += np.outer(i * uv[:, 0] ** (i - 1) * uv[:, 1] ** j, self.coefficients[k])
            if j:
                dv += np.outer(j * uv[:, 0] ** i * uv[:, 1] ** (j - 1), self.coefficients[k])
        du /= half_width[0]
        dv /= half_width[1]
        return du[:, 0] * dv[:, 1] - dv[:, 0] * du[:, 1]

    @property
    def monotonic(self) -> bool:
        """True if the map is one-to-one in the small everywhere in the fitted hull: its Jacobian determinant
        keeps one sign on a 61 x 61 grid of the fitted box clipped to the hull (and at the hull's vertices)."""
        grid = np.linspace(0.0, 1.0, 61)
        gu, gv = np.meshgrid(grid, grid)
        lo, span = self.fit_box[:, 0], self.fit_box[:, 1] - self.fit_box[:, 0]
        points = np.column_stack([lo[0] + gu.ravel() * span[0], lo[1] + gv.ravel() * span[1]])
        if len(self.fit_hull) >= 3:
            points = points[~_outside_hull(points, self.fit_hull, 0.0)]
        det = self.jacobian_determinant(np.vstack([points, self.fit_hull]))
        return bool(np.all(det > 0) or np.all(det < 0))

    def outside_range(self, obs_xy: ArrayLike) -> np.ndarray:
        """Boolean mask (n,) of finite points outside the convex hull of the calibration points (what
        :meth:`apply` extrapolates); no warning."""
        obs2 = np.atleast_2d(np.asarray(obs_xy, dtype=np.float64))
        finite = np.all(np.isfinite(obs2), axis=1)
        extrapolated = np.zeros(len(obs2), dtype=bool)
        if np.any(finite):
            tolerance = _RANGE_TOLERANCE * float(np.max(self.fit_box[:, 1] - self.fit_box[:, 0]))
            extrapolated[finite] = _outside_hull(obs2[finite], self.fit_hull, tolerance)
        return extrapolated

    def _scaled(self, obs: np.ndarray) -> np.ndarray:
        centre = self.fit_box.mean(axis=1)
        half_width = 0.5 * (self.fit_box[:, 1] - self.fit_box[:, 0])
        return (obs - centre) / half_width

    def _basis(self, obs: np.ndarray) -> np.ndarray:
        uv = self._scaled(obs)
        return np.stack([uv[:, 0] ** i * uv[:, 1] ** j for i, j in self.exponents], axis=1)

    def apply(self, obs_xy: ArrayLike, return_extrapolated: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Predicted true positions [m], shape ``(n, 2)`` (a single ``(2,)`` point gives ``(2,)``).

        Rows with NaN give NaN. With ``return_extrapolated=True`` returns ``(predicted_m, extrapolated)``, the
        mask of finite points outside the convex hull of the calibration points (also warned once).
        """
        obs = np.asarray(obs_xy, dtype=np.float64)
        single = obs.ndim == 1
        obs2 = np.atleast_2d(obs)
        if obs2.ndim != 2 or obs2.shape[1] != 2:
            raise ValueError(f"Calibration2D.apply: obs_xy must have shape (n, 2) or (2,), got {obs.shape}")
        predicted = self._basis(obs2) @ self.coefficients
        extrapolated = self.outside_range(obs2)
        _warn_extrapolation(self, int(np.count_nonzero(extrapolated)), len(obs2))
        if single:
            predicted, extrapolated = predicted[0], extrapolated[0]
        return (predicted, extrapolated) if return_extrapolated else predicted

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-serialisable representation."""
        return {
            "kind": "Calibration2D",
            "degree": self.degree,
            "basis": "monomials u**i * v**j (exponents), u, v = observed x, y scaled to [-1, 1] over fit_box",
            "exponents": [list(e) for e in self.exponents],
            "coefficients_x": [float(c) for c in self.coefficients[:, 0]],
            "coefficients_y": [float(c) for c in self.coefficients[:, 1]],
            "fit_box": self.fit_box.tolist(),
            "fit_hull": self.fit_hull.tolist(),
            "rms_residual_m": [float(r) for r in self.rms_residual_m],
            "n_points": int(self.n_points),
            "units": {"observed": "relative (dimensionless)", "true": "m"},
            "metadata": self.metadata,
        }

    @classmethod
    def from_dict(cls, payload: dict[str, Any]) -> Calibration2D:
        """Inverse of :meth:`to_dict`; data that cannot be a fit's (missing keys, exponents that are not those of
        ``degree``, coefficient counts that differ, an empty or non-finite box) is an InputError."""
        payload = _checked_payload(payload, "Calibration2D",
                                   ("degree", "exponents", "coefficients_x", "coefficients_y", "fit_box",
                                    "fit_hull", "rms_residual_m", "n_points"))
        degree = payload["degree"]
        try:
            exponents = [(int(i), int(j)) for i, j in payload["exponents"]]
            cx = np.asarray(payload["coefficients_x"], dtype=np.float64).reshape(-1)
            cy = np.asarray(payload["coefficients_y"], dtype=np.float64).reshape(-1)
            box = np.asarray(payload["fit_box"], dtype=np.float64).reshape(2, 2)
            hull = np.asarray(payload["fit_hull"], dtype=np.float64).reshape(-1, 2)
            rms = np.asarray(payload["rms_residual_m"], dtype=np.float64).reshape(2)
            n_points = int(payload["n_points"])
        except (TypeError, ValueError) as err:
            raise InputError(f"Calibration2D data: exponents must be (i, j) pairs, coefficients numbers, fit_box "
                             f"2 x 2, fit_hull (x, y) points, rms_residual_m two numbers ({err})") from None
        expected = bivariate_exponents(degree) if isinstance(degree, int) and not isinstance(degree, bool) else None
        _checked_calibration_numbers("Calibration2D", degree, cx.size if cx.size == cy.size else -1,
                                     len(expected) if expected is not None else -2, box, np.concatenate([cx, cy]))
        if exponents != expected:
            raise InputError(f"Calibration2D data: exponents must be those of degree {degree}, {expected}, got "
                             f"{exponents}")
        if len(hull) < 3 or not np.all(np.isfinite(hull)):
            raise InputError(f"Calibration2D data: fit_hull must be at least 3 finite (x, y) points, got {len(hull)}")
        return cls(degree, exponents, np.stack([cx, cy], axis=1), box, hull, rms, n_points,
                   dict(payload.get("metadata", {})))

    def to_json(self, path: str | Path) -> None:
        """Write :meth:`to_dict` to ``path`` (floats round-trip exactly)."""
        _write_json(path, self.to_dict())

    @classmethod
    def from_json(cls, path: str | Path) -> Calibration2D:
        """Load a calibration written by :meth:`to_json`."""
        return cls.from_dict(_read_json(path, "Calibration2D"))
