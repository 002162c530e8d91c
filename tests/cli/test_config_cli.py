"""The TOML schema, its validation, and the command line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from mincam_sim.cli import app
from mincam_sim.configuration.config import EXAMPLE_TOML, ConfigError, load_config

ROOT = Path(__file__).resolve().parents[2]


def test_example_schema_is_the_default():
    cfg = load_config(EXAMPLE_TOML)
    from mincam_sim.render.solvers import ResponseMap

    assert cfg.run.solver == ResponseMap()
    assert cfg.mincam.names == ["x", "1-x"]
    assert cfg.frames.shape == (26, 144, 256)
    x, one_minus_x = cfg.mincam  # each ramp brightest on its own side: x on the right (world +x here)
    assert np.isclose(x.pose.position_m[0] - one_minus_x.pose.position_m[0], 0.033)


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
        ("[run]\nreplicates = 1", "replicates must be an integer >= 2"),
        ("[run]\nsolver = 'magic'", "solver = 'magic' is not one of"),
        ("[run]\nform = 'magic'", r"\[run\] form is the old key of the solver: use \[run\] solver"),
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
    for name in ("measurements.npz", "measurements.csv"):  # response maps: test_outputs (after the merge)
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


# --- paths resolve against the config file; values are refused, not coerced


def _png(path):
    from PIL import Image

    Image.fromarray((np.linspace(0, 255, 32)[None, :] * np.ones((32, 1))).astype(np.uint8)).save(path)


def test_config_paths_resolve_against_the_config_file(tmp_path, monkeypatch):
    sub = tmp_path / "scene"
    sub.mkdir()
    _png(sub / "m.png")
    np.save(sub / "frames.npy", np.ones((2, 18, 32)))
    (sub / "c.toml").write_text(
        "[run]\nout_dir = 'results'\n[mincam]\nlayout = 'custom'\n[[mixel]]\nmask = 'file:m.png'\n"
        "[screen]\nresolution = [32, 18]\n[frames]\nkind = 'npy'\npath = 'frames.npy'\n"
    )
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    cfg = load_config(sub / "c.toml")
    assert cfg.mincam[0].mask.shape == (32, 32)
    assert cfg.run.out_dir == sub / "results"
    assert cfg.frames.shape == (2, 18, 32)
    assert cfg.source == sub / "c.toml"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[run]\nseed = true", r"seed must be an integer >= 0, got True \(boolean\)"),
        ("[screen]\nresolution = [256.5, 144]", r"resolution\[0\] must be an integer > 0 \(a whole number"),
        ("run = 5", r"\[run\] must be a table"),
        ("[run]\nout_dir = 5", "out_dir must be a string"),
        ("[mincam]\nd_f_m = '2mm'", "d_f_m must be a number > 0 .no quotes, no units., got '2mm'"),
        ("[mincam]\nlayout = 'custom'\n[[mixel]]\nmask = 'ramp:x'\nd_f_m = '2mm'", r"\[\[mixel\]\] #1 d_f_m"),
        ("[mincam]\nlayout = 'custom'\n[mixel]\nmask = 'ramp:x'", "double brackets"),
        ("mixel = [1]\n[mincam]\nlayout = 'custom'", r"\[\[mixel\]\] #1 must be a table"),
        ("[frames]\nn = 100000000", r"n must be at most 10000000"),
        ("[mincam]\nmask_resolution = 1000000000", "mask_resolution must be at most 8192"),
    ],
)
def test_values_are_refused_not_coerced(text, message):
    with pytest.raises(ConfigError, match=message):
        load_config(text)


@pytest.mark.parametrize(
    ("content", "message"),
    [(b"", "empty file"), (b"1 2 3\n", "not a readable .npy"), (b"\x93NUMPY\x01\x00", "not a readable .npy")],
)
def test_unreadable_frame_files_are_config_errors(tmp_path, content, message):
    (tmp_path / "f.npy").write_bytes(content)
    with pytest.raises(ConfigError, match=message):
        load_config("[frames]\nkind = 'npy'\npath = 'f.npy'\n", base_dir=tmp_path)


def test_config_error_is_a_mincam_error():
    from mincam_sim.errors import MincamError

    assert issubclass(ConfigError, MincamError) and issubclass(ConfigError, ValueError)


# --- reruns into one output directory


SMALL = "[run]\nsamples_per_texel = 16\nout_dir = 'out'\n[frames]\nn = 2\n[screen]\nresolution = [32, 18]\n"
SINE = ("[mincam]\nlayout = 'custom'\n[[mixel]]\nname = 's'\nmask = {kind = 'sinusoid', omega_rad_per_m = 3000.0, "
        "a0 = 0.5, a1 = 0.5, phase_rad = %s}\n")


def _render(tmp_path, text, *extra):
    (tmp_path / "c.toml").write_text(text)
    return CliRunner().invoke(app, ["--quiet", "render", str(tmp_path / "c.toml"), *extra])


def test_cli_refuses_stale_results_when_a_mask_changes(tmp_path):
    first = _render(tmp_path, SMALL + SINE % "0.0")
    assert first.exit_code == 0, first.output
    changed = _render(tmp_path, SMALL + SINE % "1.0")  # same name and shape, other content
    assert changed.exit_code == 2
    assert "different run" in changed.output and "masks" in changed.output and "--overwrite" in changed.output
    replaced = _render(tmp_path, SMALL + SINE % "1.0", "--overwrite")
    assert replaced.exit_code == 0, replaced.output
    from mincam_sim.measurements import Measurements

    a = Measurements.load_npz(tmp_path / "out" / "measurements.npz")
    (tmp_path / "x").mkdir()
    fresh = _render(tmp_path / "x", SMALL + SINE % "1.0")  # the same config into a new directory
    assert fresh.exit_code == 0, fresh.output
    b = Measurements.load_npz(tmp_path / "x" / "out" / "measurements.npz")
    np.testing.assert_array_equal(a.irradiance_w_m2, b.irradiance_w_m2)


def test_cli_rerun_of_the_same_config_with_target_noise(tmp_path):
    text = SMALL.replace("samples_per_texel = 16", "target_rel_stderr = 0.05")
    first = _render(tmp_path, text)
    assert first.exit_code == 0, first.output
    second = _render(tmp_path, text)
    assert second.exit_code == 0, second.output
    assert "shown again without rendering" in second.output
    assert first.stdout == second.stdout


def test_cli_refuses_an_out_dir_another_process_writes(tmp_path):
    import subprocess
    import sys

    code = ("import sys, time; from mincam_sim.storage.store import lock_out_dir; l = lock_out_dir(sys.argv[1]); "
            "print('locked', flush=True); time.sleep(60)")
    holder = subprocess.Popen([sys.executable, "-c", code, str(tmp_path / "out")], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        result = _render(tmp_path, SMALL)
        assert result.exit_code == 2
        assert f"PID {holder.pid}" in result.output and "in use by another run" in result.output
    finally:
        holder.kill()
        holder.wait()
        holder.stdout.close()


def test_shipped_reproduce_config_loads_and_bad_ones_name_the_field(tmp_path):
    from mincam_sim.errors import ConfigError
    from mincam_sim.experiments import REGISTRY, load_reproduce_config

    setup, params = load_reproduce_config(ROOT / "scenes" / "experiments" / "reproduce.toml")
    assert setup.spacing_m == 0.033 and set(params) == set(REGISTRY)
    assert params["tracking"].frames_per_toy == 100
    quick_setup, quick = load_reproduce_config(None, quick=True)
    assert quick_setup.quick and quick["tracking"].frames_per_toy < params["tracking"].frames_per_toy
    _, custom = load_reproduce_config({"tracking": {"frames_per_toy": 300}}, quick=True)
    assert custom["tracking"].frames_per_toy == 300  # a section applies after the quick defaults
    for doc, words in [({"setup": {"spacing_m": "3cm"}}, ("[setup] spacing_m", "number")),
                       ({"tracking": {"frames_per_toy": 2.5}}, ("[tracking] frames_per_toy", "integer")),
                       ({"intrusion": {"band_m": -1.0}}, ("[intrusion]", "band_m")),
                       ({"speed": {"bogus": 1}}, ("[speed]", "bogus", "allowed keys")),
                       ({"setp": {}}, ("[setp]", "allowed sections")),
                       ({"tracking": {"toys": "robot"}}, ("[tracking] toys", "list"))]:
        with pytest.raises(ConfigError) as err:
            load_reproduce_config(doc)
        assert all(w in str(err.value) for w in words), (doc, str(err.value))


def test_results_table_prints_unscored_experiments(capsys):
    """An experiment with no scored frame has None errors: the table prints '-' rather than crashing."""
    from mincam_sim.cli import _print_table

    paper = {"max_error_pct": 7.1, "avg_error_pct": 2.0}
    _print_table({"intrusion": {"max_error_pct": None, "avg_error_pct": None, "n": 0, "paper": paper},
                  "tracking": {"max_error_pct": 3.25, "avg_error_pct": 1.0, "n": 9, "paper": paper}})
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].split()[:4] == ["intrusion", "-", "/", "-"]
    assert lines[2].split()[:4] == ["tracking", "3.25", "/", "1.00"]


def test_a_refused_run_leaves_no_folder_it_created(tmp_path):
    """A world whose mesh has no triangle is refused after ``render`` created (and locked) its output folder, two
    levels deep: the folders go again; a folder that was there before stays."""
    (tmp_path / "m.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    (tmp_path / "s.xml").write_text('<scene version="3.0.0"><shape type="obj" id="toy"><string name="filename" '
                                    'value="m.obj"/><boolean name="face_normals" value="true"/></shape>'
                                    '<emitter type="constant"/></scene>')
    body = '[world]\nscene = "s.xml"\n[[world.mover]]\nid = "toy"\noffsets_m = [[0, 0, 0]]\n'
    for out, existed in (("new/deeper/out", False), ("there", True)):
        if existed:
            (tmp_path / out).mkdir()
        config = tmp_path / "c.toml"
        config.write_text(f'[run]\nout_dir = "{out}"\n' + body)
        result = CliRunner().invoke(app, ["render", str(config)])
        assert result.exit_code == 2 and "a mesh without a single triangle" in result.output
        assert (tmp_path / out).is_dir() == existed and (tmp_path / "new").exists() is False
