"""Studies at scale: a grid (or list, or random sample) of an experiment's parameters, run on
``dask.distributed``, stored as an xarray Dataset in Zarr, resumable, the same numbers on 1 or N workers."""

from .plots import plot_study
from .points import STUDY_EXPERIMENTS, StudyExperiment
from .runner import compute_point, point_seed, run_study
from .spec import StudySpec, load_study

__all__ = ["STUDY_EXPERIMENTS", "StudyExperiment", "StudySpec", "compute_point", "load_study", "plot_study",
           "point_seed", "run_study"]
