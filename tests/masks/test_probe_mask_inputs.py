"""Masks and films refuse wrong types, huge sizes and impossible frequencies with one InputError naming the
argument, where they raised numpy's TypeError, a MemoryError or sampled nonsense."""

from __future__ import annotations

import numpy as np
import pytest

import mincam_sim as ms
from mincam_sim.errors import InputError

M = ms.masks


@pytest.mark.parametrize("make, words", [
    (lambda: M.ramp("x", (4,)), "resolution must be a positive integer or a pair"),
    (lambda: M.ramp("x", 100_000), "too large"),
    (lambda: M.constant("0.5"), "constant mask transmission must be a number"),
    (lambda: M.constant(True), "constant mask transmission must be a number"),
    (lambda: M.sinusoid("1000"), "omega_rad_per_m must be a frequency"),
    (lambda: M.sinusoid(1e30, resolution=4), "omega_rad_per_m must be a frequency"),
    (lambda: M.sinusoid(1000.0, a0="0.5"), "sinusoid a0 must be a finite number"),
    (lambda: M.sinusoid(1000.0, a1=float("nan")), "sinusoid a1 must be a finite number"),
    (lambda: M.PrintedFilm(t_min="0.1"), "t_min"),
    (lambda: M.PrintedFilm(levels=float("nan")), "levels must be an integer"),
    (lambda: M.PrintedFilm(levels=float("inf")), "levels must be an integer"),
    (lambda: M.PrintedFilm(dpi="600"), "dpi must be a positive number"),
    (lambda: M.PrintedFilm(dpi=True), "dpi must be a positive number"),
    (lambda: M.PrintedFilm(gamma="1"), "gamma must be positive"),
])
def test_one_input_error(make, words):
    """Before: ValueError (unpack), MemoryError (74.5 GiB), TypeError (isfinite on str), a 1-dpi film from True,
    an aliased picture of a 6e-30 m period, ValueError/OverflowError from int(nan/inf)."""
    with pytest.raises(InputError, match=words):
        make()


def test_sinusoid_at_the_frequency_limit_still_samples_its_mean():
    """The largest accepted frequency (a 63 nm period) is a valid profile whose area mean is a0."""
    m = M.sinusoid(M.mask.MAX_SINUSOID_OMEGA_RAD_PER_M, resolution=(3, 5), width_m=1e-3)
    assert m.shape == (3, 5) and np.all((0 <= m.transmission) & (m.transmission <= 1))


def test_odd_and_one_texel_masks_keep_their_mean_when_resampled_and_printed():
    """Invariants on odd sizes: area resampling keeps the mean exactly; a print keeps t_min + (t_max - t_min) v."""
    rng = np.random.default_rng(0)
    m = M.Mask(rng.random((5, 2)), width_m=3e-3, height_m=1e-3)
    for shape in ((3, 7), (7, 3), (1, 1)):
        assert M.resample(m, shape).mean() == pytest.approx(m.transmission.mean(), rel=1e-12)
    film = M.PrintedFilm(levels=None)
    one = film.print(M.constant(0.3, 1))
    np.testing.assert_allclose(one.transmission, 0.02 + 0.88 * 0.3, rtol=1e-12)


def test_unreadable_mask_files_are_input_errors(tmp_path):
    """``masks.load`` promises InputError for a non-image file or a directory; both were a plain ValueError."""
    bad = tmp_path / "f.png"
    bad.write_bytes(b"not a png")
    with pytest.raises(InputError, match="is not an image this package reads"):
        M.load(bad, width_m=2e-3)
    with pytest.raises(InputError, match="is not a regular file"):
        M.load(tmp_path, width_m=2e-3)


def test_a_value_just_above_one_is_shown_as_it_is():
    """1 + 1e-7 was reported as spanning [1, 1], a range that looks allowed."""
    with pytest.raises(InputError, match=r"spans \[1\.0000001, 1\.0000001\]"):
        M.Mask(np.full((2, 2), 1.0000001))
