"""How a mixel samples a video shown on a display (pure numpy): refresh, sample-and-hold, exposure, clock.

The speed experiment's road video has one mixel reading per video frame in its ideal form. A real set-up (the
paper's: a video on a screen, a camera sampling on its own clock) differs in three ways, modelled here:

* **refresh and sample-and-hold**: video frame ``j`` is published at ``j / video_rate_hz`` and shown from the
  first display refresh at or after that instant until the next frame replaces it (held, not flashed); a video
  rate that does not divide the refresh rate gives uneven hold times (judder), and a video faster than the
  refresh drops frames (each refresh shows the latest frame published; the dropped ones are held for no time);
* **exposure**: a reading integrates the displayed signal over ``exposure_s`` (the average over the exposure:
  frames that change within it blur together);
* **asynchronous sampling**: readings start at ``start_s + k / sample_rate_hz + jitter`` on the mixel's own
  clock, whose phase against the video is arbitrary and whose instants jitter (Gaussian, ``jitter_s`` rms); the
  estimator assumes the nominal, uniform ``1 / sample_rate_hz``.

The mixel's irradiance is linear in the displayed radiance, so the per-frame irradiance ``P_j`` of each video
frame (rendered once) determines every reading: a reading is the exposure-weighted mean of the ``P_j`` shown.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class DisplayTiming:
    """Display and sampling timing of a video on a screen read by a mixel.

    Attributes
    ----------
    refresh_rate_hz : float
        Display refresh rate [1/s] (frames appear only at refreshes).
    sample_rate_hz : float
        The mixel's nominal sample rate [1/s].
    exposure_s : float
        Integration time of one reading [s] (0: an instantaneous reading).
    jitter_s : float
        Rms jitter of the reading instants [s].
    start_s : float or None
        Instant of the first reading after the video starts [s]; ``None`` draws it uniformly within one
        shown frame (the clocks are not synchronised).
    """

    refresh_rate_hz: float
    sample_rate_hz: float
    exposure_s: float = 0.0
    jitter_s: float = 0.0
    start_s: float | None = None

    def __post_init__(self) -> None:
        for key in ("refresh_rate_hz", "sample_rate_hz"):
            if not (np.isfinite(getattr(self, key)) and getattr(self, key) > 0):
                raise ValueError(f"{key} must be > 0, got {getattr(self, key)!r}")
        if not 0 <= self.exposure_s <= 1 / self.sample_rate_hz:
            raise ValueError(f"exposure_s must be in [0, 1 / sample_rate_hz = {1 / self.sample_rate_hz:.4g} s], "
                             f"got {self.exposure_s!r}")
        if not (np.isfinite(self.jitter_s) and 0 <= self.jitter_s <= 1 / self.sample_rate_hz):
            raise ValueError(f"jitter_s must be in [0, 1 / sample_rate_hz = {1 / self.sample_rate_hz:.4g} s] (rms "
                             f"jitter of a reading's instant, within one reading interval), got {self.jitter_s!r}")
        if self.start_s is not None and not self.start_s >= 0:
            raise ValueError(f"start_s must be >= 0 seconds, got {self.start_s!r}")


def frame_onsets_s(n_frames: int, video_rate_hz: float, refresh_rate_hz: float) -> np.ndarray:
    """When each of ``n_frames`` video frames appears [s]: at the first refresh at or after its publication
    ``j / video_rate_hz`` (a tolerance of 1e-9 refresh periods keeps exact multiples exact); (n_frames + 1,)
    with the end of the last frame's hold appended."""
    published = np.arange(n_frames + 1) / video_rate_hz
    return np.ceil(published * refresh_rate_hz - 1e-9) / refresh_rate_hz


def sample_times_s(timing: DisplayTiming, duration_s: float, video_rate_hz: float,
                   rng: np.random.Generator) -> np.ndarray:
    """Reading start instants [s] within ``[0, duration_s - exposure_s]`` (sorted; jittered; the first at
    ``timing.start_s`` or drawn within one shown frame: a video frame, or a refresh period where the video is faster
    than the display)."""
    phase_span_s = max(1.0 / video_rate_hz, 1.0 / timing.refresh_rate_hz)  # one shown frame
    start = rng.uniform(0.0, phase_span_s) if timing.start_s is None else timing.start_s
    n = int(np.floor((duration_s - timing.exposure_s - start) * timing.sample_rate_hz - 3 * timing.jitter_s
                     * timing.sample_rate_hz)) + 1
    if n < 1:
        raise ValueError(f"a {duration_s:g} s video holds no reading at {timing.sample_rate_hz:g} samples/s")
    t = start + np.arange(n) / timing.sample_rate_hz
    if timing.jitter_s > 0:
        t = t + rng.normal(0.0, timing.jitter_s, n)
    return np.sort(np.clip(t, 0.0, duration_s - timing.exposure_s))


def displayed_readings(frame_signal: np.ndarray, video_rate_hz: float, refresh_rate_hz: float,
                       times_s: np.ndarray, exposure_s: float) -> np.ndarray:
    """Readings of a signal shown frame by frame on a sample-and-hold display.

    Parameters
    ----------
    frame_signal : (n_frames,) or (n_frames, k) ndarray
        What the mixel(s) would read from each video frame held still (e.g. irradiance [W/m^2]).
    video_rate_hz, refresh_rate_hz : float
        Video frame rate and display refresh rate [1/s].
    times_s : (m,) ndarray
        Reading start instants [s] within the video's ``n_frames / video_rate_hz`` (minus the exposure).
    exposure_s : float
        Integration time [s]; 0 gives the value displayed at each instant.

    Returns
    -------
    (m,) or (m, k) ndarray
        The mean displayed signal over ``[t, t + exposure_s]`` for each ``t``.
    """
    p = np.asarray(frame_signal, dtype=np.float64)
    t = np.asarray(times_s, dtype=np.float64)
    onsets = frame_onsets_s(len(p), video_rate_hz, refresh_rate_hz)
    if t.min() < onsets[0] or t.max() + exposure_s > onsets[-1] + 1e-12:
        raise ValueError(f"readings from {t.min():.4g} s to {t.max() + exposure_s:.4g} s fall outside the video "
                         f"({onsets[0]:.4g} to {onsets[-1]:.4g} s)")
    if exposure_s == 0:
        index = np.clip(np.searchsorted(onsets, t, side="right") - 1, 0, len(p) - 1)
        return p[index]
    flat = p.reshape(len(p), -1)
    # the displayed signal's running integral is piecewise linear with knots at the onsets: interpolation is exact
    integral = np.vstack([np.zeros((1, flat.shape[1])), np.cumsum(flat * np.diff(onsets)[:, None], axis=0)])
    out = np.column_stack([(np.interp(t + exposure_s, onsets, integral[:, c]) - np.interp(t, onsets, integral[:, c]))
                           / exposure_s for c in range(flat.shape[1])])
    return out.reshape((len(t), *p.shape[1:]))
