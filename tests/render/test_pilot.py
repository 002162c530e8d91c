"""The pilot that sizes a run for a target relative standard error (no rendering: a model of the noise)."""

import numpy as np

from mincam_sim.render.kernels.monte_carlo import TARGET_MARGIN, UNSEEN_GROWTH, pilot_to_target

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


def test_a_missed_target_is_a_warning_not_silence(monkeypatch):
    """Response maps at their sample cap: the reached noise is above the target, and the run says so."""
    import pytest

    from mincam_sim.model.optics import pair_layout
    from mincam_sim.render.kernels.monte_carlo import TargetNotReachedWarning
    from mincam_sim.render.solvers import response_map
    from mincam_sim.scene.display import Screen

    monkeypatch.setattr(response_map, "MAX_SAMPLES_PER_TEXEL", 64)
    screen = Screen(resolution=(32, 18))
    frame = np.zeros((1, 18, 32))
    frame[0, 8:10, 15:17] = 1.0
    with pytest.warns(TargetNotReachedWarning, match="cap of 64 samples"):
        m = _map_measure(pair_layout(), screen, frame, target_rel_stderr=1e-6)
    assert m.meta["reached_rel_stderr"] > 1e-6 and m.meta["samples_per_texel"] == 64


def _map_measure(mincam, screen, frames, **budget):
    import mincam_sim as ms

    return ms.Simulation(mincam, screen=screen).measure(frames, ms.ResponseMap(), ms.Budget(**budget))


def test_the_budgets_replicates_reach_the_response_maps():
    from mincam_sim.model.optics import pair_layout
    from mincam_sim.scene.display import Screen

    screen = Screen(resolution=(16, 9))
    frame = np.ones((1, 9, 16))
    default = _map_measure(pair_layout(), screen, frame, samples_per_texel=64)
    sixteen = _map_measure(pair_layout(), screen, frame, samples_per_texel=64, replicates=16)
    assert default.meta["replicate_blocks"] == 4 and sixteen.meta["replicate_blocks"] == 16


def test_the_response_map_search_always_moves_on(monkeypatch):
    """Samples per texel are traced as replicates x k^2: doubling 16 (k = 2) rounds back to 16, and the search
    for a target just out of reach used to repeat that attempt forever. Each step now adds a stratum."""
    from mincam_sim.model.optics import pair_layout
    from mincam_sim.scene.display import Screen

    screen = Screen(resolution=(32, 18))
    frame = np.zeros((1, 18, 32))
    frame[0, 8:10, 15:17] = 1.0
    first = _map_measure(pair_layout(), screen, frame, samples_per_texel=16)
    target = 0.97 * first.meta["reached_rel_stderr"]  # need ~1.06 x 16 samples: 2 x 16 would round to 16
    m = _map_measure(pair_layout(), screen, frame, target_rel_stderr=target)
    traced = [t["samples_per_texel"] for t in m.meta["budget_trail"]]
    assert traced[0] == 16 and bool(np.all(np.diff(traced) > 0))
    assert m.meta["reached_rel_stderr"] <= target


def test_a_store_of_other_replicates_is_not_reused(tmp_path):
    """256 samples per texel are 4 blocks of 8^2 or 16 blocks of 4^2: different maps, different numbers, so a
    store written with one is refused for the other."""
    import pytest

    import mincam_sim as ms
    from mincam_sim.errors import StoreError
    from mincam_sim.model.optics import pair_layout
    from mincam_sim.scene.display import Screen

    screen = Screen(resolution=(16, 9))
    frame = np.ones((1, 9, 16))
    sim = ms.Simulation(pair_layout(), screen=screen)
    with ms.Run(tmp_path) as run:
        run.measure(sim, frame, ms.ResponseMap(), ms.Budget(samples_per_texel=256, replicates=4))
    with ms.Run(tmp_path) as run, pytest.raises(StoreError, match="replicates"):
        run.measure(sim, frame, ms.ResponseMap(), ms.Budget(samples_per_texel=256, replicates=16))


def _stratified(true_values, rel_at_one_sample, exponent):
    """Pilots of an estimator whose relative error falls as samples^-exponent (a stratified one: exponent 1)."""
    calls = []

    def measure(samples):
        calls.append(samples)
        values = np.asarray(true_values, float)
        return values, values * rel_at_one_sample * samples**-exponent

    return measure, calls


def _squares(replicates, cap):
    """``replicates x k^2``, one k more at least, at most the cap's k (as the response maps' search)."""
    top = int(np.sqrt(cap / replicates))

    def quantize(wanted, samples):
        k = min(top, max(int(round(np.sqrt(samples / replicates))) + 1, int(np.sqrt(wanted / replicates))))
        return max(samples, replicates * k * k)

    return quantize


def test_a_quantised_search_measures_its_rate_and_steps_within_bounds():
    """Counts traced as 4 k^2, each step 2x to 8x the last, the convergence rate measured on the last two
    pilots: a stratified estimator (rel ~ 1/n) reaches the target with fewer samples than the plain rule's
    n^-1/2 extrapolation asks for, and every pilot count is one that was traced."""
    kw = dict(significance=0.0, rounds=None, growth=(2, 8), unseen_growth=1, quantize=_squares(4, 1 << 20))
    measure, calls = _stratified([1.0, 3.0], 10.0, 1.0)
    samples, trail = pilot_to_target(measure, 16, 1e-3, 1 << 20, measured_exponent=(0.5, 1.5), **kw)
    assert trail[-1]["worst_rel_stderr"] <= 1e-3 and samples == calls[-1] == trail[-1]["samples"]
    assert all(c % 4 == 0 and np.sqrt(c // 4) % 1 == 0 for c in calls)
    ratios = np.diff(calls) / np.array(calls[:-1]) + 1
    assert np.all(ratios >= 2) and np.all(ratios <= 8)
    plain_measure, plain_calls = _stratified([1.0, 3.0], 10.0, 1.0)
    plain, _ = pilot_to_target(plain_measure, 16, 1e-3, 1 << 20, **kw)  # exponent 0.5 throughout
    # rel = 10 / n: the target needs 10,000 samples; the measured rate asks for them times the margin, the
    # plain rule for more (and both reach the target)
    assert 10_000 <= samples <= TARGET_MARGIN * 10_000 < plain


def test_a_quantised_search_ends_on_a_traced_count():
    """At the cap, and when nothing is significant (``unseen_growth=1``), the search returns the last count it
    traced: the result is that pilot itself (e.g. cached maps), never an untraced extrapolation."""
    kw = dict(significance=0.0, rounds=None, growth=(2, 8), unseen_growth=1, quantize=_squares(4, 1000),
              measured_exponent=(0.5, 1.5))
    measure, calls = _stratified([1.0], 10.0, 1.0)
    samples, trail = pilot_to_target(measure, 16, 1e-9, 1000, **kw)
    assert samples == calls[-1] == 4 * 15**2 and trail[-1]["worst_rel_stderr"] > 1e-9
    measure, calls = _stratified([0.0], 10.0, 1.0)
    samples, trail = pilot_to_target(measure, 16, 1e-3, 1000, **kw)
    assert calls == [16] and samples == 16 and trail[0]["worst_rel_stderr"] is None


def test_the_response_map_search_traces_stratum_steps():
    """The maps' search (the same rule): every attempt is replicates x k^2 samples per texel, more each step,
    and its last maps reach the target."""
    import mincam_sim as ms
    from mincam_sim.model.optics import pair_layout
    from mincam_sim.render.solvers.response_map import maps_to_target
    from mincam_sim.scene.display import Screen

    screen = Screen(resolution=(32, 18))
    frame = np.zeros((1, 18, 32))
    frame[0, 8:10, 15:17] = 1.0
    maps, trail = maps_to_target(ms.Simulation(pair_layout(), screen=screen), frame, 4e-4, seed=1)
    traced = [t["samples_per_texel"] for t in trail]
    assert len(traced) >= 3 and traced[0] == 16 and bool(np.all(np.diff(traced) > 0))
    assert all(np.sqrt(n / 4) % 1 == 0 for n in traced) and maps.meta["samples_per_texel"] == traced[-1]
    m = maps.measure(frame)
    assert np.max(m.stderr_w_m2 / m.irradiance_w_m2) <= 4e-4 and trail[-1]["worst_rel_stderr"] <= 4e-4
