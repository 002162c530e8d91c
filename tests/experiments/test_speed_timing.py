"""The road video's paper-like display timing: the road measured once and looked up, the paper's one-pixel-per-frame
video on a display, and the chosen default against the paper's 7.55 / 2.85 % (within a factor of two)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from mincam_sim.errors import ConfigError
from mincam_sim.experiments import Setup
from mincam_sim.experiments.display_timing import DisplayTiming, displayed_readings, sample_times_s
from mincam_sim.experiments.speed import (
    Speed,
    SpeedParams,
    _summary,
    display_timing_study,
    displayed_signal,
    read_display_timing_study,
    road_irradiance_by_shift,
    run_display_timing_study,
    run_mask_period_study,
)
from mincam_sim.paper import SPEED_AVG_ERROR_PCT, SPEED_MAX_ERROR_PCT
from mincam_sim.render.kernels.map_tracing import ResponseMaps


def _maps(weights: np.ndarray) -> ResponseMaps:
    """Response maps of one mixel whose reading is a fixed weighted sum of the frame."""
    return ResponseMaps(weights[None], np.zeros((1, *weights.shape)), ["m"])


@pytest.mark.parametrize("shape, cols, n_shifts", [((4, 40), 8, 30), ((48, 400), 96, 300)])
def test_road_irradiance_by_shift_equals_measuring_each_crop(shape, cols, n_shifts):
    """The FFT lookup against measuring every crop alone with the maps' own sum (a road of 0-1 radiance seen
    through a sinusoid-like weight map, and a small random case)."""
    rng = np.random.default_rng(0)
    road = rng.random(shape)
    weights = rng.random((shape[0], cols)) * (1.5 + np.sin(np.arange(cols) / 3.0))
    maps = _maps(weights)
    by_shift = road_irradiance_by_shift(maps, road, cols, n_shifts)
    crops = np.stack([road[:, s : s + cols] for s in range(n_shifts)])
    np.testing.assert_allclose(by_shift, maps.measure(crops).irradiance_w_m2[:, 0], rtol=1e-13)


def test_road_irradiance_by_shift_refuses_a_road_too_short_for_its_shifts():
    maps = _maps(np.ones((4, 8)))
    with pytest.raises(ValueError, match="cannot give 30 shifts"):
        road_irradiance_by_shift(maps, np.ones((4, 36)), 8, 30)


def test_displayed_signal_with_the_ideal_shift_is_the_held_video_read_on_its_clock():
    """display_shift_px = k (0 in the config) shows the ideal video: frame i is the crop shifted by i k px."""
    position_irr = np.linspace(1.0, 2.0, 400) + 0.1 * np.sin(np.arange(400) / 3.0)
    timing = DisplayTiming(60.0, 30.0, 0.01, 0.0)
    setup = Setup(quick=True)
    got = displayed_signal(position_irr, 90.0, 3, 4.0, timing, np.random.default_rng(5), setup)
    rng = np.random.default_rng(5)
    times = sample_times_s(timing, 4.0, 30.0, rng)
    shown = displayed_readings(position_irr[:360:3, None], 30.0, 60.0, times, 0.01)
    from mincam_sim.model.readout import read_out
    expected = read_out(shown, shown.min(0), setup.sensor(), rng, setup.exposure_fill).frames_dn[:, 0]
    np.testing.assert_array_equal(got, expected)


def test_a_one_pixel_video_faster_than_the_refresh_drops_frames():
    """At 150 frames/s on a 60 Hz display the screen jumps 2 or 3 px per refresh (2.5 on average)."""
    position_irr = np.arange(2000, dtype=float)  # the reading is the crop's shift itself
    times = np.arange(0, 5.0, 1 / 60) + 1e-4  # one instantaneous reading just after every refresh
    shown = displayed_readings(position_irr[:750, None], 150.0, 60.0, times[times < 4.99], 0.0)[:, 0]
    steps = np.diff(shown)
    assert set(np.unique(steps)) == {2.0, 3.0}
    assert steps.mean() == pytest.approx(2.5, abs=0.02)


def test_a_displayed_video_needs_the_road_it_shows():
    with pytest.raises(ValueError, match="road positions"):
        displayed_signal(np.ones(100), 60.0, 1, 2.0, DisplayTiming(60.0, 30.0), np.random.default_rng(0),
                         Setup(quick=True))


@pytest.mark.parametrize(("fields", "message"), [
    ({"display_road_px": 10**6}, "display_road_px"),
    ({"display_shift_px": -1}, "display_shift_px"),
    ({"display_road_px": 64}, "fewer than 16 readings"),
    ({"video_resolution": (0, 0)}, "video_resolution must be"),
    ({"video_samples_per_texel": 0}, "video_samples_per_texel must be >= 2"),
    ({"vehicle_spp": 1}, "vehicle_spp must be >= 2"),
])
def test_bad_display_video_fields_are_refused_naming_the_field(fields, message):
    with pytest.raises(ValueError, match=message):
        SpeedParams(**fields)


def test_summary_counts_draws_within_a_factor_two_of_the_paper():
    inside = np.full(9, SPEED_AVG_ERROR_PCT)
    inside[0] = SPEED_MAX_ERROR_PCT
    outside = np.full(9, 0.5)
    summary = _summary(np.stack([inside, outside]))
    assert summary["draws_within_factor_two_of_paper"] == 0.5
    assert summary["draws_with_a_speed_off_by_over_20_pct"] == 0.0


@pytest.mark.parametrize(("shift_px", "jump_px"), [(10, 10), (1, 5)])
def test_a_reading_straddling_a_frame_change_keeps_cos_of_half_the_jump(shift_px, jump_px):
    """The 74 % failure's mechanism against its closed form: at 300 px/s a 20 ms reading that spends half its
    time on each of two shown frames reads 0.5 cos(w x) + 0.5 cos(w (x + D)) = cos(w D / 2) cos(w (x + D / 2)).
    The 30 frames/s video jumps D = 10 px per frame (the mask line keeps |cos(1.36)| = 0.21); the paper's
    one-pixel video at 300 frames/s on a 60 Hz display jumps D = 5 px per refresh (keeps 0.78)."""
    omega_px = 0.2716  # the full mode's omega_d [rad per display px]
    position = np.arange(3000, dtype=float)
    video_rate_hz = 300.0 / shift_px
    shown_period_s = max(1 / video_rate_hz, 1 / 60.0)
    times = (np.arange(200) + 1) * 2 * shown_period_s - 0.01  # each reading straddles a change at its middle
    frames = np.cos(omega_px * position[: 2500 : shift_px])[:, None]
    got = displayed_readings(frames, video_rate_hz, 60.0, times[times < 8.0], 0.02)[:, 0]
    x_before = np.round(300.0 * (times[times < 8.0] + 0.01 - shown_period_s))  # the crop shown before the change
    kept = np.cos(omega_px * jump_px / 2)
    np.testing.assert_allclose(got, kept * np.cos(omega_px * (x_before + jump_px / 2)), atol=1e-12)


def _default_display_fields(quick: bool) -> dict:
    params = Speed().params(quick)
    return {f.name: getattr(params, f.name) for f in dataclasses.fields(params) if f.name.startswith("display_")}


def test_the_default_paper_video_reads_every_speed_within_the_papers_upper_limits_quick():
    """Quick variant (3 speeds, seed 0), every timing draw: no speed off by 20 %, max and average within twice
    the paper's (the lower half of the band is not reached here: see the slow test and docs/experiments.md)."""
    (row,) = display_timing_study([_default_display_fields(quick=True)], seeds=(0,), quick=True)
    own = row["difference_in_band"]
    assert own["draws_with_a_speed_off_by_over_20_pct"] == 0
    assert own["max_error_pct_p16_p84"][1] <= 2 * SPEED_MAX_ERROR_PCT
    assert own["avg_error_pct_p16_p84"][1] <= 2 * SPEED_AVG_ERROR_PCT


@pytest.mark.slow
def test_full_mode_paper_video_removes_the_74_pct_failure_and_its_max_lands_in_the_band():
    """Full mode, seed 0, 32 draws: the old 30 frames/s video with k px jumps loses a speed (> 20 % off) in most
    draws; the paper's one-pixel video in none, its median max within a factor of two of the paper's 7.55 %."""
    paper_video = _default_display_fields(quick=False)
    old_video = {**paper_video, "display_shift_px": 0}
    new, old = display_timing_study([paper_video, old_video], seeds=(0,), quick=False)
    assert old["difference_in_band"]["draws_with_a_speed_off_by_over_20_pct"] > 0.5
    assert new["difference_in_band"]["draws_with_a_speed_off_by_over_20_pct"] == 0
    assert SPEED_MAX_ERROR_PCT / 2 <= new["difference_in_band"]["max_error_pct_median"] <= 2 * SPEED_MAX_ERROR_PCT


@pytest.mark.parametrize(("table", "message"), [
    ('display_exposur_s = 0.01', "unknown \\[speed\\] fields \\['display_exposur_s'\\]"),
    ('display_exposure_s = 0.05', "\\[points.a\\]: display timing: exposure_s must be in"),
])
def test_a_bad_study_point_is_refused_before_anything_renders(tmp_path, table, message):
    study = tmp_path / "study.toml"
    study.write_text(f'[study]\nseeds = [0]\n[points.a]\n{table}\n', encoding="utf-8")
    with pytest.raises(ConfigError, match=message):
        run_display_timing_study(study, tmp_path / "out", quick=True)


def test_the_shipped_display_timing_study_file_is_valid():
    root = Path(__file__).resolve().parents[2]
    seeds, points = read_display_timing_study(root / "scenes" / "studies" / "speed" / "display_timing.toml")
    assert len(seeds) >= 3 and any(p.get("display_shift_px") == 0 for p in points.values())


def test_the_studys_ideal_errors_are_the_experiments_ideal_row_quick(tmp_path):
    """The study's ``ideal_per_seed`` draws the ideal read-out as ``reproduce speed`` does: seed 0's entry is the
    road video's own ideal row to the last digit (quick mode, one timing draw, the default 0.2 mm mask)."""
    setup = Setup(quick=True)
    params = dataclasses.replace(Speed().params(quick=True), display_timing_draws=1)
    row = Speed().road_video(setup, params, Speed().rng(setup), tmp_path, show_progress=False)
    (study,) = display_timing_study([{"display_timing_draws": 1}], seeds=(0,), quick=True)
    assert study["ideal_per_seed"][0] == {"max_error_pct": row["max_error_pct"], "avg_error_pct": row["avg_error_pct"]}


def test_a_mask_period_study_point_without_a_period_is_refused(tmp_path):
    study = tmp_path / "study.toml"
    study.write_text('[study]\nseeds = [0]\n[points.a]\ndisplay_timing_draws = 1\n', encoding="utf-8")
    with pytest.raises(ConfigError, match="mask_period_m"):
        run_mask_period_study(study, tmp_path / "out", quick=True)


def test_the_shipped_mask_period_study_file_is_valid():
    root = Path(__file__).resolve().parents[2]
    seeds, points = read_display_timing_study(root / "scenes" / "studies" / "speed" / "mask_period.toml")
    periods = sorted(p["mask_period_m"] for p in points.values())
    assert len(seeds) >= 3 and periods[0] == Speed().params().mask_period_m and periods[-1] >= 2 * periods[0]


@pytest.mark.slow
def test_full_mode_errors_jump_with_the_mask_period_so_the_default_stays():
    """Full mode, seed 0 (``reproduce speed``'s), 32 draws, the paper-like default timing: 0.29 mm loses a speed
    (> 20 % off) on most draws, 0.30 mm on none but its average lands above twice the paper's on most, 0.31 mm
    within a factor of two on most; 0.2 mm loses none. The periods consistent with the paper are isolated points
    (docs/experiments.md), so the 0.2 mm default is kept."""
    fields = _default_display_fields(quick=False)
    rows = display_timing_study([{**fields, "mask_period_m": p} for p in (0.2e-3, 0.29e-3, 0.3e-3, 0.31e-3)],
                                seeds=(0,), quick=False)
    default, lost, above, within = (row["difference_in_band"] for row in rows)
    assert default["draws_with_a_speed_off_by_over_20_pct"] == 0
    assert lost["draws_with_a_speed_off_by_over_20_pct"] > 0.5
    assert above["draws_with_a_speed_off_by_over_20_pct"] == 0 and above["draws_within_factor_two_of_paper"] < 0.5
    assert above["avg_error_pct_median"] > 2 * SPEED_AVG_ERROR_PCT
    assert within["draws_within_factor_two_of_paper"] > 0.5


def test_a_record_too_short_for_the_mask_is_one_config_error():
    """A signal with no spectral peak in the band searched (the road video at [setup] depth_m = 20 m in quick
    mode crosses 0.28 periods of the mask; here a flat one): one ConfigError naming what to change, not the
    estimator's ValueError traceback."""
    from mincam_sim.experiments.speed import _speed

    rate_hz, omega_d, v = 30.0, 0.005, 60.0  # rad per px and px/s: 0.204 periods in 128 samples
    with pytest.raises(ConfigError, match=r"crosses 0.204 periods .* nearer \[setup\] depth_m"):
        _speed(np.ones(128), rate_hz, omega_d, v, order=1, v_max=3 * v)
