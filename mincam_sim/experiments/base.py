"""What an experiment is: a name, the paper section and numbers it reproduces, a parameters dataclass (every
default in one place, quick-mode overrides beside it), ``calibrate`` / ``scene`` / ``run`` returning a typed
:class:`ExperimentResult`, and how one point of a study of it runs (``Experiment.study_target``: its
parameters, metrics and typical seconds, declared here once beside the reproduction)."""

from __future__ import annotations

import dataclasses
import tempfile
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from mincam_sim.configuration.schema import dataclass_from_section
from mincam_sim.experiments.setup import Setup
from mincam_sim.experiments.study_targets import StudyExperiment, figures_not_saved, numeric_details

#: Set-up fields that are no study parameter: the study's own seed and quick mode, and non-numeric fields.
_SETUP_NOT_STUDIED = frozenset({"seed", "quick", "screen_resolution", "dp_solver"})


def _scalar_fields(obj) -> dict:
    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj) if f.init
            and isinstance(getattr(obj, f.name), int | float) and not isinstance(getattr(obj, f.name), bool)}


@dataclass(frozen=True)
class PaperNumbers:
    """Error rates the paper reports for an experiment [% of the calibrated range, or of the true speed]."""

    max_error_pct: float
    avg_error_pct: float

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclass
class ExperimentResult:
    """An experiment's outcome: its headline error rates (``None`` for studies without one), the paper's
    numbers, everything else it measured (``details``: JSON-able) and its wall time [s]."""

    name: str
    max_error_pct: float | None
    avg_error_pct: float | None
    n: int | None
    paper: PaperNumbers | None
    details: dict = field(default_factory=dict)
    seconds: float = 0.0

    def as_dict(self) -> dict:
        """Flat JSON form (the ``results.json`` entry): details, then the headline numbers and the paper's."""
        out = dict(self.details)
        if self.max_error_pct is not None or self.n is not None:
            out.update(max_error_pct=self.max_error_pct, avg_error_pct=self.avg_error_pct, n=self.n)
        if self.paper is not None:
            out["paper"] = self.paper.as_dict()
        out["seconds"] = self.seconds
        return out

    @classmethod
    def from_rates(cls, name: str, rates: dict, paper: PaperNumbers | None, details: dict) -> ExperimentResult:
        """From an error-rate dict (:func:`~mincam_sim.estimation.metrics.error_rates`) plus details; rates of ``None``
        (nothing could be scored) stay ``None`` and ``n`` is then 0."""
        def number(key: str) -> float | None:
            return None if rates.get(key) is None else float(rates[key])

        return cls(name, number("max_error_pct"), number("avg_error_pct"), int(rates.get("n") or 0), paper,
                   {**{k: v for k, v in rates.items() if k not in ("max_error_pct", "avg_error_pct", "n")},
                    **details})


class Experiment(ABC):
    """Base of the paper's experiments (and of studies built from them).

    Subclasses set ``name``, ``paper_section``, ``paper`` (or None), ``Params`` (a frozen dataclass whose
    defaults are the full-mode values), ``quick_overrides`` (the fields ``--quick`` changes) and
    ``seed_offset`` (separates the experiments' random streams); as a study target (``mincam-sim study``),
    ``study_metrics`` (what a point returns), ``study_seconds`` (the rough wall time of one point [s], quick and
    full) and, where a point is not one run of :meth:`run`, :meth:`study_parameters` and :meth:`study_point`.
    """

    name: ClassVar[str]
    paper_section: ClassVar[str]
    paper: ClassVar[PaperNumbers | None] = None
    in_paper: ClassVar[bool] = True
    Params: ClassVar[type]
    quick_overrides: ClassVar[dict[str, Any]] = {}
    seed_offset: ClassVar[int] = 0
    #: Raise with any change to the code that changes the numbers of :meth:`run` for the same set-up and
    #: parameters: part of a reproduction's parameters key, so an older result is recomputed, not reused.
    version: ClassVar[int] = 1
    study_metrics: ClassVar[tuple[str, ...]] = ()
    study_seconds: ClassVar[tuple[float, float]] = (60.0, 1800.0)
    #: Raise with any change to the code of :meth:`study_point` that changes its numbers for the same parameters
    #: (it is part of a study's identity: a store of an older point is then refused, not reused).
    study_version: ClassVar[int] = 1

    def params(self, quick: bool = False, table: dict | None = None) -> Any:
        """The parameters: defaults, the quick-mode overrides if ``quick``, then a TOML ``[name]`` table
        (validated: unknown keys, wrong types and out-of-range values are :class:`~mincam_sim.errors.ConfigError`)."""
        params = self.Params()
        if quick:
            params = dataclasses.replace(params, **self.quick_overrides)
        if table:
            params = dataclass_from_section(self.name, table, params)
        return params

    def rng(self, setup: Setup) -> np.random.Generator:
        """This experiment's random stream: the set-up's seed plus the experiment's own ``seed_offset``."""
        return np.random.default_rng(setup.seed + self.seed_offset)

    def streams(self, setup: Setup, purposes: tuple[str, ...]) -> dict[str, np.random.Generator]:
        """Independent random streams, one per purpose (children of the seed sequence of the set-up's seed plus
        ``seed_offset``): what one purpose draws (e.g. the calibration's sensor noise, whose amount depends on
        how many squares are swept) never shifts another's numbers (e.g. the table's printed texture)."""
        children = np.random.SeedSequence(setup.seed + self.seed_offset).spawn(len(purposes))
        return {name: np.random.default_rng(child) for name, child in zip(purposes, children, strict=True)}

    def calibrate(self, setup: Setup, params: Any, rng: np.random.Generator, out_dir: Path) -> Any:
        """Fit what maps measurements to the quantity of interest (``None`` if the estimator needs nothing)."""
        return None

    @abstractmethod
    def scene(self, setup: Setup, params: Any, rng: np.random.Generator) -> Any:
        """The scene content the experiment renders."""

    @abstractmethod
    def run(self, setup: Setup, params: Any, out_dir: Path, show_progress: bool = False) -> ExperimentResult:
        """Calibrate, render, estimate and score; write plots and data into ``out_dir``."""

    # ------------------------------------------------------------------------------------- as a study target
    def study_parameters(self) -> dict:
        """A study point's parameters (name -> full-mode default): by default every scalar field of the set-up
        (:class:`~.setup.Setup`, but its seed and quick mode) and of ``Params``."""
        setup = {k: v for k, v in _scalar_fields(Setup()).items() if k not in _SETUP_NOT_STUDIED}
        own = _scalar_fields(self.Params())
        clash = sorted(set(setup) & set(own))
        if clash:  # a programming error: parameters must name one thing
            raise RuntimeError(f"experiment {self.name}: parameters {clash} are both set-up and experiment fields")
        return {**setup, **own}

    def study_inputs(self, params: dict, seed: int, quick: bool) -> tuple[Setup, Any]:
        """The set-up and parameters of a study point (validated by their dataclasses: a bad value is a
        ValueError)."""
        setup_keys = set(_scalar_fields(Setup())) - _SETUP_NOT_STUDIED
        setup = dataclasses.replace(Setup(quick=quick, seed=seed),
                                    **{k: v for k, v in params.items() if k in setup_keys})
        own = dataclasses.replace(self.params(quick), **{k: v for k, v in params.items() if k not in setup_keys})
        return setup, own

    def study_check(self, params: dict, quick: bool) -> None:
        """Refuse a study point's parameters as :meth:`study_point` would, before any point is computed: the
        set-up's and the parameters' own checks (the registry adds a reproduce file's, ``check_reproduce`` of
        ``experiments/input_checks.py``)."""
        self.study_inputs(params, 0, quick)

    def study_point(self, params: dict, seed: int, quick: bool) -> dict:
        """One study point: :meth:`run` on the set-up and parameters ``params`` gives (the others at their
        quick or full defaults), its figures not drawn; the numbers of its result entry as metrics."""
        setup, own = self.study_inputs(params, seed, quick)
        with tempfile.TemporaryDirectory(prefix=f"study_{self.name}_") as tmp, figures_not_saved():
            result = self.run(setup, own, Path(tmp)).as_dict()
        return numeric_details(result)

    def study_target(self) -> StudyExperiment:
        """This experiment as a study target (``[study] experiment = "<name>"``)."""
        ref = {"name": self.name} if self.study_version == 1 else {"name": self.name, "version": self.study_version}
        return StudyExperiment(name=self.name, description=self.study_description(),
                               parameters=self.study_parameters(), metrics=self.study_metrics,
                               point=self.study_point, seconds_per_point=self.study_seconds, ref=ref,
                               check=self.study_check)

    def study_description(self) -> str:
        return f"the {self.name} experiment (paper Sec. {self.paper_section}) per point"
