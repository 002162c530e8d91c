"""``run_design`` called from Python: an argument of the wrong type or form is one InputError naming it and the
expected form, raised before any work (no output folder, no gradient check, no optimisation). Nothing runs here:
the run's first steps are replaced by stubs that fail the test if they are reached."""

from __future__ import annotations

import pytest

from mincam_sim.errors import ConfigError, InputError


class _WorkStarted(Exception):  # noqa: N818 - a signal, not an error
    """Raised by the stubbed first steps of a run: the arguments got past the checks."""


def _started(*args, **kwargs):
    raise _WorkStarted


@pytest.fixture
def no_work(monkeypatch):
    """The first work a design run does (tracking: the gradient check and the optimisation; scene tasks: their
    run) replaced by :func:`_started`."""
    import mincam_sim.design.gradcheck as gradcheck
    import mincam_sim.design.optimise as optimise
    from mincam_sim.design.tasks import Task

    monkeypatch.setattr(gradcheck, "check_gradients", _started)
    monkeypatch.setattr(optimise, "design", _started)
    monkeypatch.setattr(Task, "run", _started)


BAD_ARGUMENTS = [
    ({"dpi": "600"}, r"dpi must be a number from 50 to 4800 dots per inch .*got '600'"),
    ({"dpi": float("nan")}, "dpi must be a number"),
    ({"dpi": True}, "dpi must be a number"),
    ({"dpi": 10}, "dpi must be a number from 50 to 4800"),
    ({"seed": "1"}, r"seed must be an integer from 0 to 4294967295, got '1'"),
    ({"seed": 1.5}, "seed must be an integer"),
    ({"seed": -1}, "seed must be an integer"),
    ({"quick": "yes"}, "quick must be True or False, got 'yes'"),
    ({"overwrite": "no"}, "overwrite must be True or False"),
    ({"baselines": 1}, "baselines must be True or False"),
    ({"show_progress": None}, "show_progress must be True or False"),
]

TRACKING_SEQUENCES = [
    ({"train_depths_m": 0.5}, r"train_depths_m must be a non-empty list or tuple of numbers: plane depths \[m\]"),
    ({"train_depths_m": "0.5"}, "train_depths_m must be a non-empty list"),
    ({"train_depths_m": ["a"]}, "train_depths_m must be a non-empty list"),
    ({"train_depths_m": []}, "train_depths_m must be a non-empty list"),
    ({"train_depths_m": [[0.5, 0.6]]}, "train_depths_m must be a non-empty list"),
    ({"background_radiances": 0.2}, "background_radiances must be a non-empty list"),
    ({"depth_range_m": 0.5}, r"depth_range_m must be 2 numbers: \(min, max\) depths \[m\]"),
    ({"depth_range_m": (0.3, 0.5, 0.7)}, "depth_range_m must be 2 numbers"),
    ({"object_size_range_m": "ab"}, "object_size_range_m must be 2 numbers"),
    ({"contrast_range": (0.1, None)}, "contrast_range must be 2 numbers"),
]


@pytest.mark.parametrize("task", ["tracking", "counting"])
@pytest.mark.parametrize("kwargs, said", BAD_ARGUMENTS)
def test_run_design_refuses_a_bad_argument_before_any_work(tmp_path, no_work, task, kwargs, said):
    """``dpi="600"`` was numpy's TypeError ("ufunc 'isfinite' not supported"); ``quick="yes"`` started a full
    quick design."""
    out = tmp_path / "d"
    with pytest.raises(InputError, match=said):
        run(task, out, **kwargs)
    assert not out.exists()


@pytest.mark.parametrize("kwargs, said", TRACKING_SEQUENCES)
def test_run_design_refuses_a_tracking_sequence_that_is_not_a_list_of_numbers(tmp_path, no_work, kwargs, said):
    """``train_depths_m=0.5`` was "'float' object is not iterable", ``depth_range_m=0.5`` "cannot unpack
    non-iterable float object" (TypeErrors from inside make_task)."""
    from mincam_sim.design.run import make_task

    out = tmp_path / "d"
    with pytest.raises(InputError, match=said):
        run("tracking", out, **kwargs)
    assert not out.exists()
    with pytest.raises(InputError, match=said):
        make_task(True, 0, **kwargs)


def test_run_design_refuses_a_bad_task_or_folder(tmp_path, no_work):
    with pytest.raises(InputError, match="unknown design task 3: choose one of tracking, counting, depth"):
        run(3, tmp_path / "d")
    for out in (5, None, ""):
        with pytest.raises(InputError, match="out_dir must be a folder path"):
            run("tracking", out)


def test_good_arguments_reach_the_work(tmp_path, no_work):
    """The checks take what the command line and the studies pass (numpy numbers, lists for tuples)."""
    import numpy as np

    for task, kwargs in (("tracking", {"dpi": np.float64(300), "seed": np.int64(3), "quick": np.bool_(True),
                                       "depth_range_m": [0.4, 0.9], "train_depths_m": np.array([0.5, 0.6])}),
                         ("counting", {"dpi": 300, "seed": 2})):
        with pytest.raises(_WorkStarted):
            run(task, tmp_path / task, **kwargs)


def test_a_decoder_that_is_not_a_name_is_the_task_field_error():
    """``decoder=[1]`` was "unhashable type: 'list'" from the task's own check."""
    from mincam_sim.design.run import make_task

    with pytest.raises(ConfigError, match="TrackingTask.decoder must be one of eq7, learned"):
        make_task(True, 0, decoder=[1])


def run(task, out, **kwargs):
    from mincam_sim.design.run import run_design

    return run_design(task, out, **kwargs)
