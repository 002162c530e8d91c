"""The paper's experiments reproduced in simulation, as a framework: each experiment (:mod:`.base`) has its
parameters dataclass, ``calibrate`` / ``scene`` / ``run`` and a typed result; :mod:`.registry` lists them and
runs them (``reproduce(names, setup, out_dir)``).

Along the data path: :mod:`.setup` (the shared set-up) -> :mod:`.layouts` (mincam designs) ->
:mod:`.screen_calibration` -> :mod:`.tabletop_world` and :mod:`.ground_truth` -> :mod:`.pipeline` (render,
read out, estimate, score) -> the experiments (:mod:`.intrusion`, :mod:`.tracking`, :mod:`.speed`,
:mod:`.spacing`).
Files:

* ``base.py``: what an experiment is: parameters, ``calibrate`` / ``scene`` / ``run``, a typed result, its study
  target.
* ``setup.py``: the set-up shared by the experiments: geometry, sensor, screen and sampling defaults.
* ``layouts.py``: the paper's mincam designs (the intrusion pair, the tracking cross, the speed mixel).
* ``screen_calibration.py``: calibration on the 50" screen (paper Sec. 4.1.1, 4.2.1).
* ``tabletop_world.py``: the tabletop of the intrusion and tracking experiments as a world ``Simulation``.
* ``ground_truth.py``: the ground truth: a pinhole camera at the mincam's centre looking straight down.
* ``pipeline.py``: render each frame's change, read it out, detect, estimate, score against the ground truth.
* ``intrusion.py``: paper Sec. 4.1, 1D intrusion detection with two mixels.
* ``tracking.py``: paper Sec. 4.2, tracking wind-up toys with four mixels.
* ``speed.py``: paper Sec. 4.3, speed from one mixel with a sinusoid mask.
* ``display_timing.py``: how a mixel samples a video shown on a display (refresh, hold, exposure, clock).
* ``spacing.py``: the spacing study: intrusion error against mixel spacing and depth.
* ``ideal_model.py``: the pair and the cross calibrated on the idealised model (``DotProduct``), tested on the
  physics.
* ``registry.py``: the one registry of what ``reproduce``, ``study`` and ``demo`` run, and its runner.
* ``reproduce_file.py``: the reproduce file (``mincam-sim reproduce --config FILE``).
* ``input_checks.py``: the values the experiments would refuse only deep inside, refused up front (by
  ``reproduce`` and for every study point).
* ``study_targets.py``: what a study target is, and the targets that are no experiment of the paper.
"""

from mincam_sim.experiments.base import Experiment, ExperimentResult, PaperNumbers
from mincam_sim.experiments.registry import EXPERIMENTS, REGISTRY, experiment, load_reproduce_config, reproduce
from mincam_sim.experiments.setup import Setup

__all__ = ["EXPERIMENTS", "REGISTRY", "Experiment", "ExperimentResult", "PaperNumbers", "Setup", "experiment",
           "load_reproduce_config", "reproduce"]
