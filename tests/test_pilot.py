"""The pilot that sizes a run for a target relative standard error (no rendering: a model of the noise)."""

import numpy as np

from mincam_sim.render.estimation import UNSEEN_GROWTH, pilot_to_target

TARGET = 0.01


def _measure(true_values, sigma_at_one_sample):
    """Pilot measurements of ``true_values`` whose standard error falls as 1/sqrt(samples) (the mean is exact, so
    what is tested is the sizing, not the noise)."""
    calls = []

    def measure(samples):
        calls.append(samples)
        values = np.asarray(true_values, float)
        return values, np.full_like(values, sigma_at_one_sample / np.sqrt(samples))

    return measure, calls


def test_one_pilot_when_it_sees_everything():
    measure, calls = _measure([1.0, 2.0], sigma_at_one_sample=10.0)
    samples, trail = pilot_to_target(measure, 1000, TARGET, cap=1 << 30)
    # rel 0.316 at 1000 -> 1000 * 1.5 * 31.6^2 = 1.5e6: the second pilot meets the target and is the count used
    assert calls == [1000, 1_500_000] and samples == 1_500_000
    assert trail[-1]["worst_rel_stderr"] <= TARGET


def test_a_change_too_small_for_the_first_pilot_is_found_by_the_next():
    """0.05 is within 3 sigma at the first pilot's 1000 samples (sigma 0.32); sized from the large change alone,
    the run would take 1.5e6 samples and miss the target 16-fold on the small one."""
    measure, calls = _measure([1.0, 0.05], sigma_at_one_sample=10.0)
    samples, trail = pilot_to_target(measure, 1000, TARGET, cap=1 << 40)
    assert trail[0]["worst_rel_stderr"] > TARGET  # the first pilot saw the large change only ...
    small_rel = 10.0 / np.sqrt(samples) / 0.05
    assert small_rel <= TARGET  # ... the final count brings the small one to the target
    assert len(calls) == 3 and samples > 1_500_000


def test_nothing_visible_grows_then_gives_up_at_the_first_count():
    measure, calls = _measure([0.0, 0.0], sigma_at_one_sample=10.0)
    samples, trail = pilot_to_target(measure, 1000, TARGET, cap=1 << 40)
    assert calls == [1000, 1000 * UNSEEN_GROWTH, 1000 * UNSEEN_GROWTH**2]
    assert samples == 1000 and all(t["worst_rel_stderr"] is None for t in trail)


def test_the_cap_bounds_every_pilot():
    measure, calls = _measure([1.0], sigma_at_one_sample=10.0)
    samples, _ = pilot_to_target(measure, 1000, TARGET, cap=50_000)
    assert max(calls) <= 50_000 and samples == 50_000
