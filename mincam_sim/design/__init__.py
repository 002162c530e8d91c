"""Mask design by differentiable rendering through the mincam's real geometry.

An upper floor beside the experiments: it imports the core (optics, masks, sensor, calibration) and the render
layer, whose ``mincam_sim.render.gradients.differentiable`` holds the differentiable rendering and
``mincam_sim.render.gradients.autodiff`` the Dr.Jit namespace the optimiser is written against (this floor imports no
renderer itself).

* :mod:`.tracking`: the task (four mixels 3.3 cm apart, objects 1-15 cm at 0.35-0.7 m on black or grey
  planes, 12-bit sensor) and its training distribution.
* :mod:`.parameterization`: logits on a coarse grid -> printer dots -> film transmission.
* :mod:`.optimise`: builds the linear forward model from traced samples and optimises the masks.
* ``problem``: the design problem as plain arrays (linear models, film, noise, targets) and the result.
* ``optimiser``: Adam on the mask logits through the film, the noise and a decoder fitted in the loop.
* :mod:`.evaluate`: the old held-out draw (squares 2-5 cm on black) in the physical simulator (response maps).
* ``suite``: the held-out suite of every report (sizes, shapes, backgrounds, two objects, depths, tilt,
  contrast), the baseline (ramps of ``cross_layout``, Eq. 7, cubic calibration) beside the design.
* ``baselines.py``: the baselines the field uses (random, PCA, trained through the idealised ``DotProduct``
  model), measured on the same suite, each decoder refitted on the physics.
* :mod:`.gradcheck`: AD against central finite differences.
* :mod:`.run`: one run and its outputs (``mincam-sim design TASK``).
* ``tasks.py``: the registry: every task as data (scenes, target, metric and direction, decoder, suite, hand).
* ``scene_tasks.py``, ``counting.py``, ``depth.py``, ``scene_design.py``, ``scene_run.py``: the tasks whose
  scenes are flat objects or textured planes (counting, depth) and the machinery that designs and measures them.

Files:

* ``tracking.py``: the task ``tracking``: four mixels 3.3 cm apart (paper Sec. 4.2) and its training distribution.
* ``checks.py``: the range checks of every task's sizes (geometry, film and seed shared by all), one
  ``FieldError`` naming the field and its range before anything runs.
* ``parameterization.py``: masks as a coarse grid of logits onto the printer's dots and grey values.
* ``problem.py``: the design problem as plain arrays (linear forward model, film, sensor noise, targets).
* ``optimiser.py``: Adam on the mask logits through the forward model, with a decoder fitted in the loop.
* ``optimise.py``: the tracking problem built from traced samples (or DotProduct maps), and the optimiser run on it.
* ``baselines.py``: random and PCA masks through the film, and the idealised model's linear model on the dots.
* ``decoder.py``: a learned decoder in plain numpy (a polynomial of gain-free mixel ratios).
* ``gradcheck.py``: gradients against central finite differences with the same seed.
* ``evaluate.py``: physical evaluation of a tracking mincam on held-out scenes (response maps, 12-bit sensor).
* ``suite.py``: the held-out suite of a design report, designed masks beside the paper's ramps.
* ``report.py``: figures of a design run.
* ``run.py``: one design run: gradient check, optimisation, held-out evaluation and the outputs.
* ``tasks.py``: the registry of design tasks (``Task`` records; ``get_task``).
* ``scene_tasks.py``: a task as data (``TaskSpec``: scene ``Distribution``, target, metric, decoder, suite ``Case``s),
  frames and labels, traced rows, the polynomial ``SceneDecoder``.
* ``counting.py``: the task ``counting`` (0-3 objects on a tabletop at 0.5 m, accuracy).
* ``depth.py``: the task ``depth`` (distance 0.3-1.0 m to an object, error in % of the depth).
* ``scene_design.py``: training, baselines, the held-out suite, the decoders' loss-gradient check, the Zarr dataset.
* ``scene_run.py``: one run of a scene task and its outputs.
"""

from mincam_sim.design.run import TASKS, run_design

__all__ = ["TASKS", "run_design"]
