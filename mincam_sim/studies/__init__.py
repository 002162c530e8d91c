"""Studies at scale: a grid (or list, or random sample) of any experiment's parameters, of a render config's
keys or of the mask design, run on ``dask.distributed``, stored as an xarray Dataset in Zarr with a standard
error beside every metric; resumable, verified on reuse, the same numbers on 1 or N workers."""

from .plots import plot_study
from .points import StudyExperiment, study_target, target_names, unit_of
from .runner import compute_point, point_seed, point_seeds, run_study
from .spec import StudySpec, load_study

__all__ = ["StudyExperiment", "StudySpec", "compute_point", "load_study", "plot_study",
           "point_seed", "point_seeds", "run_study", "study_target", "target_names", "unit_of"]
