"""``render`` run again into its output directory: a damaged ``measurements.npz`` is rebuilt (no traceback, no
"aborted"), response maps a killed run never wrote are written, ``--overwrite`` leaves none of the replaced run's
maps; and an ``EOFError`` that reaches the command line is a bug's traceback, never "error: aborted"."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from typer.testing import CliRunner

CONFIG = """[run]
samples_per_texel = 8
out_dir = "out"
[screen]
resolution = [32, 18]
[frames]
n = 2
"""
APERTURE = CONFIG.replace("samples_per_texel = 8", 'solver = "aperture"\nspp = 256')
MAPS = ("out/response_maps/response_x.exr", "out/response_maps/response_1-x.exr", "out/response_maps.png")


def _cli(argv: list[str], cwd: Path):
    from mincam_sim.cli import app

    old = Path.cwd()
    os.chdir(cwd)
    try:
        return CliRunner().invoke(app, argv)
    finally:
        os.chdir(old)


def _stderr(result) -> str:
    try:
        return result.stderr
    except ValueError:  # older click: stderr mixed into output
        return result.output


def _render(tmp_path: Path, *extra: str, config: str = "c.toml"):
    result = _cli(["--quiet", "render", config, *extra], tmp_path)
    assert result.exit_code == 0, (result.exception, _stderr(result))
    return result


def _table(output: str) -> list[str]:
    """The printed measurements (the lines after the header), without the line naming the figures."""
    return [line for line in output.splitlines() if not line.startswith("# written to")]


@pytest.mark.parametrize("damage", ["empty", "cut"])
def test_a_damaged_measurements_npz_is_rebuilt_on_a_rerun(damage, tmp_path):
    """A 0-byte file was "error: aborted" (rc 1), one cut short a BadZipFile traceback: now the rerun rebuilds it
    from the run's store, shows the same numbers and says what it did."""
    (tmp_path / "c.toml").write_text(CONFIG)
    first = _render(tmp_path)
    path = tmp_path / "out" / "measurements.npz"
    data = path.read_bytes()
    path.write_bytes(b"" if damage == "empty" else data[: len(data) // 2])
    again = _render(tmp_path)
    assert "measurements.npz is damaged or unreadable" in _stderr(again)
    assert "aborted" not in _stderr(again) and "Traceback" not in _stderr(again)
    assert _table(again.stdout) == _table(first.stdout)
    assert _render(tmp_path).stdout == first.stdout and "damaged" not in _stderr(_render(tmp_path))


def test_response_maps_a_killed_run_never_wrote_are_written_on_the_rerun(tmp_path):
    (tmp_path / "c.toml").write_text(CONFIG)
    _render(tmp_path)
    for name in MAPS[1:]:
        (tmp_path / name).unlink()
    again = _render(tmp_path)
    assert "without rendering" in _stderr(again) and "making the response maps again" in _stderr(again)
    assert all((tmp_path / name).stat().st_size > 0 for name in MAPS)
    assert "figures: measurements.png, response_maps.png" in again.stdout
    quiet = _render(tmp_path)  # complete: nothing to make again, the figure still listed
    assert "response maps again" not in _stderr(quiet)
    assert "figures: measurements.png, response_maps.png" in quiet.stdout


def test_overwrite_with_another_solver_leaves_none_of_the_replaced_runs_maps(tmp_path):
    (tmp_path / "c.toml").write_text(CONFIG)
    (tmp_path / "a.toml").write_text(APERTURE)
    _render(tmp_path)
    assert all((tmp_path / name).is_file() for name in MAPS)
    replaced = _render(tmp_path, "--overwrite", config="a.toml")
    assert not any((tmp_path / name).exists() for name in MAPS)
    assert not (tmp_path / "out" / "response_maps").exists()
    assert "(figures: measurements.png)" in replaced.stdout
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [
        ".mincam.lock", "measurements", "measurements.csv", "measurements.npz", "measurements.png"]


@pytest.mark.parametrize("debug", [False, True])
def test_an_eoferror_from_inside_a_command_is_a_bugs_traceback_not_an_abort(debug, monkeypatch, capsys):
    """click answers an EOFError with "Aborted" (an input prompt at the end of stdin); no command here prompts,
    so one that reaches the command line is a reader's bug: it propagates with its traceback (exit code 1),
    with or without --debug, and is never called "aborted"."""
    import mincam_sim.configuration.toml_files as toml_files
    from mincam_sim import cli

    def torn(*args, **kwargs):
        raise EOFError("No data left in file")

    monkeypatch.setattr(toml_files, "read_document", torn)
    with pytest.raises(EOFError, match="No data left in file") as caught:
        cli.main([*(["--debug"] if debug else []), "render", "c.toml"])
    assert any(entry.name == "torn" for entry in caught.traceback)  # raised as it was, where it was
    assert "aborted" not in capsys.readouterr().err.lower()
