"""The registry of design tasks: each task is a record of data (its scene distribution, its target, its metric
and that metric's direction, its decoder family, its held-out suite and its hand design where one exists) and
the run that trains masks for it. ``mincam-sim design TASK`` runs any registered task.

* ``tracking``: one object on a plane (:mod:`.tracking`; its run is :func:`mincam_sim.design.run.run_design`'s
  own, with the physical response-map suite of :mod:`.suite`).
* ``counting`` (:mod:`.counting`) and ``depth`` (:mod:`.depth`): :class:`~.scene_tasks.TaskSpec` records run by
  :func:`~.scene_run.run_scene_task`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from mincam_sim.design.counting import COUNTING
from mincam_sim.design.depth import DEPTH
from mincam_sim.design.scene_tasks import TaskSpec


@dataclass(frozen=True)
class Task:
    """A registered design task.

    Attributes
    ----------
    name : str
        The CLI's ``TASK``.
    scenes : str
        The training scene distribution, in words.
    target : str
        What the decoder answers.
    metric : str
        The suite's metric (``suite.summary.metric``) and ``lower_is_better`` its direction.
    decoder : str
        The decoder family.
    suite : tuple of str
        Names of the held-out cases.
    hand : str or None
        The hand design the task is compared with, where one exists.
    spec : TaskSpec or None
        The data of a scene task (None for tracking, whose data is :class:`~.tracking.TrackingTask`).
    """

    name: str
    scenes: str
    target: str
    metric: str
    lower_is_better: bool
    decoder: str
    suite: tuple[str, ...]
    hand: str | None
    spec: TaskSpec | None = None

    def run(self, out_dir, quick: bool = False, seed: int = 0, show_progress: bool = False,
            overwrite: bool = False, baselines: bool = True, **overrides) -> dict:
        """Run the task's design into ``out_dir``; return its ``design.json`` dict."""
        from mincam_sim.design.scene_run import run_scene_task

        if self.spec is None:
            raise ValueError(f"task {self.name!r} runs through mincam_sim.design.run.run_design")
        return run_scene_task(self.spec, out_dir, quick=quick, seed=seed, show_progress=show_progress,
                              overwrite=overwrite, baselines=baselines, **overrides)


def _scene_task(spec: TaskSpec) -> Task:
    from mincam_sim.design.scene_design import HAND

    return Task(spec.name, spec.description, spec.target, spec.metric, spec.lower_is_better, spec.decoder_family,
                tuple(c.name for c in spec.suite), HAND.get(spec.name), spec)


def _tracking() -> Task:
    from mincam_sim.design.suite import case_names

    return Task("tracking", "one or two objects (squares, bars) 1-15 cm at 0.35-0.7 m on black or grey planes",
                "centroid of the change (normalised field coordinates)", "avg_error_pct", True,
                "cubic polynomial of the four normalised changes (learned) / Eq. 7 with cubic calibration (hand)",
                tuple(case_names()), "the paper's ramps (cross layout), Eq. 7 and a cubic calibration")


REGISTRY: dict[str, Callable[[], Task]] = {"tracking": _tracking, "counting": lambda: _scene_task(COUNTING),
                                           "depth": lambda: _scene_task(DEPTH)}
TASK_NAMES = tuple(REGISTRY)


def get_task(name: str) -> Task:
    """The registered task ``name`` (ValueError naming the choices otherwise)."""
    if name not in REGISTRY:
        raise ValueError(f"unknown design task {name!r}: choose one of {', '.join(TASK_NAMES)}")
    return REGISTRY[name]()


__all__ = ["REGISTRY", "TASK_NAMES", "Task", "get_task"]
