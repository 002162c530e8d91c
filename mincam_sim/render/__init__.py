"""The render layer: the only floor that imports Mitsuba / Dr.Jit.

Callers outside it import the front door and scene building, nothing else (a layering test checks it):

* ``simulation.py``: :class:`~mincam_sim.render.simulation.Simulation`, a mincam in a display or world scene.
* ``camera_change.py``: a frame's change as the ground-truth camera sees it, over its change window.
* ``solvers/``: the estimators of the mixel integral, one module each (:mod:`mincam_sim.render.solvers`).
* ``scene/``: scene building (:mod:`mincam_sim.render.scene`).
* ``kernels/``: the Monte Carlo kernels the solvers run (:mod:`mincam_sim.render.kernels`).
* ``gradients/``: automatic differentiation for mask design (:mod:`mincam_sim.render.gradients`).
* ``backend.py``: the choice of the Mitsuba / Dr.Jit variant, in one place.
* ``check.py``: ``python -m mincam_sim.render.check``, the set-up check.
"""
