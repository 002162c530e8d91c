"""The paper's error rates (pure numpy).

The position error is ``|predicted - true|`` as a percentage of the calibrated range (paper Sec. 4.1.1,
4.2.1). In 2D the paper does not say how it combined the axes, so two normalisations are offered:
``"euclidean"`` (the distance per frame, one error per frame) and ``"per_axis"`` (``|dx|`` and ``|dy|`` each
a sample, two per frame: a frame's mean of them lies between 1/2 and 1/sqrt(2) of its distance, their
maximum never above it). The speed error is ``|predicted - true|`` as a percentage of the true speed
(Sec. 4.3.1). Every summary has the maximum, the 95th percentile, the mean and the rms. Rows with a NaN/inf
prediction but a ground truth (frames without a detection) are counted as missed (``n_missing``,
``missing_pct``), not scored; rows without a ground truth are counted apart (``n_without_truth``). The paper
does not say how it treated missed frames; report the two together.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

NORMALISATIONS = ("euclidean", "per_axis")


def _error_summary(errors_pct: np.ndarray, truth_ok: np.ndarray) -> dict[str, float | int]:
    """Summary of per-row errors [%] (n,) or per-row, per-axis errors (n, k); ``truth_ok`` marks the rows that
    have a finite ground truth. A row counts when all its errors are finite."""
    finite = np.isfinite(errors_pct) if errors_pct.ndim == 1 else np.all(np.isfinite(errors_pct), axis=1)
    valid = errors_pct[finite].ravel()
    if valid.size == 0:
        raise ValueError(
            f"no finite predictions to evaluate: {int(np.count_nonzero(truth_ok))} rows with a ground truth, all "
            "predicted NaN/inf (e.g. no detection)" if errors_pct.size else "no rows to evaluate (empty input)"
        )
    n_missing = int(np.count_nonzero(truth_ok & ~finite))
    return {
        "max_error_pct": float(valid.max()),
        "avg_error_pct": float(valid.mean()),
        "p95_error_pct": float(np.percentile(valid, 95)),
        "rms_error_pct": float(np.sqrt(np.mean(valid**2))),
        "n": int(np.count_nonzero(finite)),
        "n_missing": n_missing,
        "n_without_truth": int(np.count_nonzero(~truth_ok)),
        "missing_pct": 100.0 * n_missing / max(1, int(np.count_nonzero(truth_ok))),
    }


def error_rates(predicted: ArrayLike, truth: ArrayLike, calibrated_range: float,
                normalisation: str = "euclidean") -> dict[str, float | int | str]:
    """Position error rates as defined in the paper: ``|predicted - truth|`` as % of the calibrated range.

    Parameters
    ----------
    predicted, truth : array_like, shape (n,) or (n, k)
        Predicted and true positions in the same unit as ``calibrated_range`` (metres in this package); for
        (n, k) arrays the error is the Euclidean distance per row.
    calibrated_range : float
        Length of the calibrated range (e.g. 0.5 for the paper's 50 cm boundary or field of view).
    normalisation : {"euclidean", "per_axis"}
        For (n, k) arrays: one error per row, the Euclidean distance (default), or k errors per row, the
        absolute difference on each axis (pooled: the maximum, percentile and mean run over all n k of them).
        Identical for 1D input.

    Returns
    -------
    dict
        ``max_error_pct``, ``p95_error_pct`` (95th percentile, linear interpolation), ``avg_error_pct``,
        ``rms_error_pct`` over the ``n`` rows where both are finite; ``normalisation`` as given;
        ``n_missing``: rows with a finite truth but a NaN/inf prediction (missed: no detection or no position),
        excluded from the averages and counted here; ``missing_pct``: their share of the rows with a truth [%];
        ``n_without_truth``: rows whose truth is NaN/inf (nothing to score, whatever was predicted).
    """
    pred = np.asarray(predicted, dtype=np.float64)
    true = np.asarray(truth, dtype=np.float64)
    if pred.shape != true.shape or pred.ndim not in (1, 2):
        raise ValueError(f"predicted and truth need equal shape (n,) or (n, k), got {pred.shape}, {true.shape}")
    if not np.isfinite(calibrated_range) or calibrated_range <= 0:
        raise ValueError(f"calibrated_range must be a finite length > 0, got {calibrated_range!r}")
    if normalisation not in NORMALISATIONS:
        raise ValueError(f"normalisation must be one of {NORMALISATIONS}, got {normalisation!r}")
    if pred.ndim == 1 or normalisation == "per_axis":
        error = np.abs(pred - true)
    else:
        error = np.sqrt(np.sum((pred - true) ** 2, axis=1))
    truth_ok = np.isfinite(true) if true.ndim == 1 else np.all(np.isfinite(true), axis=1)
    return {**_error_summary(100.0 * error / calibrated_range, truth_ok), "normalisation": normalisation}


def speed_error_rates(pred_v: ArrayLike, true_v: ArrayLike) -> dict[str, float | int]:
    """Speed error rates: ``|pred_v - true_v| / |true_v|`` in %, summarised as in :func:`error_rates`."""
    pred = np.asarray(pred_v, dtype=np.float64)
    true = np.asarray(true_v, dtype=np.float64)
    if pred.shape != true.shape or pred.ndim != 1:
        raise ValueError(f"pred_v and true_v must be 1D arrays of one length, got {pred.shape}, {true.shape}")
    if np.any(true == 0):
        raise ValueError("true_v contains zero speeds: a percentage of the true speed is undefined there")
    with np.errstate(invalid="ignore"):
        errors = 100.0 * np.abs(pred - true) / np.abs(true)
    return _error_summary(errors, np.isfinite(true))
