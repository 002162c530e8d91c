"""``mincam-sim design``: a bad size or geometry is one line ``error: ...`` naming the option or the ``[tracking]``
key and its range, exit code 2, before anything runs or is written; the ``[tracking]`` seed of a ``--config``
file reaches the run, and an explicit ``--seed`` wins over it.

No design runs here: the run itself (``run_design``, a scene task's ``Task.run``) is replaced by a stub that
stops the command where the work would start, so a value that is not refused fails fast instead of running.
"""

from __future__ import annotations

import pickle
from dataclasses import replace
from pathlib import Path

import pytest

from mincam_sim.design import tracking as tr
from mincam_sim.design.scene_tasks import Sizes
from mincam_sim.errors import ConfigError

MAX_SEED = 2**32 - 1  # the design runs' seeds: unsigned 32-bit integers


class _RunStarted(Exception):  # noqa: N818 - a signal, not an error
    """Raised by the stubbed run: the command got past its checks (carries the run's arguments)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__("the design run started")
        self.kwargs = kwargs


def _started(*args, **kwargs):
    raise _RunStarted(*args, **kwargs)


@pytest.fixture
def no_run(monkeypatch):
    """Every design task's run replaced by :func:`_started`."""
    import mincam_sim.design
    from mincam_sim.design.tasks import Task

    monkeypatch.setattr(mincam_sim.design, "run_design", _started)
    monkeypatch.setattr(Task, "run", _started)


def _design(args: list[str]):
    from typer.testing import CliRunner

    from mincam_sim.cli import app

    return CliRunner().invoke(app, ["--quiet", "design", *args])


def _one_line_error(result, *words: str) -> str:
    """The single ``error:`` line of a refused command (exit code 2, no traceback), containing ``words``."""
    assert not isinstance(result.exception, _RunStarted), "the design run started instead of refusing the input"
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert result.exit_code == 2, result.output
    assert len(lines) == 1 and lines[0].startswith("error: "), result.output
    assert "Traceback" not in result.output
    for word in words:
        assert word in lines[0], (word, lines[0])
    return lines[0]


# ------------------------------------------------------------------------------------------------ [tracking] seed


def _config(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "design.toml"
    path.write_text("[tracking]\n" + body + "\n")
    return path


def test_config_seed_reaches_the_run_and_an_explicit_seed_wins(tmp_path, no_run):
    """A ``[tracking] seed`` is the run's seed (it was passed twice: a TypeError); ``--seed`` wins over it."""
    cfg = _config(tmp_path, "seed = 5")
    r = _design(["tracking", "--quick", "--config", str(cfg), "--out", str(tmp_path / "a")])
    assert isinstance(r.exception, _RunStarted), r.output
    assert r.exception.kwargs["seed"] == 5
    r = _design(["tracking", "--quick", "--config", str(cfg), "--seed", "7", "--out", str(tmp_path / "b")])
    assert isinstance(r.exception, _RunStarted), r.output
    assert r.exception.kwargs["seed"] == 7
    r = _design(["tracking", "--quick", "--out", str(tmp_path / "c")])
    assert isinstance(r.exception, _RunStarted) and r.exception.kwargs["seed"] == 0


def test_bad_config_seed_and_bad_seed_option_are_named(tmp_path, no_run):
    cfg = _config(tmp_path, f"seed = {MAX_SEED + 1}")
    _one_line_error(_design(["tracking", "--quick", "--config", str(cfg), "--out", str(tmp_path / "a")]),
                    "[tracking] seed", f"0 to {MAX_SEED}")
    _one_line_error(_design(["tracking", "--quick", "--seed", str(2**64), "--out", str(tmp_path / "b")]),
                    "--seed", f"0 to {MAX_SEED}")
    _one_line_error(_design(["depth", "--quick", "--seed", "-1", "--out", str(tmp_path / "c")]), "--seed")
    assert not any((tmp_path / d).exists() for d in "abc")


# ------------------------------------------------------------------------------------------------ [tracking] sizes


BAD_SIZES = [
    ("iterations", "0"), ("iterations", "1000000000000"), ("learning_rate", "-1.0"), ("learning_rate", "11.0"),
    ("frames_per_depth", "0"), ("strata", "0"), ("grid", "0"), ("grid", "1"), ("eval_depths", "0"),
    ("eval_frames_per_depth", "0"), ("screen_texels", "16"), ("samples_per_texel", "2"), ("calibration_grid", "5"),
    ("suite_frames", "0"), ("suite_frames", "3"), ("suite_texels", "16"), ("suite_samples_per_texel", "0"),
]


@pytest.mark.parametrize("field, value", BAD_SIZES)
def test_config_size_out_of_range_is_one_line_naming_key_and_range(tmp_path, no_run, field, value):
    """Each numeric field of the task is refused up front, naming ``[tracking] field`` and its range (they
    crashed later with an IndexError, a TypeError, Dr.Jit's or the calibration's error, or ran unbounded)."""
    cfg = _config(tmp_path, f"{field} = {value}")
    out = tmp_path / "out"
    line = _one_line_error(_design(["tracking", "--quick", "--config", str(cfg), "--out", str(out)]),
                           f"[tracking] {field} must be")
    assert " to " in line or "<=" in line  # the allowed range
    assert not out.exists()


def test_too_few_training_frames_for_the_decoder_is_named(tmp_path, no_run):
    cfg = _config(tmp_path, "train_depths_m = [0.5]\nframes_per_depth = 16")
    _one_line_error(_design(["tracking", "--quick", "--config", str(cfg), "--out", str(tmp_path / "o")]),
                    "[tracking] frames_per_depth", "at least 20 training frames")


# ------------------------------------------------------------------------------------------------ geometry, any task


@pytest.mark.parametrize("task", ["counting", "depth", "tracking"])
@pytest.mark.parametrize("option, value", [("--spacing-m", "-1"), ("--spacing-m", "0"), ("--spacing-m", "100"),
                                           ("--d-f-m", "0"), ("--d-f-m", "1")])
def test_geometry_out_of_range_is_refused_before_the_lock(tmp_path, no_run, task, option, value):
    """Every task refuses the same geometry with the same words, naming the option, before its output folder
    (and ``.mincam.lock``) exists; counting and depth failed after the start on an internal name."""
    out = tmp_path / "out"
    line = _one_line_error(_design([task, "--quick", option, value, "--out", str(out)]), f"{option} must be")
    from mincam_sim.design import checks

    rule = checks.SHARED[option.lstrip("-").replace("-", "_")].rule()
    assert rule in line
    assert not out.exists()


def test_film_option_against_file_names_both(tmp_path, no_run):
    cfg = _config(tmp_path, "film_t_max = 0.5")
    _one_line_error(_design(["tracking", "--quick", "--config", str(cfg), "--film-t-min", "0.6", "--out",
                             str(tmp_path / "o")]), "--film-t-min and [tracking] film_t_max")


# ------------------------------------------------------------------------------------------------ the records


def test_task_minima_work_and_one_below_is_refused():
    """The smallest allowed sizes construct (the run works with them: tests/design), one less is refused with a
    ConfigError naming the record's field; the shared geometry check is one for every task's record."""
    from mincam_sim.design import checks

    base = replace(tr.TrackingTask.quick(), train_depths_m=(0.5,) * 20, frames_per_depth=1)  # 20 frames: the minimum
    for field, allowed in tr.size_ranges().items():
        replace(base, **{field: allowed.low if allowed.integer else allowed.high})
        below = int(allowed.low) - 1 if allowed.integer else allowed.low
        with pytest.raises(ConfigError, match=rf"TrackingTask\.{field} must be"):
            replace(base, **{field: below})
    for record in (base, Sizes()):
        with pytest.raises(checks.FieldError) as err:
            replace(record, spacing_m=-1.0)
        assert err.value.rule == checks.SHARED["spacing_m"].rule()
    err = pytest.raises(checks.FieldError, replace, base, iterations=0).value
    assert str(pickle.loads(pickle.dumps(err))) == str(err)


def test_texel_and_calibration_minima_match_the_screens():
    """The texel minima are the coarsest displays whose texels are no larger than a calibration square (the
    screens of evaluate.py and suite.py), and the calibration minimum the first grid with >= 10 squares."""
    from mincam_sim.design.evaluate import _screen
    from mincam_sim.design.suite import suite_screen

    ranges = tr.size_ranges()
    for field, screen in (("screen_texels", _screen), ("suite_texels", suite_screen)):
        n = int(ranges[field].low)
        assert screen(tr.CALIBRATION_DEPTH_M, n).width_m / n <= tr.CALIBRATION_SQUARE_M + 1e-12
        assert screen(tr.CALIBRATION_DEPTH_M, n - 1).width_m / (n - 1) > tr.CALIBRATION_SQUARE_M
    n = int(ranges["calibration_grid"].low)
    assert len(tr.calibration_positions(n)) >= 10 > len(tr.calibration_positions(n - 1))


def test_dpi_whose_print_sheet_is_too_large_is_refused_before_the_output_folder(tmp_path, no_run):
    """The print sheet, written last, is checked with the other inputs: the output folder is not created."""
    out = tmp_path / "out"
    _one_line_error(_design(["tracking", "--quick", "--dpi", "4800", "--out", str(out)]), "print sheet", "dpi")
    assert not out.exists()
