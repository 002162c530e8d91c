"""Wave optics (mincam_sim.wave): what a caller gives is refused up front with one InputError naming the argument
and the fix (wavelengths against each other and against the QE model, the render table's size), before any solve
or large allocation."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from mincam_sim import masks, wave
from mincam_sim.errors import InputError
from mincam_sim.model.optics import Mixel
from mincam_sim.wave import geometric, table


@pytest.fixture(scope="module")
def ramp_mixel() -> Mixel:
    return Mixel(masks.ramp("x"))


def test_repeated_wavelengths_are_named_not_blamed_on_the_qe(ramp_mixel):
    """``(550e-9, 550e-9)`` was refused as "the QE curve gives no weight to these wavelengths"; a repeat among
    others was merged silently. Either is one error naming the repeated value and the fix."""
    for lams in ((550e-9, 550e-9), (500e-9, 550e-9, 600e-9, 550e-9)):
        with pytest.raises(InputError, match=r"wavelengths_m repeats 5\.5e-07 m: give each wavelength once"):
            wave.angular_response(ramp_mixel, [[0.1, 0.0]], wavelengths_m=lams)
        with pytest.raises(InputError, match="repeats"):
            wave.spectral_weights(lams, qe=None)
        with pytest.raises(InputError, match="repeats"):
            wave.response_table(ramp_mixel, lams, n_tan=5)


def test_a_wavelength_outside_the_qe_model_is_refused_alone_as_with_others(ramp_mixel):
    """Two wavelengths outside 400-1100 nm were refused by silicon_qe, one alone was weighted 1 silently; both
    now give the same error naming the range, the value and the fix (``qe=None`` or a measured curve)."""
    assert wave.QE_RANGE_M == (400e-9, 1100e-9)
    wave.silicon_qe(np.array(wave.QE_RANGE_M))  # both ends are covered
    for lams, said in (((1200e-9,), "1.2e-06"), ((300e-9,), "3e-07"), ((500e-9, 1200e-9), "1.2e-06"),
                       ((300e-9, 1200e-9), "3e-07, 1.2e-06")):
        match = rf"wavelengths_m {said} m lie outside the silicon QE model's range \[4e-07, 1\.1e-06\] m.*qe=None"
        with pytest.raises(InputError, match=match):
            wave.spectral_weights(lams)
        with pytest.raises(InputError, match=match):
            wave.angular_response(ramp_mixel, [[0.1, 0.0]], wavelengths_m=lams)
    with pytest.raises(InputError, match=r"silicon_qe: wavelength_m must lie in .* got 1\.2e-06 m"):
        wave.silicon_qe(1200e-9)
    # without the QE model any wavelength is taken, alone or not
    assert wave.spectral_weights([1200e-9], qe=None).tolist() == [1.0]
    r = wave.angular_response(ramp_mixel, [[0.1, 0.0]], wavelengths_m=(1200e-9,), qe=None)
    assert abs(r[0] - 0.6) < 0.01
    # a custom curve that is zero at the one wavelength given is refused as it is for several
    with pytest.raises(InputError, match="gives no weight to wavelengths_m"):
        wave.spectral_weights([550e-9], qe=lambda lam: np.zeros_like(lam))


def test_wavelengths_that_are_not_numbers_are_one_input_error():
    for given in (["a"], "550e-9", [], [[550e-9]]):
        with pytest.raises(InputError, match="wavelengths_m must be a non-empty list"):
            wave.spectral_weights(given)


def test_response_table_refuses_a_table_too_large_for_memory_before_allocating(ramp_mixel):
    """``n_tan=1e9`` tried to allocate 7.45 GiB for its first axis (numpy's MemoryError); the table's
    memory is now estimated from ``n_tan`` and refused above :data:`TABLE_MEMORY_LIMIT_BYTES`."""
    assert wave.TABLE_MEMORY_LIMIT_BYTES == 8 * 2**30
    most = int((table.TABLE_MEMORY_LIMIT_BYTES / table.TABLE_BYTES_PER_CELL) ** 0.5)
    assert table.table_memory_bytes(most) <= table.TABLE_MEMORY_LIMIT_BYTES < table.table_memory_bytes(most + 1)
    for n_tan in (10**6, 1e9, most + 1):
        with pytest.raises(InputError, match=rf"n_tan = {int(n_tan)} points per axis .* GiB \(at most 8 GiB\): "
                                             rf"lower n_tan to at most {most}"):
            wave.response_table(ramp_mixel, n_tan=n_tan)


@pytest.mark.parametrize("n_tan", [float("nan"), float("inf"), 2.5, 2, 0, -3, "33", True, [5]])
def test_response_table_n_tan_must_be_an_integer_of_at_least_3(ramp_mixel, n_tan):
    """``n_tan=nan`` was "cannot convert float NaN to integer" (a bare ValueError)."""
    with pytest.raises(InputError, match="n_tan must be an integer >= 3 points per axis"):
        wave.response_table(ramp_mixel, n_tan=n_tan)


def test_response_table_checks_the_solver_sizes_of_one_axis_masks(ramp_mixel):
    """``max_cells`` and ``workers`` were checked by the 2D path only; a one-axis mask's table took any."""
    with pytest.raises(InputError, match="max_cells must be None"):
        wave.response_table(ramp_mixel, n_tan=5, max_cells=3)
    with pytest.raises(InputError, match="workers must be an integer >= 1"):
        wave.response_table(ramp_mixel, n_tan=5, workers=0)


def test_geometric_quadrature_of_many_directions_holds_a_block_at_a_time(ramp_mixel, monkeypatch):
    """The one-axis quadrature held ~200 nodes x 5 arrays per direction at once (1.2 KB x 1000 per table cell,
    2.4 GB for the default 513^2 table): it is now computed in blocks, with the same answer."""
    rng = np.random.default_rng(0)
    tan = rng.uniform(-0.6, 0.6, (40_000, 2))
    tracemalloc.start()
    try:
        whole = wave.geometric_response(ramp_mixel, tan)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 120e6, f"{peak / 1e6:.0f} MB"  # ~300 MB when every direction's nodes were held at once
    monkeypatch.setattr(geometric, "QUADRATURE_CHUNK_POINTS", 7)
    np.testing.assert_allclose(wave.geometric_response(ramp_mixel, tan[:50]), whole[:50], rtol=0, atol=1e-15)


def test_repeated_wavelengths_are_refused_where_the_mixel_or_the_file_names_them():
    """A mixel or a display file with a wavelength twice was taken and failed only when the wave table was built."""
    import mincam_sim as ms
    from mincam_sim.configuration.config import load_config
    from mincam_sim.errors import ConfigError

    with pytest.raises(InputError, match=r"mixel 'w': wavelengths_m repeats 5\.5e-07 m: give each wavelength once"):
        ms.Mixel(ms.masks.ramp("x"), name="w", optics="wave", wavelengths_m=(550e-9, 600e-9, 550e-9))
    with pytest.raises(ConfigError, match=r"\[mincam\] wavelengths_m repeats 5\.5e-07 m"):
        load_config("[mincam]\noptics = \"wave\"\nwavelengths_m = [550e-9, 550e-9]\n")
