"""What one study point computes, read from the experiment registry (:mod:`mincam_sim.experiments.registry`).

Each experiment of the registry declares there, beside its reproduction, how one study point of it runs: its
parameters with defaults (units from the names), the metrics it returns and a rough cost per point (for the
grid-size refusal); a point function ``point(params, seed, quick) -> {metric: value}`` (plain floats) is a pure
function of its parameters and seed, so a point gives the same numbers on any worker, in any order.

Targets (:func:`study_target`):

* ``spacing`` -- the spacing experiment's own code, one (spacing, calibration depth, depth, sensor) per point,
  with a noisy read-out beside the noiseless one;
* every other experiment of :data:`mincam_sim.experiments.REGISTRY` (``intrusion``, ``tracking``, ``speed``):
  any scalar field of :class:`~mincam_sim.experiments.Setup` or of the experiment's parameters dataclass is a
  parameter; the metrics are the experiment's headline numbers and its numeric details;
* ``render`` -- a render config (``[study] config = "file.toml"``): any numeric key as ``section.key``
  (``mincam.d_f_m``, ``screen.distance_m``, ``frames.square_m`` ...); metrics per mixel;
* ``design`` -- the mask design task (``mincam-sim design tracking``) over its printer resolution.
"""

from __future__ import annotations

from ..experiments.registry import study_target, target_names
from ..experiments.study_targets import PointFunction, StudyExperiment, render_target, unit_of

__all__ = ["PointFunction", "StudyExperiment", "render_target", "study_target", "target_names", "unit_of"]
