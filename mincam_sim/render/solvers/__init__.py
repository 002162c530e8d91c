"""Solvers: the estimators of the mixel integral, one small module each, behind one interface.

A :class:`~mincam_sim.render.simulation.Simulation` holds the scene; a solver says *how* to estimate what the
mixels measure in it, a :class:`~mincam_sim.budget.Budget` says *how much* work to spend. Every solver is a
frozen dataclass of options (:class:`~.base.Solver`) whose ``plan(sim, frames, budget)`` returns a
:class:`~.base.Plan` (its rows, then its typed result); the simulation runs the plan through a sink.

Adding a solver: one new module here (a ``Solver`` subclass with its ``plan``), its export below, one row of
``docs/forms.md`` and one entry in ``tests/render/solvers/test_contract.py``.

=====================  ===========================================================================================
file                   role
=====================  ===========================================================================================
``base.py``            :class:`Solver`, :class:`Plan`; the display ray plan shared by Aperture and Reference
``reference.py``       :class:`Reference` (displays): the literal scene per mixel, Mitsuba's irradiance meter
``aperture.py``        :class:`Aperture` (displays and worlds): rays started on the mask aperture (fast form)
``response_map.py``    :class:`ResponseMap` (displays): maps over the screen's texels, the quantised target search;
                       a frame is ``sum(W * frame)`` (kernel: ``mincam_sim.render.kernels.map_tracing``)
``change.py``          :class:`PlainChange`, :class:`StratifiedChange` (worlds): dP against a background, the
                       pilots, the retry of heavy-tailed frames, the typed :class:`~mincam_sim.changes.RunInfo`
``plane_replay.py``    :class:`PlaneReplay` (worlds): the aperture's rays traced once, a frame that moves a
                       textured plane within its plane replayed per ray (:class:`SlidingPlane`)
``dot_product.py``     :class:`DotProduct` (displays): the idealised model (mask stretched over the field, dotted
                       with the frame), physics added one effect at a time; deterministic quadrature with an error
                       estimate, pure numpy
=====================  ===========================================================================================
"""

from mincam_sim.render.kernels.map_tracing import ResponseMaps
from mincam_sim.render.kernels.monte_carlo import UncertainSigmaWarning
from mincam_sim.render.solvers.aperture import Aperture
from mincam_sim.render.solvers.base import Plan, Solver
from mincam_sim.render.solvers.change import FallbackWarning, HeavyTailWarning, PlainChange, StratifiedChange
from mincam_sim.render.solvers.dot_product import DotProduct
from mincam_sim.render.solvers.plane_replay import PlaneReplay, SlidingPlane
from mincam_sim.render.solvers.reference import Reference
from mincam_sim.render.solvers.response_map import ResponseMap

SOLVERS = (Reference, Aperture, ResponseMap, PlainChange, StratifiedChange, PlaneReplay, DotProduct)
"""Every public solver class (the contract test crosses them with its scenes)."""

__all__ = ["SOLVERS", "Aperture", "DotProduct", "FallbackWarning", "HeavyTailWarning", "Plan", "PlainChange",
           "PlaneReplay", "Reference", "ResponseMap", "ResponseMaps", "SlidingPlane", "Solver", "StratifiedChange",
           "UncertainSigmaWarning"]
