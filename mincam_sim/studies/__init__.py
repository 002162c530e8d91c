"""Studies at scale: a grid (or list, or random sample) of any experiment's parameters, of a render config's
keys or of the mask design, run on ``dask.distributed``, stored as an xarray Dataset in Zarr with a standard
error beside every metric; resumable, verified on reuse, the same numbers on 1 or N workers.

Files:

* ``cli.py``: what ``mincam-sim study run STUDY.toml [--workers N | --scheduler ADDRESS] [--out DIR] [--quick]``
  does.
* ``cluster.py``: where the points run and how a study stops: the cores this process may use (``--workers``
  capped), an existing scheduler checked within seconds, an embedded cluster that Ctrl-C stops at once.
* ``plots.py``: plots drawn from a study's xarray Dataset: error bars from ``<metric>_stderr``, axes in readable
  units.
* ``runner.py``: run a study's points on ``dask.distributed`` and keep the results as an xarray Dataset in Zarr.
* ``spec.py``: a study file: which experiment, which parameter points, which metrics (TOML, read like a render
  config).
"""

from mincam_sim.experiments.registry import study_target, target_names
from mincam_sim.experiments.study_targets import StudyExperiment, unit_of
from mincam_sim.studies.plots import plot_study
from mincam_sim.studies.runner import StudyInterrupted, compute_point, point_seed, point_seeds, run_study
from mincam_sim.studies.spec import StudySpec, load_study

__all__ = ["StudyExperiment", "StudyInterrupted", "StudySpec", "compute_point", "load_study", "plot_study",
           "point_seed", "point_seeds", "run_study", "study_target", "target_names", "unit_of"]
