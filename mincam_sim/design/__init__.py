"""Mask design by differentiable rendering through the mincam's real geometry.

An upper floor beside the experiments: it imports the core (optics, masks, sensor, calibration) and the render
layer, whose ``mincam_sim.render.differentiable`` holds the differentiable rendering and
``mincam_sim.render.autodiff`` the Dr.Jit namespace the optimiser is written against (this floor imports no
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
* :mod:`.gradcheck`: AD against central finite differences.
* :mod:`.run`: one run and its outputs (``mincam-sim design TASK``).
"""

from .run import TASKS, run_design

__all__ = ["TASKS", "run_design"]
