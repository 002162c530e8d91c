"""Mask generators, curved ramps, file I/O (PNG/EXR), the printed-film model and the mask library."""

from __future__ import annotations

import numpy as np
import pytest

from mincam_sim import masks as M
from mincam_sim.storage import imageio

# ------------------------------------------------------------------------------------------- generators


@pytest.mark.parametrize(
    ("kind", "expected"),
    [("x", lambda x, y: x), ("1-x", lambda x, y: 1 - x), ("y", lambda x, y: y), ("1-y", lambda x, y: 1 - y)],
)
def test_ramps_are_exact_linear_functions_of_texel_centres(kind, expected):
    h, w = 12, 20
    m = M.ramp(kind, (h, w), width_m=3e-3, height_m=2e-3)
    x = (np.arange(w) + 0.5) / w
    y = 1.0 - (np.arange(h) + 0.5) / h  # row 0 at the top: largest y
    xx, yy = np.meshgrid(x, y)
    np.testing.assert_allclose(m.transmission, expected(xx, yy), rtol=0, atol=1e-15)
    assert m.shape == (h, w) and m.width_m == 3e-3 and m.height_m == 2e-3


def test_ramp_orientation_convention():
    m = M.ramp("y", 8)
    assert m.transmission[0, 0] > m.transmission[-1, 0]  # top row is y ~ 1
    m = M.ramp("x", 8)
    assert m.transmission[0, -1] > m.transmission[0, 0]  # right column is x ~ 1


def test_complement_and_scale():
    m = M.ramp("x", 16)
    np.testing.assert_allclose(m.complement().transmission, M.ramp("1-x", 16).transmission, atol=1e-15)
    np.testing.assert_allclose(m.scaled(0.25).transmission, 0.25 * m.transmission)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        m.scaled(2.0)


def test_unknown_ramp_kind():
    with pytest.raises(ValueError, match="choose one of"):
        M.ramp("diagonal")


def test_sinusoid_row_fft_peaks_at_expected_cycles():
    width = 2e-3
    period = 0.25e-3
    m = M.sinusoid(2 * np.pi / period, 0.5, 0.5, resolution=128, width_m=width)
    spec = np.abs(np.fft.rfft(m.transmission[5] - m.transmission[5].mean()))
    assert int(np.argmax(spec)) == round(width / period)  # omega * width / (2 pi) cycles across the mask
    assert m.transmission.min() >= 0 and m.transmission.max() <= 1
    # direction 90 degrees: the wave runs along the columns instead
    v = M.sinusoid(2 * np.pi / period, 0.5, 0.5, direction_deg=90, resolution=128, width_m=width)
    assert np.ptp(v.transmission[:, 3]) > 0.9 and np.ptp(v.transmission[3, :]) < 1e-12


def test_sinusoid_rejects_unphysical_amplitude():
    with pytest.raises(ValueError, match="leaves"):
        M.sinusoid(1000.0, a0=0.5, a1=0.7)


# ------------------------------------------------------------------------------------------- curved ramps


def test_curved_ramp_along_straight_line_equals_plain_ramp():
    ref = M.ramp("x", (16, 24))
    line = M.curved_ramp(np.array([[0.0, 0.3], [1.0, 0.3]]), (16, 24))
    np.testing.assert_allclose(line.transmission, ref.transmission, atol=1e-12)
    # several collinear vertices, and a vertical line giving ramp y
    many = M.curved_ramp(np.column_stack((np.linspace(0, 1, 7), np.full(7, 0.6))), (16, 24))
    np.testing.assert_allclose(many.transmission, ref.transmission, atol=1e-12)
    vert = M.curved_ramp(np.array([[0.5, 0.0], [0.5, 1.0]]), 16)
    np.testing.assert_allclose(vert.transmission, M.ramp("y", 16).transmission, atol=1e-12)
    # physical coordinates and reversed values
    phys = M.curved_ramp(np.array([[-1e-3, 0.0], [1e-3, 0.0]]), 16, coords="physical", values=(1.0, 0.0))
    np.testing.assert_allclose(phys.transmission, M.ramp("1-x", 16).transmission, atol=1e-12)


def test_curved_ramp_off_curve_takes_nearest_point_value():
    # curve covers only the middle half: texels left of it get 0, right of it 1
    m = M.curved_ramp(np.array([[0.25, 0.5], [0.75, 0.5]]), 16)
    assert np.all(m.transmission[:, :4] == 0.0) and np.all(m.transmission[:, -4:] == 1.0)


def test_curved_ramp_l_shape_uses_arc_length():
    # L-shaped curve of two equal legs: the corner is at s/L = 0.5
    m = M.curved_ramp(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]), 64)
    i_corner, j_corner = 63, 63  # bottom-right texel is next to the corner
    assert abs(m.transmission[i_corner, j_corner] - 0.5) < 0.02
    assert m.meta["length_m"] == pytest.approx(4e-3)


def test_circular_ramp_is_angle_fraction_and_monotone_along_circle():
    res, radius, start = 96, 0.35, 30.0
    m = M.circular_ramp(center=(0.5, 0.5), radius=radius, start_angle_deg=start, resolution=res)
    t = m.transmission
    assert t.min() >= 0.0 and t.max() <= 1.0
    x, y = m.normalized_coords()
    r = np.hypot(x - 0.5, y - 0.5)
    ang = np.mod(np.degrees(np.arctan2(y - 0.5, x - 0.5)) - start, 360.0)
    near = (np.abs(r - radius) < 3.0 / res) & (ang > 1.0) & (ang < 359.0)  # away from the seam
    np.testing.assert_allclose(t[near], ang[near] / 360.0, atol=1e-6)
    order = np.argsort(ang[near])
    assert np.all(np.diff(t[near][order]) >= -1e-9)
    # a clockwise half circle
    half = M.circular_ramp(radius=0.3, start_angle_deg=90, sweep_deg=-180, resolution=64)
    assert half.transmission[0, 32] < 0.05  # top (start)
    assert abs(half.transmission[32, -1] - 0.5) < 0.05  # right = a quarter turn clockwise from the top
    assert half.transmission[-1, 32] > 0.95  # bottom (end)


def test_circular_ramp_matches_curved_ramp_on_a_polygon():
    exact = M.circular_ramp(radius=0.3, start_angle_deg=-45, sweep_deg=270, resolution=48)
    poly = M.circular_ramp(radius=0.3, start_angle_deg=-45, sweep_deg=270, resolution=48, n_segments=270)
    x, y = exact.normalized_coords()
    r = np.hypot(x - 0.5, y - 0.5)
    ring = (r > 0.1) & (r < 0.5)
    assert np.abs(exact.transmission - poly.transmission)[ring].max() < 2e-3
    assert np.mean(np.abs(exact.transmission - poly.transmission)[ring] < 1e-3) > 0.97


def test_curved_ramp_bad_inputs():
    with pytest.raises(ValueError, match="at least 2 points"):
        M.curved_ramp(np.array([[0.0, 0.0]]))
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        M.curved_ramp(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="zero length"):
        M.curved_ramp(np.array([[0.2, 0.2], [0.2, 0.2]]))
    with pytest.raises(ValueError, match="NaN"):
        M.curved_ramp(np.array([[0.0, np.nan], [1.0, 0.0]]))
    with pytest.raises(ValueError, match="coords"):
        M.curved_ramp(np.array([[0.0, 0.0], [1.0, 0.0]]), coords="pixels")
    with pytest.raises(ValueError, match="radius"):
        M.circular_ramp(radius=0.0)
    with pytest.raises(ValueError, match="sweep_deg"):
        M.circular_ramp(sweep_deg=400.0)


# ------------------------------------------------------------------------------------------- Mask validation


@pytest.mark.parametrize(
    ("array", "message"),
    [
        (np.array([[0.5, np.nan]]), "NaN or infinite"),
        (np.array([[0.5, 1.5]]), r"must lie in \[0, 1\]"),
        (np.array([[-0.1, 0.5]]), r"must lie in \[0, 1\]"),
        (np.zeros((0, 4)), "empty"),
        (np.zeros(5), "2D array"),
    ],
)
def test_mask_rejects_bad_arrays(array, message):
    with pytest.raises(ValueError, match=message):
        M.Mask(array)


@pytest.mark.parametrize("size", [0.0, -1e-3, np.nan, np.inf])
def test_mask_rejects_bad_sizes(size):
    with pytest.raises(ValueError, match="positive size in metres"):
        M.Mask(np.ones((2, 2)), width_m=size)
    with pytest.raises(ValueError, match="positive size in metres"):
        M.Mask(np.ones((2, 2)), height_m=size)


def test_bad_resolution():
    with pytest.raises(ValueError, match="resolution"):
        M.ramp("x", 0)


# ------------------------------------------------------------------------------------------- file I/O


def test_exr_round_trip_and_metadata(tmp_path):
    m = M.sinusoid(2 * np.pi / 0.5e-3, 0.5, 0.4, resolution=(20, 30), width_m=3e-3, height_m=2e-3)
    path = M.save_exr(m, tmp_path / "sub" / "sin.exr")
    back = M.load(path)
    np.testing.assert_allclose(back.transmission, m.transmission, atol=1e-7)
    assert (back.width_m, back.height_m, back.name) == (3e-3, 2e-3, m.name)
    assert back.meta["kind"] == "sinusoid" and back.meta["format"] == "exr"
    arr, meta = imageio.read_exr(path)
    assert arr.dtype == np.float32 and arr.shape == (20, 30)
    assert meta["units"] == "m" and meta["channels"] == ["Y"]
    # explicit size overrides the stored one
    assert M.load(path, width_m=1e-3).width_m == 1e-3


def test_exr_multichannel_keeps_channel_order(tmp_path):
    rng = np.random.default_rng(0)
    a = rng.random((5, 7, 3))
    p = imageio.write_exr(tmp_path / "m.exr", a, channels=("W", "sigma", "A0"), metadata={"n": np.int64(3)})
    arr, meta = imageio.read_exr(p)
    assert meta["channels"] == ["W", "sigma", "A0"] and meta["n"] == 3
    np.testing.assert_allclose(arr, a.astype(np.float32))
    with pytest.raises(ValueError, match="has 3 channels"):
        M.load(p, width_m=1e-3)
    with pytest.raises(ValueError, match="channel name"):
        imageio.write_exr(tmp_path / "x.exr", a, channels=("Y",))


def test_exr_values_out_of_range_rejected(tmp_path):
    p = imageio.write_exr(tmp_path / "hdr.exr", np.full((4, 4), 2.5))
    with pytest.raises(ValueError, match=r"must lie in \[0, 1\].*rescale"):
        M.load(p, width_m=1e-3)
    p = imageio.write_exr(tmp_path / "nan.exr", np.array([[0.5, np.nan]]))
    with pytest.raises(ValueError, match="NaN"):
        M.load(p, width_m=1e-3)


def test_png_16bit_round_trip(tmp_path):
    m = M.ramp("x", (10, 37), width_m=1e-3)
    p = imageio.write_png(tmp_path / "r16.png", m.transmission, bit_depth=16, dpi=1200)
    back = M.load(p, width_m=1e-3)
    assert np.abs(back.transmission - m.transmission).max() <= 0.5 / 65535 + 1e-12
    assert back.meta["bit_depth"] == 16
    assert back.height_m == pytest.approx(1e-3 * 10 / 37)  # square texels by default
    arr, info = imageio.read_png(p)
    assert info["dpi"][0] == pytest.approx(1200, abs=0.01)


def test_png_8bit_rgb_and_invert(tmp_path):
    from PIL import Image

    g = np.array([[0, 51, 255], [255, 102, 0]], dtype=np.uint8)
    Image.fromarray(np.stack([g] * 3, axis=-1)).save(tmp_path / "rgb.png")
    m = M.load(tmp_path / "rgb.png", width_m=1e-3)
    np.testing.assert_allclose(m.transmission, g / 255.0, atol=1e-12)
    inv = M.load(tmp_path / "rgb.png", width_m=1e-3, height_m=2e-3, invert=True, name="neg")
    np.testing.assert_allclose(inv.transmission, 1 - g / 255.0, atol=1e-12)
    assert inv.name == "neg" and inv.height_m == 2e-3 and m.name == "rgb"
    # row 0 of the image is the top row of the mask
    assert m.transmission[0, 2] == 1.0 and m.transmission[1, 2] == 0.0


def test_png_transparent_alpha_rejected(tmp_path):
    from PIL import Image

    rgba = np.zeros((2, 2, 4), dtype=np.uint8)
    rgba[..., 3] = 128
    Image.fromarray(rgba).save(tmp_path / "a.png")
    with pytest.raises(ValueError, match="alpha"):
        M.load(tmp_path / "a.png", width_m=1e-3)


def test_png_needs_physical_size(tmp_path):
    p = imageio.write_png(tmp_path / "r.png", np.full((4, 8), 0.5), dpi=600)
    with pytest.raises(ValueError, match=r"no physical size: give width_m.*600 dpi"):
        M.load(p)


def test_load_missing_empty_and_non_image_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        M.load(tmp_path / "nope.png", width_m=1e-3)
    (tmp_path / "empty.png").write_bytes(b"")
    with pytest.raises(ValueError, match="is empty"):
        M.load(tmp_path / "empty.png", width_m=1e-3)
    (tmp_path / "notes.png").write_text("this is not an image\n")
    with pytest.raises(ValueError, match="not an image.*PNG.*OpenEXR"):
        M.load(tmp_path / "notes.png", width_m=1e-3)
    with pytest.raises(ValueError, match="not a regular file"):
        M.load(tmp_path, width_m=1e-3)
    # truncated files with valid signatures
    good = imageio.write_png(tmp_path / "g.png", np.full((32, 32), 0.5)).read_bytes()
    (tmp_path / "trunc.png").write_bytes(good[: len(good) // 2])
    with pytest.raises(ValueError, match="could not be decoded"):
        M.load(tmp_path / "trunc.png", width_m=1e-3)
    good = imageio.write_exr(tmp_path / "g.exr", np.full((32, 32), 0.5)).read_bytes()
    (tmp_path / "trunc.exr").write_bytes(good[:40])
    with pytest.raises(ValueError, match="could not be decoded"):
        M.load(tmp_path / "trunc.exr", width_m=1e-3)


def test_native_output_held_while_an_exr_is_read_is_kept_unless_the_read_fails(tmp_path, capfd):
    """What native code writes during a read goes where it was going when the read succeeds, and becomes a
    note of the error (seen with its traceback, not above the one-line error) when it fails."""
    import os

    from mincam_sim.masks import files

    with files._library_output_held():
        os.write(1, b"native out\n")
        os.write(2, b"native err\n")
        print("python out")  # OpenEXR's bindings print their warnings through sys.stdout
    out, err = capfd.readouterr()
    assert sorted(out.splitlines()) == ["native out", "python out"] and err == "native err\n"
    with pytest.raises(ValueError, match="bad file") as failed, files._library_output_held():
        os.write(2, b"t.exr: EXR_ERR_BAD_CHUNK_LEADER\n")
        print("Warning: Exception raised reading pixel data")
        raise ValueError("bad file")
    assert capfd.readouterr() == ("", "")
    assert failed.value.__notes__ == ["OpenEXR said:\nWarning: Exception raised reading pixel data\n"
                                      "t.exr: EXR_ERR_BAD_CHUNK_LEADER"]
    good = M.save_exr(M.ramp("x", 256, width_m=2e-3), tmp_path / "g.exr").read_bytes()
    (tmp_path / "half.exr").write_bytes(good[: len(good) // 2])
    with pytest.raises(ValueError, match="could not be decoded") as failed:
        M.load(tmp_path / "half.exr")
    assert capfd.readouterr() == ("", "") and "EXR_ERR" in "".join(failed.value.__notes__)


def test_write_png_bad_inputs(tmp_path):
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        imageio.write_png(tmp_path / "x.png", np.array([[2.0]]))
    with pytest.raises(ValueError, match="bit_depth"):
        imageio.write_png(tmp_path / "x.png", np.array([[0.5]]), bit_depth=12)
    with pytest.raises(ValueError, match="empty"):
        imageio.write_png(tmp_path / "x.png", np.zeros((0, 3)))


# ------------------------------------------------------------------------------------------- printing


def test_printed_film_resolution_range_and_constant():
    film = M.PrintedFilm(t_min=0.03, t_max=0.88, dpi=600)
    m = M.ramp("x", 256, width_m=2e-3, height_m=3e-3)
    p = film.print(m)
    assert p.shape == (round(3e-3 / 0.0254 * 600), round(2e-3 / 0.0254 * 600))  # (71, 47)
    assert (p.width_m, p.height_m) == (m.width_m, m.height_m)
    assert p.transmission.min() >= 0.03 - 1e-12 and p.transmission.max() <= 0.88 + 1e-12
    assert np.all(np.diff(p.transmission[0]) >= 0)  # still a ramp
    assert p.meta["film"]["dpi"] == 600 and p.meta["printed_from"] == m.name
    c = film.print(M.constant(0.5, 7))
    np.testing.assert_allclose(c.transmission, 0.03 + 0.85 * 128 / 255, atol=1e-12)  # 8-bit levels
    assert film.print(M.constant(1.0)).transmission.min() == pytest.approx(0.88)


def test_printed_film_levels_halftone_and_validation():
    m = M.ramp("x", 64)
    q = M.PrintedFilm(t_min=0.0, t_max=1.0, levels=4).print(m)
    assert len(np.unique(np.round(q.transmission, 12))) <= 4
    ht = M.PrintedFilm(halftone="ordered", dpi=2400).print(M.constant(0.25, 4, width_m=4e-3))
    assert set(np.unique(ht.transmission)) <= {0.02, 0.9}
    assert ht.transmission.mean() == pytest.approx(0.02 + 0.88 * 0.25, abs=0.01)
    with pytest.raises(ValueError, match="t_min < t_max"):
        M.PrintedFilm(t_min=0.9, t_max=0.1)
    with pytest.raises(ValueError, match="dpi"):
        M.PrintedFilm(dpi=0)
    with pytest.raises(ValueError, match="levels"):
        M.PrintedFilm(levels=1)


def test_resample_preserves_mean_and_constants():
    m = M.ramp("x", (30, 50))
    for shape in [(7, 11), (30, 50), (97, 131)]:
        r = M.resample(m, shape)
        assert r.shape == shape
        assert r.mean() == pytest.approx(m.transmission.mean(), abs=1e-12)
    np.testing.assert_allclose(M.resample(M.constant(0.3, (5, 9)), (13, 4)), 0.3, atol=1e-15)


def test_export_print_png_size_and_dpi(tmp_path):
    m = M.ramp("x", 128, width_m=5e-3, height_m=2e-3)
    p = M.export_print_png(m, tmp_path / "print.png", dpi=1200)
    arr, info = imageio.read_png(p)
    assert arr.shape == (round(2e-3 / 0.0254 * 1200), round(5e-3 / 0.0254 * 1200))
    assert info["dpi"][0] == pytest.approx(1200, abs=0.01) and info["bit_depth"] == 8
    back = M.load(p, width_m=5e-3, height_m=2e-3)
    assert back.transmission.mean() == pytest.approx(0.5, abs=2e-3)
    film = M.PrintedFilm(dpi=300, halftone="ordered")
    arr, info = imageio.read_png(M.export_print_png(m, tmp_path / "ht.png", film=film))
    assert set(np.unique(arr)) <= {0.0, 1.0} and info["dpi"][0] == pytest.approx(300, abs=0.01)


# ------------------------------------------------------------------------------------------- library & plot


def test_generate_library_writes_readable_deterministic_files(tmp_path):
    paths = M.generate_library(tmp_path / "a", resolution=32, size_m=1e-3)
    names = {p.stem for p in paths}
    assert {"ramp_x", "ramp_1-x", "ramp_y", "ramp_1-y", "constant_1", "circular_ramp"} <= names
    assert any(n.startswith("sinusoid") for n in names)
    for p in paths:
        m = M.load(p, width_m=1e-3) if p.suffix == ".png" else M.load(p)
        assert m.shape == (32, 32) and m.width_m == 1e-3
    np.testing.assert_allclose(M.load(tmp_path / "a" / "ramp_x.exr").transmission, M.ramp("x", 32).transmission,
                               atol=1e-7)
    again = M.generate_library(tmp_path / "b", resolution=32, size_m=1e-3)
    assert [p.read_bytes() for p in paths] == [p.read_bytes() for p in again]


def test_plot_mask(tmp_path):
    from mincam_sim.plotting.plots import plot_mask

    ax = plot_mask(M.circular_ramp(resolution=32, width_m=3e-3))
    assert ax.get_xlabel() == "x [mm]"
    assert ax.images[0].get_extent() == pytest.approx([-1.5, 1.5, -1.5, 1.5])
    ax.figure.savefig(tmp_path / "m.png")
    assert (tmp_path / "m.png").stat().st_size > 0
