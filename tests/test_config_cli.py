"""The TOML schema, its validation, and the command line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from mincam_sim.cli import app
from mincam_sim.config import EXAMPLE_TOML, ConfigError, load_config

ROOT = Path(__file__).resolve().parents[1]


def test_example_schema_is_the_default():
    cfg = load_config(EXAMPLE_TOML)
    assert cfg.run.form == "response_map"
    assert cfg.mincam.names == ["x", "1-x"]
    assert cfg.frames.shape == (26, 144, 256)
    left, right = cfg.mincam
    assert np.isclose(right.pose.position_m[0] - left.pose.position_m[0], 0.033)


@pytest.mark.parametrize("path", sorted((ROOT / "scenes").glob("*.toml")), ids=lambda p: p.name)
def test_shipped_scene_configs_load(path):
    cfg = load_config(path)
    assert len(cfg.frames) > 0


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[run]\nspp_count = 3", "unknown key.*spp_count.*allowed"),
        ("[runn]\n", "unknown section"),
        ("[run]\nspp = 0", r"spp must be an integer > 0"),
        ("[run]\nspp = -4", r"spp must be an integer > 0"),
        ("[run]\nreplicates = 1", "replicates must be >= 2"),
        ("[run]\nform = 'magic'", "form = 'magic' is not one of"),
        ("[mincam]\nd_f_m = 0.0", r"d_f_m must be a number > 0"),
        ("[mincam]\ndetector_size_m = -1e-4", "detector_size_m must be"),
        ("[mincam]\nlayout = 'star'", "layout = 'star' is not one of"),
        ("[mincam]\nlayout = 'custom'", "needs at least one \\[\\[mixel\\]\\]"),
        ("[mincam]\nlayout = 'custom'\n[[mixel]]\nmask = 'ramp:z'", "unknown ramp 'z'"),
        ("[mincam]\nlayout = 'custom'\n[[mixel]]\nmask = 'blob'", "not understood"),
        ("[mincam]\nlayout = 'custom'\n[[mixel]]\nmask = 'file:/nonexistent/m.png'", "m.png"),
        ("[mincam]\nlayout = 'custom'\n[[mixel]]\nmask = 'ramp:x'\ncolour = 1", "unknown key.*colour"),
        ("[mincam]\nlayout = 'custom'\n[[mixel]]\nmask = {kind = 'sinusoid', a0 = 0.5}", "omega_rad_per_m"),
        ("[mincam]\nlayout = 'custom'\n[[mixel]]\nmask = 'constant:1.5'", r"\[0, 1\]"),
        ("[screen]\ndistance_m = 0", "distance_m must be a number > 0"),
        ("[screen]\nresolution = [0, 10]", "resolution"),
        ("[frames]\nkind = 'npy'\npath = 'missing.npy'", "is not a file"),
        ("[frames]\nsquare_m = 0", "square_m must be"),
        ("not toml = = =", "not valid TOML"),
    ],
)
def test_bad_configs_name_the_field(text, message):
    with pytest.raises(ConfigError, match=message):
        load_config(text)


def test_cli_render_writes_outputs(tmp_path):
    config = tmp_path / "c.toml"
    config.write_text(
        "[run]\nsamples_per_texel = 16\nout_dir = 'out'\n[frames]\nn = 3\n[screen]\nresolution = [64, 36]\n"
    )
    result = CliRunner().invoke(app, ["render", str(config)])
    assert result.exit_code == 0, result.output
    out = tmp_path / "out"
    for name in ("measurements.npz", "measurements.csv", "response_maps/response_x.exr"):
        assert (out / name).is_file(), name
    from mincam_sim.measurements import Measurements

    m = Measurements.load_npz(out / "measurements.npz")
    assert m.irradiance_w_m2.shape == (3, 2)
    assert m.meta["variant"] in ("llvm_ad_mono", "cuda_ad_mono", "scalar_rgb")
    assert m.meta["seed"] == 0
    assert "W/m^2" in result.output


def test_cli_reports_bad_config_cleanly(tmp_path):
    config = tmp_path / "bad.toml"
    config.write_text("[mincam]\nd_f_m = -1\n")
    result = CliRunner().invoke(app, ["render", str(config)])
    assert result.exit_code == 2
    assert "d_f_m" in result.output
    result = CliRunner().invoke(app, ["render", str(tmp_path / "missing.toml")])
    assert result.exit_code == 2 and "does not exist" in result.output


def test_cli_masks_generate_and_export(tmp_path):
    result = CliRunner().invoke(app, ["masks", "generate", "--out", str(tmp_path / "lib"), "--resolution", "32"])
    assert result.exit_code == 0, result.output
    assert list((tmp_path / "lib").glob("*.exr"))
    png = tmp_path / "ramp.png"
    preview = tmp_path / "printed.exr"
    result = CliRunner().invoke(app, ["masks", "export", "ramp:x", "--out", str(png), "--dpi", "1200",
                                      "--film-t-min", "0.05", "--preview", str(preview)])
    assert result.exit_code == 0, result.output
    from mincam_sim.masks import load

    printed = load(preview)
    assert abs(printed.transmission.min() - 0.05) < 0.01 and printed.transmission.max() <= 0.9 + 1e-6
    from PIL import Image

    with Image.open(png) as im:
        assert im.size[0] == round(2e-3 / 0.0254 * 1200)
