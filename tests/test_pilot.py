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


def test_a_missed_target_is_a_warning_not_silence(monkeypatch):
    """Response maps at their sample cap: the reached noise is above the target, and the run says so."""
    import pytest

    from mincam_sim.optics import pair_layout
    from mincam_sim.render import screen_engine
    from mincam_sim.render.estimation import TargetNotReachedWarning
    from mincam_sim.scene.display import Screen

    monkeypatch.setattr(screen_engine, "MAX_SAMPLES_PER_TEXEL", 64)
    screen = Screen(resolution=(32, 18))
    frame = np.zeros((1, 18, 32))
    frame[0, 8:10, 15:17] = 1.0
    with pytest.warns(TargetNotReachedWarning, match="cap of 64 samples"):
        m, _ = screen_engine.render_frames(pair_layout(), screen, frame, target_rel_stderr=1e-6)
    assert m.meta["reached_rel_stderr"] > 1e-6 and m.meta["samples_per_texel"] == 64


def test_render_frames_passes_replicates_to_the_response_maps():
    from mincam_sim.optics import pair_layout
    from mincam_sim.render.screen_engine import render_frames
    from mincam_sim.scene.display import Screen

    screen = Screen(resolution=(16, 9))
    frame = np.ones((1, 9, 16))
    default, _ = render_frames(pair_layout(), screen, frame, samples_per_texel=64)
    sixteen, _ = render_frames(pair_layout(), screen, frame, samples_per_texel=64, replicates=16)
    assert default.meta["replicate_blocks"] == 4 and sixteen.meta["replicate_blocks"] == 16


def test_the_response_map_search_always_moves_on(monkeypatch):
    """Samples per texel are traced as replicates x k^2: doubling 16 (k = 2) rounds back to 16, and the search
    for a target just out of reach used to repeat that attempt forever. Each step now adds a stratum."""
    from mincam_sim.optics import pair_layout
    from mincam_sim.render import screen_engine
    from mincam_sim.scene.display import Screen

    screen = Screen(resolution=(32, 18))
    frame = np.zeros((1, 18, 32))
    frame[0, 8:10, 15:17] = 1.0
    first, _ = screen_engine.render_frames(pair_layout(), screen, frame, samples_per_texel=16)
    target = 0.97 * first.meta["reached_rel_stderr"]  # need ~1.06 x 16 samples: 2 x 16 would round to 16
    m, _ = screen_engine.render_frames(pair_layout(), screen, frame, target_rel_stderr=target)
    traced = [t["samples_per_texel"] for t in m.meta["budget_trail"]]
    assert traced[0] == 16 and bool(np.all(np.diff(traced) > 0))
    assert m.meta["reached_rel_stderr"] <= target


def test_a_store_of_other_replicates_is_not_reused(tmp_path):
    """256 samples per texel are 4 blocks of 8^2 or 16 blocks of 4^2: different maps, different numbers, so a
    store written with one is refused for the other."""
    import pytest

    from mincam_sim.errors import StoreError
    from mincam_sim.optics import pair_layout
    from mincam_sim.render.screen_engine import render_frames
    from mincam_sim.scene.display import Screen

    screen = Screen(resolution=(16, 9))
    frame = np.ones((1, 9, 16))
    render_frames(pair_layout(), screen, frame, samples_per_texel=256, replicates=4, out_dir=tmp_path)
    with pytest.raises(StoreError, match="replicates"):
        render_frames(pair_layout(), screen, frame, samples_per_texel=256, replicates=16, out_dir=tmp_path)
