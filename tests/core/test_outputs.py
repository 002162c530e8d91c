"""Outputs a user can use as they are: print sheets, figures, positions in the CSV, what runs is what was asked,
atomic writes on a full disk, the budget guard, one-line warnings and progress lines, clear API errors."""

from __future__ import annotations

import errno
import io
import os
import re
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from mincam_sim import masks
from mincam_sim.configuration.config import EXAMPLE_TOML, load_config, traced_samples
from mincam_sim.errors import ConfigError, StaleResultError
from mincam_sim.masks import PrintedFilm, export_print_png
from mincam_sim.masks.files import srgb_to_linear
from mincam_sim.masks.sheet import CROP_GAP_M, write_print_sheet
from mincam_sim.measurements import Measurements
from mincam_sim.storage import atomic

SMALL = {"run": {"samples_per_texel": 16, "out_dir": "out"}, "frames": {"n": 2}, "screen": {"resolution": [32, 18]}}


def _dots(length_m: float, dpi: float) -> float:
    return length_m * dpi / 0.0254


# ------------------------------------------------------------------------------------------- print sheets


def test_sheet_places_every_mask_at_its_spacing(tmp_path):
    dpi = 300.0
    film = PrintedFilm(dpi=dpi)
    inks = [masks.constant(0.0), masks.constant(0.0)]  # full ink: black squares on the white sheet
    spacing = 0.033
    sheet, notes = write_print_sheet(inks, [(-spacing / 2, 0.0), (spacing / 2, 0.001)], dpi, film,
                                     tmp_path / "s.png", names=["left", "right"])
    with Image.open(sheet) as im:
        assert round(im.info["dpi"][0]) == 300
        a = np.asarray(im, dtype=float) / 255
    side = round(_dots(2e-3, dpi))
    # the two masks: side x side blocks of full ink; find them by their exact value in the sheet
    text = notes.read_text()
    rows_cols = [tuple(map(int, m.groups())) for m in re.finditer(r"at column (\d+), row (\d+)", text)]
    assert len(rows_cols) == 2
    (c_left, r_left), (c_right, r_right) = rows_cols
    for c, r in rows_cols:
        assert np.all(a[r:r + side, c:c + side] == 0.0)
        assert np.all(a[r - 1, c:c + side] == 1.0) and np.all(a[r + side, c:c + side] == 1.0)  # blank border
    assert abs((c_right - c_left) - _dots(spacing, dpi)) <= 1.0  # spacing kept to the nearest dot
    assert abs((r_left - r_right) - _dots(0.001, dpi)) <= 1.0  # +y is up on the sheet
    # crop marks: ink on the mask's top edge line, CROP_GAP_M to the left of it, not inside the gap
    gap = round(_dots(CROP_GAP_M, dpi))
    assert a[r_left, c_left - gap - 2] == 0.0 and np.all(a[r_left + 1:r_left + side - 1, c_left - gap + 1:c_left] == 1)
    for word in ("300 dpi", "0.02 + (0.9 - 0.02)", "towards the detectors", "left: centre (-16.50, +0.00) mm",
                 "PRINT AT 100 %"):
        assert word in text
    assert a.shape[0] > _dots(0.02, dpi)  # room for the notes printed on the sheet itself


def test_sheet_registration_marks_and_pdf_size(tmp_path):
    dpi = 200.0
    sheet, _ = write_print_sheet([masks.ramp("x")], [(0.0, 0.0)], dpi, None, tmp_path / "s.png")
    with Image.open(sheet) as im:
        a = np.asarray(im)
    h, w = a.shape
    corner = a[: h // 4, : w // 4]
    assert (corner == 0).sum() > 20  # a registration mark in the top-left corner
    pdf, txt = write_print_sheet([masks.ramp("x")], [(0.0, 0.0)], dpi, None, tmp_path / "s.pdf")
    box = re.search(rb"MediaBox \[ 0 0 ([\d.]+) ([\d.]+) \]", pdf.read_bytes())
    assert box is not None
    assert float(box.group(1)) == pytest.approx(w / dpi * 72, abs=0.01)
    assert float(box.group(2)) == pytest.approx(h / dpi * 72, abs=0.01)
    assert "no film model" in txt.read_text()


def test_sheet_refuses_overlaps_and_other_names(tmp_path):
    with pytest.raises(ValueError, match="overlap"):
        write_print_sheet([masks.ramp("x"), masks.ramp("y")], [(0, 0), (0.001, 0)], 600, None, tmp_path / "s.png")
    with pytest.raises(ValueError, match=".png"):
        write_print_sheet([masks.ramp("x")], [(0, 0)], 600, None, tmp_path / "s.jpg")


def test_export_levels_and_suffix(tmp_path):
    film = PrintedFilm(levels=1024)
    path = export_print_png(masks.ramp("x", 256, 0.03), tmp_path / "m.png", film=film)  # 709 dots across
    with Image.open(path) as im:
        assert im.mode.startswith("I")  # 16 bits: 1024 levels survive
        assert len(np.unique(np.asarray(im))) > 256
    with pytest.raises(ValueError, match="65536"):
        export_print_png(masks.ramp("x"), tmp_path / "m.png", film=PrintedFilm(levels=70000))
    with pytest.raises(ValueError, match=r"\.png"):
        export_print_png(masks.ramp("x"), tmp_path / "m.jpg")


def test_masks_export_cli_writes_a_sheet(tmp_path):
    from typer.testing import CliRunner

    from mincam_sim.cli import app

    r = CliRunner().invoke(app, ["masks", "export", "ramp:x", "--out", str(tmp_path / "m.png"), "--dpi", "300"])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "m_sheet.png").stat().st_size > 0
    assert "300 dpi" in (tmp_path / "m_sheet.txt").read_text()


def test_finished_design_of_another_seed_is_refused(tmp_path):
    from mincam_sim.design import tracking as tr
    from mincam_sim.design.run import IDENTITY_FILE, design_identity, run_design
    from mincam_sim.storage.store import check_identity

    task = replace(tr.TrackingTask.quick(0), dpi=600.0)
    (tmp_path / "design.json").write_text("{}")
    check_identity(tmp_path, design_identity("tracking", task, True, 0), name=IDENTITY_FILE)
    with pytest.raises(StaleResultError, match="seed"):
        run_design("tracking", tmp_path, quick=True, seed=1)
    (tmp_path / IDENTITY_FILE).unlink()
    with pytest.raises(StaleResultError, match="older version"):
        run_design("tracking", tmp_path, quick=True, seed=0)


# ------------------------------------------------------------------------------------ atomic, full disk


def test_full_disk_names_the_file_and_leaves_nothing(tmp_path, monkeypatch):
    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(atomic.os, "fsync", full)
    with pytest.raises(OSError) as info:
        atomic.atomic_write_text(tmp_path / "a.txt", "x" * 100)
    assert info.value.errno == errno.ENOSPC and info.value.filename == str(tmp_path / "a.txt")
    with pytest.raises(OSError) as info:
        masks.generate_library(tmp_path / "lib", resolution=8)
    assert info.value.filename.endswith(".exr") and ".tmp-" not in info.value.filename
    assert list((tmp_path / "lib").iterdir()) == []  # no 0-byte files, no temporaries
    assert not (tmp_path / "a.txt").exists()

    from mincam_sim.cli import user_error_message

    line = user_error_message(OSError(errno.ENOSPC, "No space left on device", "out/x.png"))
    assert "out/x.png" in line and "free some space" in line


def test_exr_writer_failure_becomes_a_named_oserror(tmp_path):
    tmp_seen = {}

    with pytest.raises(OSError) as info, atomic.atomic_path(tmp_path / "m.exr") as tmp:
        tmp_seen["p"] = tmp
        raise RuntimeError(f'Failed to write pixel data to image file "{tmp}". File too large.')
    assert info.value.errno == errno.EFBIG and info.value.filename == str(tmp_path / "m.exr")
    assert not tmp_seen["p"].exists()


# --------------------------------------------------------------------------------- measurements and CSV


def test_measurements_refuse_negative_or_nan_stderr():
    with pytest.raises(ValueError, match="stderr_w_m2 must be standard errors >= 0"):
        Measurements([[1.0, 2.0]], [[0.1, -0.1]], ["a", "b"])
    with pytest.raises(ValueError, match="frame 0, mixel 'a'"):
        Measurements([[1.0, 2.0]], [[np.nan, 0.1]], ["a", "b"])


def test_csv_carries_positions_and_time(tmp_path):
    m = Measurements([[1.0], [2.0]], [[0.1], [0.2]], ["x"],
                     {"frame_positions_m": [[-0.1, 0.0], [0.1, 0.05]], "frame_times_s": [0.0, 0.5]})
    rows = (tmp_path / "m.csv")
    m.save_csv(rows)
    lines = rows.read_text().splitlines()
    assert lines[1] == "frame,time_s,position_x_m,position_y_m,x_w_m2,x_stderr_w_m2"
    assert lines[3].split(",")[:4] == ["1", "0.5", "0.1", "0.05"]


def test_render_writes_figure_positions_and_the_traced_count(tmp_path):
    from typer.testing import CliRunner

    from mincam_sim.cli import app

    (tmp_path / "c.toml").write_text('[run]\nsamples_per_texel = 16\nout_dir = "out"\n[frames]\nn = 3\n'
                                     '[screen]\nresolution = [32, 18]\n')
    r = CliRunner().invoke(app, ["--quiet", "render", str(tmp_path / "c.toml")])
    assert r.exit_code == 0, r.output
    out = tmp_path / "out"
    assert (out / "measurements.png").stat().st_size > 0
    header = (out / "measurements.csv").read_text().splitlines()[1]
    assert header.startswith("frame,position_x_m,position_y_m,")
    meta = Measurements.load_npz(out / "measurements.npz").meta
    cfg = load_config(tmp_path / "c.toml")
    assert meta["samples_per_texel"] == traced_samples(cfg.run)[0] == 8  # what the note says is what ran
    assert "traces 8 samples per texel" in r.stderr


def test_a_response_map_render_writes_its_maps(tmp_path):
    from typer.testing import CliRunner

    from mincam_sim.cli import app

    (tmp_path / "c.toml").write_text('[run]\nsamples_per_texel = 16\nout_dir = "out"\n[frames]\nn = 2\n'
                                     '[screen]\nresolution = [32, 18]\n')
    r = CliRunner().invoke(app, ["--quiet", "render", str(tmp_path / "c.toml")])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "out" / "response_maps.png").stat().st_size > 0
    assert list((tmp_path / "out" / "response_maps").glob("*.exr"))


def test_check_shows_the_full_pose_and_an_estimate(tmp_path):
    from typer.testing import CliRunner

    from mincam_sim.cli import app

    text = ('[run]\nsamples_per_texel = 16\nout_dir = "out"\n[frames]\nn = 2\n[screen]\nresolution = [32, 18]\n'
            '[mincam]\nlayout = "custom"\n[[mixel]]\nmask = "ramp:x"\nforward = [0.0, 0.1, -1.0]\n')
    (tmp_path / "c.toml").write_text(text)
    r = CliRunner().invoke(app, ["render", str(tmp_path / "c.toml"), "--check"])
    assert r.exit_code == 0, r.output
    line = next(x for x in r.stdout.splitlines() if x.startswith("mixel m0"))
    assert "forward [+0.0000, +0.0995, -0.9950]" in line and "up [" in line
    assert "estimate: about" in r.stdout


# -------------------------------------------------------------------------------- what runs is what asked


def test_sample_rounding_is_stated():
    cfg = load_config({**SMALL, "run": {"samples_per_texel": 64}})
    traced, note = traced_samples(cfg.run)
    assert traced == 32 and "traces 32" in note and "72" in note
    assert traced_samples(load_config({"run": {"samples_per_texel": 72}}).run) == (72, None)
    fast = load_config({"run": {"solver": "aperture", "spp": 1001}})
    assert traced_samples(fast.run)[0] == 1008
    assert "64 with 8 replicates traces 32" in EXAMPLE_TOML


def _png(path: Path, rows: int, cols: int, value: int) -> None:
    Image.fromarray(np.full((rows, cols), value, dtype=np.uint8)).save(path)


def test_mask_sizes_per_mixel_and_non_square_files(tmp_path):
    _png(tmp_path / "wide.png", 32, 64, 128)
    base = {"mincam": {"layout": "custom"}, "screen": {"resolution": [32, 18]}, "frames": {"n": 2}}
    with pytest.raises(ConfigError, match=r"mask_size_m = \[0.002, 0.001\]"):
        load_config({**base, "mixel": [{"mask": "file:wide.png"}]}, base_dir=tmp_path)
    cfg = load_config({**base, "mixel": [{"mask": "file:wide.png", "mask_size_m": [0.002, 0.001]}]},
                      base_dir=tmp_path)
    mask = cfg.mincam[0].mask
    assert (mask.width_m, mask.height_m) == (0.002, 0.001)
    with pytest.raises(ConfigError, match="stretched"):
        load_config({**base, "mixel": [{"mask": "file:wide.png", "mask_size_m": [0.002, 0.002]}]}, base_dir=tmp_path)
    ramp = load_config({**base, "mixel": [{"mask": "ramp:x", "mask_size_m": [0.003, 0.002]}]}).mincam[0].mask
    assert (ramp.width_m, ramp.height_m) == (0.003, 0.002) and ramp.shape == (171, 256)


def test_srgb_masks_are_decoded(tmp_path):
    _png(tmp_path / "g.png", 8, 8, 128)
    base = {"mincam": {"layout": "custom"}, "screen": {"resolution": [32, 18]}, "frames": {"n": 2}}
    lin = load_config({**base, "mixel": [{"mask": "file:g.png"}]}, base_dir=tmp_path).mincam[0].mask
    srgb = load_config({**base, "mixel": [{"mask": "file:g.png", "mask_encoding": "srgb"}]},
                       base_dir=tmp_path).mincam[0].mask
    assert lin.transmission[0, 0] == pytest.approx(128 / 255)
    assert srgb.transmission[0, 0] == pytest.approx(((128 / 255 + 0.055) / 1.055) ** 2.4)  # 0.2158
    assert srgb_to_linear(np.array([0.0, 1.0])).tolist() == [0.0, 1.0]
    masks.save_exr(masks.ramp("x", 8), tmp_path / "r.exr")
    with pytest.raises(ConfigError, match="linear"):
        load_config({**base, "mixel": [{"mask": "file:r.exr", "mask_encoding": "srgb"}]}, base_dir=tmp_path)


def test_config_with_a_byte_order_mark(tmp_path):
    (tmp_path / "c.toml").write_bytes(b"\xef\xbb\xbf[run]\nseed = 3\n")
    assert load_config(tmp_path / "c.toml").run.budget.seed == 3


def test_sinusoid_direction_out_of_range():
    with pytest.raises(ValueError, match="direction_deg"):
        masks.sinusoid(1000.0, direction_deg=1e308)
    with pytest.raises(ConfigError, match="direction_deg"):
        load_config({"mincam": {"layout": "custom"},
                     "mixel": [{"mask": {"kind": "sinusoid", "omega_rad_per_m": 1000.0, "direction_deg": 1e308}}]})


# ------------------------------------------------------------------------------------------- budget guard


def test_budget_guard_refuses_with_the_estimate():
    from mincam_sim.render.solvers import Aperture
    from mincam_sim.runs.jobs import SAMPLES_PER_S, check_budget, estimate_seconds

    cfg = load_config({"run": {"solver": "aperture", "spp": 2**40}, "frames": {"n": 2}})
    seconds, what = estimate_seconds(cfg)
    assert seconds > 86400 and "1099511627776 samples" in what
    with pytest.raises(ConfigError, match=r"about .* days .*--time-limit-s"):
        check_budget(cfg, None, 3600.0)
    assert check_budget(cfg, None, 2 * seconds) == seconds
    twice = load_config({"run": {"solver": "aperture", "spp": 2**41}, "frames": {"n": 2}})
    # twice the rays: the tracing part (2 frames x 2 mixels x spp) doubles, the rest stays
    assert estimate_seconds(twice)[0] - seconds == pytest.approx(2 * 2 * 2**40 / SAMPLES_PER_S[Aperture])


# ------------------------------------------------------------------------------ warnings, progress, API


def test_warnings_are_one_line_and_the_dask_port_is_quiet(capsys):
    from mincam_sim.cli import install_warning_format

    with warnings.catch_warnings():
        install_warning_format()
        warnings.warn("something odd\nacross lines", UserWarning, stacklevel=1)
        warnings.warn("Port 8787 is already in use.\nPerhaps you already have a cluster running?", UserWarning,
                      stacklevel=1)
    err = capsys.readouterr().err
    assert err == "warning: something odd across lines (UserWarning)\n"


def test_progress_off_a_terminal_is_periodic_lines(monkeypatch):
    from mincam_sim import progress

    stream = io.StringIO()
    monkeypatch.setattr(progress.sys, "stderr", stream)
    monkeypatch.setenv(progress.ENV_INTERVAL, "0")
    with progress.bar(4, "frames", disable=False, unit="frame") as b:
        for _ in range(4):
            b.update(1)
    text = stream.getvalue()
    assert "\r" not in text
    lines = text.strip().splitlines()
    assert lines[0].startswith("frames:   0%") and "4/4" in lines[-1] and len(lines) == 5
    stream.truncate(0)
    stream.seek(0)
    monkeypatch.setenv(progress.ENV_INTERVAL, "3600")
    assert list(progress.progress(range(3), "items", disable=False)) == [0, 1, 2]
    assert len(stream.getvalue().strip().splitlines()) == 2  # the start and the end, nothing in between


def test_api_inputs_name_the_field():
    from mincam_sim.model.optics import Mincam, Mixel, cross_layout, pair_layout

    with pytest.raises(ConfigError, match="d_f_m .*no quotes, no units"):
        Mixel(masks.ramp("x"), d_f_m="2mm")
    with pytest.raises(ConfigError, match="spacing_m"):
        pair_layout(spacing_m="3.3cm")
    with pytest.raises(ConfigError, match="spacing_m"):
        cross_layout(spacing_m="3.3cm")
    with pytest.raises(ConfigError, match="item 0 .* not a Mixel"):
        Mincam(("x",))
    with pytest.raises(ConfigError, match="tuple of Mixel"):
        Mincam(Mixel(masks.ramp("x")))


# -------------------------------------------------------------------------------------------- figures


def _capture(monkeypatch):
    from mincam_sim.plotting import plots

    figs = []
    monkeypatch.setattr(plots, "_save", lambda fig, path: figs.append(fig) or Path(path))
    return plots, figs


def test_tracking_paths_equal_aspect_and_linked(monkeypatch):
    plots, _ = _capture(monkeypatch)
    truth = np.column_stack([np.linspace(0, 0.2, 10), np.zeros(10)])
    pred = truth + 0.01
    fig = plots.tracks_figure(pred, truth, np.array(["a"] * 10))
    ax = fig.axes[0]
    assert ax.get_aspect() == 1.0
    (links,) = ax.collections
    segments = links.get_segments()
    assert len(segments) == 10  # one segment per estimate, to its own frame's truth
    assert all(np.allclose(seg, 100 * np.array([t, p])) for seg, t, p in zip(segments, truth, pred, strict=True))
    assert any(t.get_text() == "0" for t in ax.texts)
    pred[3] = np.nan  # a frame without an estimate has no link
    (links,) = plots.tracks_figure(pred, truth, np.array(["a"] * 10)).axes[0].collections
    assert len(links.get_segments()) == 9


def test_calibration_2d_right_panel_has_axis_labels(monkeypatch):
    plots, figs = _capture(monkeypatch)

    class Identity:
        def apply(self, obs):
            return obs

    pts = np.random.default_rng(0).uniform(-0.1, 0.1, (9, 2))
    plots.plot_calibration_2d(pts, pts, Identity(), "x.png")
    right = figs[0].axes[1]
    assert "[cm]" in right.get_xlabel() and "[cm]" in right.get_ylabel()


def test_spectrum_says_why_the_highest_peak_is_not_detected(monkeypatch):
    from mincam_sim.estimation.estimators import spectrum

    plots, figs = _capture(monkeypatch)
    t = np.arange(256) / 32.0
    signal = 5 * np.sin(2 * np.pi * 1.0 * t) + np.sin(2 * np.pi * 6.0 * t)
    spec = spectrum(signal, 32.0, min_frequency_hz=3.0)
    note = plots.highest_peak_note(spec)
    assert note is not None and "below the search band" in note
    plots.plot_spectrum(spec, 2 * np.pi * 6.0, "s.png")
    assert any("search band" in t.get_text() for t in figs[0].axes[0].texts)
    assert plots.highest_peak_note(spectrum(signal, 32.0)) is None


def test_readme_make_test_timing_is_not_one_minute():
    text = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    assert "~1 min" not in text.split("make test")[1][:200]


def test_design_json_not_needed_for_sheet_notes(tmp_path):
    # the notes beside a sheet are enough to print it: dpi, film mapping, every mask's place and size
    film = PrintedFilm(t_min=0.05, t_max=0.85, dpi=600, levels=64)
    _, txt = write_print_sheet([masks.ramp("x"), masks.ramp("1-x")], [(0.0165, 0), (-0.0165, 0)], 600, film,
                               tmp_path / "s.png")
    text = txt.read_text()
    assert "0.05 + (0.85 - 0.05) * v^1" in text and "64 grey levels" in text and "47 x 47 dots" in text
    assert os.path.getsize(tmp_path / "s.png") > 0


def test_a_render_refused_by_the_budget_claims_nothing(tmp_path):
    from mincam_sim.runs.jobs import run_render_config

    cfg = load_config({"run": {"solver": "aperture", "spp": 2**40, "out_dir": str(tmp_path / "out")},
                       "frames": {"n": 2}})
    with pytest.raises(ConfigError, match="--time-limit-s"):
        run_render_config(cfg, time_limit_s=60.0)
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())  # nothing claimed


def test_grid_sweep_figure_has_a_map_per_mixel(monkeypatch):
    plots, figs = _capture(monkeypatch)
    xs, ys = np.meshgrid([-0.1, 0.0, 0.1], [-0.05, 0.05])
    pos = np.column_stack([xs.ravel(), ys.ravel()])
    m = Measurements(np.column_stack([pos[:, 0] + 1, pos[:, 1] + 1]), np.full((6, 2), 0.01), ["a", "b"],
                     {"frame_positions_m": pos.tolist()})
    plots.plot_render(m, "g.png", pos, "grid_sweep")
    images = [ax.images[0].get_array() for ax in figs[0].axes if ax.images]
    assert len(images) == 2
    assert images[0][1, 2] == pytest.approx(1.1) and images[1][0, 0] == pytest.approx(0.95)  # (x, y) in place
