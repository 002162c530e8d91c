"""The render layer's kernels: Monte Carlo estimates of the mixel integral in Dr.Jit, used by the solvers.

Nothing outside :mod:`mincam_sim.render` imports these; the solvers (:mod:`mincam_sim.render.solvers`) are the
way in.

* ``monte_carlo.py``: the rules every solver shares: the seed rule, replicate statistics and standard errors, the
  budget policy (a pilot scaled to a target).
* ``tracing.py``: launches of a sensor through the scene's integrator, accumulated in float64 lanes.
* ``mixel_sensor.py``: one Mitsuba sensor that starts every ray on a mixel's mask aperture.
* ``mask_eval.py``: mask transmission inside Dr.Jit kernels (analytic profiles, raster textures).
* ``map_tracing.py``: response maps traced per display texel, with their variance, and their content cache.
* ``map_export.py``: response maps and point-source responses out as NumPy arrays with a JSON sidecar.
* ``stratified.py``: stratified estimates: most rays where a frame can change things, a few everywhere else.
* ``frozen.py``: frozen functions (``dr.freeze``) kept per scene: the stratified launches, the ground-truth camera.
* ``qmc.py``: randomised quasi-Monte Carlo points (an Owen-scrambled Sobol sequence) in Dr.Jit integer arithmetic.
* ``guided_path.py``: path tracing with the inter-reflection bounce guided toward what a frame moves.
* ``split_scene.py``: rays traced against a static scene and a small movers scene as if they were one.
* ``change_region.py``: bounds on a mixel's aperture plane where a frame can change its measurement.
* ``change_geometry.py``: the geometry oracle of the change solvers (where a frame's change can reach).
* ``camera_window.py``: the ground-truth camera over the window of its film where a frame's change can be seen.
"""
