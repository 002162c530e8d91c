"""The Monte Carlo rules every form shares: one seed rule, one replicate / standard-error path, one budget policy.

* Seeds: :func:`derive_seed` turns the user's seed and a *purpose* (``"fast"``, ``"reference"``, ``"response"``,
  ``"pilot"`` ...) into the seed of one kernel launch; the same inputs always give the same seed, different
  purposes never share random numbers by accident.
* Standard errors: every value is the mean of ``R >= 2`` independent replicate estimates;
  :func:`replicate_mean_stderr` returns the mean and ``std(ddof=1) / sqrt(R)``.
* Budgets: :func:`samples_for_target` extrapolates a pilot's sample count to a target relative standard error,
  with one margin and one cap for all forms; :func:`pilot_to_target` runs the pilots (the ray forms, and with
  a measured rate and quantised counts the response maps' search).
"""

from __future__ import annotations

import functools
import itertools
import math
import warnings
import zlib
from collections.abc import Callable

import numpy as np

from mincam_sim.measurements import Measurements

TARGET_MARGIN = 1.5  # samples beyond the extrapolated need: a pilot's noise estimate (few replicates) is itself noisy


def derive_seed(*parts: int | str) -> int:
    """A 31-bit seed derived deterministically from ``parts`` (same inputs, same seed)."""
    return zlib.crc32(repr(parts).encode()) & 0x7FFFFFFF


def replicate_mean_stderr(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard error over axis 0 (independent replicates, at least 2)."""
    samples = np.asarray(samples, dtype=np.float64)
    r = samples.shape[0]
    if r < 2:
        raise ValueError("a standard error needs at least 2 independent replicates")
    return samples.mean(axis=0), samples.std(axis=0, ddof=1) / np.sqrt(r)


def check_counts(samples: int, replicates: int, what: str = "spp (samples per mixel per frame)") -> None:
    """Raise a clear ``ValueError`` unless both are valid integers (samples >= 1, replicates >= 2)."""
    if isinstance(samples, bool) or int(samples) != samples or samples <= 0:
        raise ValueError(f"{what} must be a positive integer, got {samples!r}")
    if isinstance(replicates, bool) or int(replicates) != replicates or replicates < 2:
        raise ValueError(f"replicates must be an integer >= 2 (needed for a standard error), got {replicates!r}")


def worst_relative_stderr(values: np.ndarray, stderr: np.ndarray, significance: float = 0.0) -> float:
    """Largest ``stderr / |value|`` over values that are non-zero (and > ``significance`` sigma, if given).

    NaN when no value qualifies (e.g. nothing was seen), so that callers never mistake it for "exact".
    """
    values, stderr = np.asarray(values, float), np.asarray(stderr, float)
    live = np.abs(values) > 0
    if significance > 0:
        live &= np.abs(values) > significance * stderr
    if not live.any():
        return float("nan")
    return float(np.max(stderr[live] / np.abs(values[live])))


def samples_for_target(pilot_samples: int, pilot_rel: float, target_rel: float, cap: int,
                       exponent: float = 0.5) -> int:
    """Samples needed to bring ``pilot_rel`` (measured with ``pilot_samples``) down to ``target_rel``.

    ``rel ~ samples^-exponent`` (0.5 for plain Monte Carlo; stratified estimators converge faster), times
    :data:`TARGET_MARGIN`, at least the pilot and at most ``cap``. An unmeasurable pilot (NaN, 0) keeps the
    pilot's count.
    """
    if not (np.isfinite(pilot_rel) and pilot_rel > 0):
        return int(pilot_samples)
    need = pilot_samples * TARGET_MARGIN * (pilot_rel / target_rel) ** (1.0 / exponent)
    return int(min(cap, max(pilot_samples, np.ceil(need))))


PILOT_ROUNDS = 3  # pilots at most, each at the count the previous one extrapolated
UNSEEN_GROWTH = 16  # samples x this when a pilot measured no change significantly (nothing to extrapolate from)


def pilot_to_target(measure, pilot_samples: int, target_rel: float, cap: int, significance: float = 3.0,
                    rounds: int | None = PILOT_ROUNDS, *, exponent: float = 0.5,
                    measured_exponent: tuple[float, float] | None = None,
                    growth: tuple[float, float] = (1, math.inf), unseen_growth: int = UNSEEN_GROWTH,
                    quantize: Callable[[float, int], int] | None = None) -> tuple[int, list[dict]]:
    """Samples with which the pilot measurements reach ``target_rel``, and the trail of pilots.

    ``measure(samples)`` returns ``(values, stderr)`` of the pilot frames. A value within ``significance``
    sigma of zero has no measurable relative error, so one pilot can miss a small change that, measured with
    more samples, turns out to be the worst: each later pilot runs at the count the previous one
    extrapolated (:func:`samples_for_target`; ``unseen_growth`` times more when nothing was significant),
    until a pilot meets the target itself (then that count is used, and the pilot frames are known to meet it:
    same seed, same numbers) or ``rounds`` pilots have run (then the last extrapolation, or the first count if
    no pilot measured any change: a change that stays invisible is not worth more samples).

    The keywords fit the rule to estimators whose counts are quantised and converge faster than plain Monte
    Carlo (response maps: ``replicates x k^2`` samples per texel, stratified); their defaults are the ray forms'.

    Parameters
    ----------
    rounds : int or None
        Most pilots; ``None``: until the target or the cap (every pilot's result is then the final result
        candidate, e.g. cached maps).
    exponent : float
        ``rel ~ samples^-exponent`` of the extrapolation (until measured).
    measured_exponent : (float, float), optional
        Measure the exponent on the last two pilots (when both have a relative error and the later one more
        samples), clipped to these bounds; it stays at the last measured value otherwise.
    growth : (float, float)
        The next pilot has at least ``growth[0]`` and at most ``growth[1]`` times the samples of the last one
        (and at most ``cap``).
    unseen_growth : int
        Factor of the next pilot when nothing was significant (1: stop there).
    quantize : callable, optional
        ``quantize(wanted, samples)``: the count actually traced for ``wanted`` after a pilot of ``samples``;
        it must exceed ``samples`` unless the cap allows nothing more (the search ends there).
    """
    samples, trail, extrapolated = int(pilot_samples), [], int(pilot_samples)
    rate = exponent
    for _ in range(rounds) if rounds is not None else itertools.count():
        worst = worst_relative_stderr(*measure(samples), significance=significance)
        trail.append({"samples": samples, "worst_rel_stderr": worst if np.isfinite(worst) else None})
        if np.isfinite(worst):
            if worst <= target_rel:
                return samples, trail
            if measured_exponent is not None:
                rate = _measured_exponent(trail, rate, measured_exponent)
            wanted = samples_for_target(samples, worst, target_rel, cap, rate)
            wanted = min(cap, max(growth[0] * samples, min(wanted, growth[1] * samples)))
            following = extrapolated = int(quantize(wanted, samples) if quantize is not None else wanted)
        else:
            following = min(cap, samples * unseen_growth)
        if following <= samples:
            break
        samples = following
    return extrapolated, trail


def _measured_exponent(trail: list[dict], previous: float, bounds: tuple[float, float]) -> float:
    """``a`` of ``rel ~ samples^-a`` through the last two pilots of ``trail``, clipped to ``bounds``; ``previous``
    when fewer than two pilots measured a relative error, or the later one has no more samples."""
    if len(trail) < 2:
        return previous
    (n_a, r_a), (n_b, r_b) = ((t["samples"], t["worst_rel_stderr"]) for t in trail[-2:])
    if r_a is None or r_b is None or not (r_a > 0 and r_b > 0 and n_b > n_a):
        return previous
    return float(np.clip(np.log(r_a / r_b) / np.log(n_b / n_a), *bounds))


def warn_unreached(m: Measurements) -> None:
    """Warn when a mixel's value is 0 with standard error 0: no sample reached anything bright, which is not
    a measurement of exactly zero (and its relative error is undefined)."""
    dark = (m.irradiance_w_m2 == 0) & (m.stderr_w_m2 == 0)
    if dark.any():
        frames = np.flatnonzero(dark.any(axis=1))
        names = [n for k, n in enumerate(m.mixel_names) if dark[:, k].any()]
        warnings.warn(
            f"no sample of mixel(s) {', '.join(names)} reached a lit part of the scene in {len(frames)} frame(s) "
            f"(first: {frames[0]}): 0 +/- 0 W/m^2 there means 'not seen', not a certain zero; check that the "
            "frames show something inside the mixels' fields of view, or raise the samples",
            UnseenWarning, stacklevel=3)


class TargetNotReachedWarning(UserWarning):
    """A run that asked for a relative standard error and did not reach it everywhere."""


def warn_target_missed(reached: float, target: float, samples: int, cap: int, why: str | None = None) -> None:
    """Warn when the worst relative standard error ``reached`` is above a requested ``target`` (> 0); ``why``
    the target was missed, if the caller knows better than the pilot / cap rule."""
    if target > 0 and not np.isfinite(reached):
        warnings.warn(f"no measurement was significantly non-zero (> 3 sigma) with {samples} samples, so the "
                      f"target relative standard error {target:.3g} could not be checked; raise the samples if the "
                      "frames should change what the mixels see", TargetNotReachedWarning, stacklevel=3)
    elif target > 0 and reached > target:
        if why is None:
            why = f"the cap of {cap} samples" if samples >= cap else "pilots that did not show the worst measurement"
        warnings.warn(f"reached a worst relative standard error of {reached:.3g} > target {target:.3g} with "
                      f"{samples} samples (limited by {why}): the values are unbiased, only noisier than asked; "
                      "see meta['reached_rel_stderr']", TargetNotReachedWarning, stacklevel=3)


class UnseenWarning(UserWarning):
    """A measurement that no Monte Carlo sample reached."""


class UncertainSigmaWarning(UserWarning):
    """Standard errors estimated from few degrees of freedom: their z-scores have heavier tails than the ray
    solvers' 8 replicates give."""


@functools.lru_cache(maxsize=256)
def dominance_threshold(replicates: int, false_alarm: float = 1e-4) -> float:
    """Share of the replicates' squared deviations that one of ``replicates`` Gaussian replicates exceeds with
    probability at most ``false_alarm``; above it one replicate dominates.

    For ``n`` Gaussian replicates, one replicate's share ``(x_i - mean)^2 / sum_j (x_j - mean)^2`` is
    ``(n - 1) / n`` times a Beta(1/2, (n - 2) / 2) variable, so the largest of the ``n`` exceeds ``t`` with
    probability at most ``n`` times one's (Bonferroni; equal where ``t`` >= 1/2, as two shares cannot both pass
    a half): the threshold is that share's upper ``false_alarm / n`` quantile. Exact in closed form, for any
    count (an independent Monte Carlo quantile checks it in the tests)."""
    from scipy import stats

    n = int(replicates)
    if n < 3:
        raise ValueError(f"replicates must be >= 3 for a dominance threshold, not {n}")
    return float((n - 1) / n * stats.beta.isf(false_alarm / n, 0.5, (n - 2) / 2))


def heavy_tailed(replicates: np.ndarray) -> np.ndarray:
    """Per column of ``replicates`` (R, n): True where one replicate holds more of the squared deviations than
    Gaussian replicates would but once in 10^4 (:func:`dominance_threshold`): a rare heavy path decides the
    estimate, and its standard error is itself uncertain. Never True for R < 3."""
    x = np.asarray(replicates, dtype=np.float64)
    if x.shape[0] < 3:
        return np.zeros(x.shape[1:], dtype=bool)
    dev2 = (x - x.mean(axis=0)) ** 2
    total = dev2.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(total > 0, dev2.max(axis=0) / total, 0.0)
    return share > dominance_threshold(x.shape[0])
