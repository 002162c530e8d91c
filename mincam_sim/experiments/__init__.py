"""The paper's experiments reproduced in simulation, as a framework: each experiment (:mod:`.base`) has its
parameters dataclass, ``calibrate`` / ``scene`` / ``run`` and a typed result; :mod:`.registry` lists them and
runs them (``reproduce(names, setup, out_dir)``).

Along the data path: :mod:`.setup` (the shared set-up) -> :mod:`.layouts` (mincam designs) ->
:mod:`.screen_calibration` -> :mod:`.tabletop_world` and :mod:`.ground_truth` -> :mod:`.pipeline` (render,
read out, estimate, score) -> the experiments (:mod:`.intrusion`, :mod:`.tracking`, :mod:`.speed`,
:mod:`.spacing`).
"""

from .base import Experiment, ExperimentResult, PaperNumbers
from .registry import EXPERIMENTS, REGISTRY, experiment, load_reproduce_config, reproduce
from .setup import Setup

__all__ = ["EXPERIMENTS", "REGISTRY", "Experiment", "ExperimentResult", "PaperNumbers", "Setup", "experiment",
           "load_reproduce_config", "reproduce"]
