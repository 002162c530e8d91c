"""Runs kept outside the numerics: output directories, their one lock and identity, and the config jobs.

Two floors, bottom to top: ``run.py`` (never imported by the solvers) below ``jobs.py``.

* ``run.py``: :class:`~mincam_sim.runs.run.Run` owns an output directory: its lock, the one identity of a run,
  the stores, resume after a kill.
* ``jobs.py``: a validated config (display or world) becomes ``(Simulation, frames, solver, budget)`` and goes
  through a ``Run``; time estimates and ``--check`` summaries.
"""
