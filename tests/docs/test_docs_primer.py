"""The radiometry primer's worked example (docs/primer.md): every number on the page is recomputed with the
package's own functions and checked against hand arithmetic written out here, independently of the package.

Two checks per value: the page shows what the package computes (to the digits printed), and the package
computes what the hand arithmetic gives (the physics). Pure numpy, < 1 s.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from mincam_sim import Screen
from mincam_sim.model.sensor import SensorModel
from mincam_sim.oracles.closed_forms import open_aperture_irradiance, point_to_parallel_rect

PRIMER = Path(__file__).resolve().parents[2] / "docs" / "primer.md"

# The worked example's inputs, as the page states them.
RADIANCE_W_M2_SR = 1.0
MASK_SIDE_M = 2e-3
D_F_M = 2e-3
DETECTOR_SIDE_M = 1e-4
SCREEN_DISTANCE_M = 0.5
EXPOSURE_S = 1e-3
PIXELS = 48 * 48

# Hand arithmetic: constants typed in, not imported.
H_J_S = 6.62607015e-34
C_M_S = 299792458.0
LAMBDA_M = 550e-9
QE = 0.6
DARK_E_PER_S = 5.0
READ_NOISE_E = 2.5
FULL_WELL_E = 10_000.0
MAX_DN = 2**12 - 1


def _page_values() -> dict[str, float]:
    """``step label -> value`` from the worked-example table of docs/primer.md."""
    text = PRIMER.read_text(encoding="utf-8")
    start = text.index("| step | computed by | value | unit |")
    values = {}
    for line in text[start:].splitlines()[2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        values[cells[0]] = float(cells[2])
    return values


def _package_values() -> dict[str, float]:
    screen = Screen()
    assert screen.pose.position_m[2] == -SCREEN_DISTANCE_M  # the page's "default screen 0.5 m away"
    half_w, half_h = screen.width_m / 2, screen.height_m / 2
    half = MASK_SIDE_M / 2
    f_point = float(point_to_parallel_rect(-half, half, -half, half, D_F_M))
    e_mean = open_aperture_irradiance(RADIANCE_W_M2_SR, DETECTOR_SIDE_M, MASK_SIDE_M, MASK_SIDE_M, D_F_M,
                                      (-half_w, half_w, -half_h, half_h), SCREEN_DISTANCE_M)
    sensor = SensorModel.paper_prototype(exposure_s=EXPOSURE_S)
    power_w = e_mean * DETECTOR_SIDE_M**2
    return {
        "radiance L": RADIANCE_W_M2_SR,
        "view factor F, on-axis point": f_point,
        "irradiance πLF, on-axis point": math.pi * RADIANCE_W_M2_SR * f_point,
        "irradiance averaged over the detector": e_mean,
        "power on the detector": power_w,
        "photon energy at 550 nm": sensor.photon_energy_j,
        "photons per second on the detector": power_w / sensor.photon_energy_j,
        "photons per pixel per exposure": float(sensor.photons(e_mean)),
        "electrons per pixel per exposure": float(sensor.electrons(e_mean)),
        "conversion gain": sensor.gain,
        "mixel value": float(sensor.expected(e_mean)),
        "temporal noise of the mixel value": float(sensor.expected_std_dn(e_mean)),
        "slope of the read-out": sensor.dn_per_irradiance,
    }


def _hand_values() -> dict[str, float]:
    """The same chain by hand: Howell's square-aperture formula, then E A t / (h c / lambda) ..."""
    x = (MASK_SIDE_M / 2) / D_F_M
    s = x / math.sqrt(1 + x * x)
    f_point = 4 / math.pi * s * math.atan(s)
    e_point = math.pi * RADIANCE_W_M2_SR * f_point
    photon_j = H_J_S * C_M_S / LAMBDA_M
    pixel_area_m2 = DETECTOR_SIDE_M**2 / PIXELS
    gain = FULL_WELL_E / MAX_DN
    # The detector average is not a closed form; it is bracketed below (test_detector_average_bracket), and
    # the chain from E on is checked exactly at the package's E.
    return {"view factor F, on-axis point": f_point, "irradiance πLF, on-axis point": e_point,
            "photon energy at 550 nm": photon_j, "conversion gain": gain, "pixel_area_m2": pixel_area_m2}


def _chain_by_hand(e_w_m2: float) -> dict[str, float]:
    hand = _hand_values()
    photon_j = hand["photon energy at 550 nm"]
    photons = e_w_m2 * hand["pixel_area_m2"] * EXPOSURE_S / photon_j
    electrons = QE * photons + DARK_E_PER_S * EXPOSURE_S
    gain = hand["conversion gain"]
    return {
        "power on the detector": e_w_m2 * DETECTOR_SIDE_M**2,
        "photons per second on the detector": e_w_m2 * DETECTOR_SIDE_M**2 / photon_j,
        "photons per pixel per exposure": photons,
        "electrons per pixel per exposure": electrons,
        "mixel value": electrons / gain,
        "temporal noise of the mixel value": math.sqrt(
            (electrons + READ_NOISE_E**2) / PIXELS / gain**2 + 1 / (12 * PIXELS)),
        "slope of the read-out": hand["pixel_area_m2"] * EXPOSURE_S / photon_j * QE / gain,
    }


def _printed_digits(label: str) -> int:
    text = PRIMER.read_text(encoding="utf-8")
    row = next(line for line in text.splitlines() if line.startswith(f"| {label} |"))
    number = row.strip().strip("|").split("|")[2].strip()
    mantissa = re.sub(r"e[+-]?\d+$", "", number).replace(".", "").lstrip("0")
    return max(len(mantissa), 1)


def test_page_has_every_step():
    assert set(_page_values()) == set(_package_values())


@pytest.mark.parametrize("label", list(_package_values()))
def test_page_shows_what_the_package_computes(label):
    """Each number on the page equals the package's value to the digits printed (half a unit of the last)."""
    page, package = _page_values()[label], _package_values()[label]
    digits = _printed_digits(label)
    assert page == pytest.approx(package, rel=0.5 * 10.0 ** (1 - digits) + 1e-12), (
        f"primer row {label!r}: page {page}, package {package:.8g}")


def test_package_matches_hand_arithmetic():
    package, hand = _package_values(), _hand_values()
    for label in ("view factor F, on-axis point", "irradiance πLF, on-axis point", "photon energy at 550 nm",
                  "conversion gain"):
        assert package[label] == pytest.approx(hand[label], rel=1e-12), label
    for label, value in _chain_by_hand(package["irradiance averaged over the detector"]).items():
        assert package[label] == pytest.approx(value, rel=1e-12), label


def test_detector_average_bracket():
    """The detector-averaged irradiance lies below the on-axis value (every other point sees the aperture
    obliquely) and above the value at the detector's corner, from the same hand formula shifted off axis."""
    e_axis = _hand_values()["irradiance πLF, on-axis point"]

    def at(dx: float, dy: float) -> float:  # four corner rectangles of Howell's case B-3, by hand
        def corner(a: float, b: float) -> float:
            sa, sb = math.sqrt(1 + a * a), math.sqrt(1 + b * b)
            return (a / sa * math.atan(b / sa) + b / sb * math.atan(a / sb)) / (2 * math.pi)

        h = MASK_SIDE_M / 2
        x0, x1, y0, y1 = ((-h - dx) / D_F_M, (h - dx) / D_F_M, (-h - dy) / D_F_M, (h - dy) / D_F_M)
        f = corner(x1, y1) - corner(x0, y1) - corner(x1, y0) + corner(x0, y0)
        return math.pi * RADIANCE_W_M2_SR * f

    e_corner = at(DETECTOR_SIDE_M / 2, DETECTOR_SIDE_M / 2)
    e_mean = _package_values()["irradiance averaged over the detector"]
    assert at(0.0, 0.0) == pytest.approx(e_axis, rel=1e-12)
    assert e_corner < e_mean < e_axis
    # and the average of the hand formula over a fine midpoint grid of the detector agrees with the package
    n = 64
    offsets = (np.arange(n) + 0.5) / n * DETECTOR_SIDE_M - DETECTOR_SIDE_M / 2
    grid_mean = float(np.mean([[at(dx, dy) for dx in offsets] for dy in offsets]))
    assert e_mean == pytest.approx(grid_mean, rel=1e-6)


def test_prose_claims():
    """The sentences around the table: the small-angle estimate is 33 % high, the value fills 54 % of the
    range, a 0.1 % change is 2.2 DN (3.5 sigma), and 10 ms would saturate the full well."""
    v = _package_values()
    small_angle = RADIANCE_W_M2_SR * MASK_SIDE_M**2 / D_F_M**2
    assert round(100 * (small_angle / v["irradiance averaged over the detector"] - 1)) == 33
    assert round(100 * v["mixel value"] / MAX_DN) == 54
    change_dn = 1e-3 * v["irradiance averaged over the detector"] * v["slope of the read-out"]
    assert round(change_dn, 1) == 2.2
    assert round(change_dn / v["temporal noise of the mixel value"], 1) == 3.5
    ten_ms = SensorModel.paper_prototype(exposure_s=10e-3)
    assert float(ten_ms.electrons(v["irradiance averaged over the detector"])) > FULL_WELL_E
    assert round(float(ten_ms.electrons(v["irradiance averaged over the detector"])), -3) == 54_000
