"""Solvers: small configured objects, one per estimator of the mixel integral, behind one interface.

A :class:`~.simulation.Simulation` holds the scene; a solver says *how* to estimate what the mixels measure in
it, a :class:`~mincam_sim.budget.Budget` says *how much* work to spend. Solvers for displays measure frames
(radiance images); solvers for worlds measure parameter updates (absolute ``P``) or changes against a
background (``dP``, :class:`~mincam_sim.changes.Changes`). Adding an estimator is a new solver class here.

===========================  =======  ==========================================================================
solver                       scenes   what it traces
===========================  =======  ==========================================================================
:class:`Reference`           display  the literal scene: mask surface, housing, Mitsuba's irradiance meter
:class:`Aperture`            both     rays started on the mask aperture, weight ``A T cos^2 / r^2`` (fast form)
:class:`ResponseMap`         display  each mixel's map over the screen texels; a frame is ``sum(W * frame)``
:class:`PlainChange`         world    whole-aperture rays per frame with the background's seed (reference dP)
:class:`StratifiedChange`    world    most rays where the frame's change can reach, bounces guided (fast dP)
:class:`PlaneReplay`         world    the aperture's rays once; a frame that moves a textured plane within its
                                      own plane is a texture lookup per ray (roads, belts, turntables)
===========================  =======  ==========================================================================
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from .world import STRATA_EXPANSIONS, STRATA_SHARES


@dataclass(frozen=True)
class Solver:
    """Base of every solver: ``name`` is what results record; ``scenes`` which scene kinds it solves."""

    name = "solver"
    scenes: tuple[str, ...] = ()
    form: str = ""


@dataclass(frozen=True)
class Reference(Solver):
    """The literal scene per mixel, in millimetres around it (slow, obviously right); displays only."""

    name = "reference"
    scenes: tuple[str, ...] = ("display",)
    form: str = "reference"


@dataclass(frozen=True)
class Aperture(Solver):
    """Rays from the detector through the mask aperture, all mixels in one kernel (the fast form)."""

    name = "aperture"
    scenes: tuple[str, ...] = ("display", "world")
    form: str = "fast"


@dataclass(frozen=True)
class ResponseMap(Solver):
    """Per-mixel response maps over the screen's texels (stratified, with their variance); then any frame is
    a dot product. Displays only; the budget's ``samples_per_texel`` or target sets the work."""

    name = "response_map"
    scenes: tuple[str, ...] = ("display",)
    form: str = "response_map"


@dataclass(frozen=True)
class PlainChange(Solver):
    """dP with whole-aperture rays per frame, traced with the background's seed (the reference)."""

    name = "plain"
    scenes: tuple[str, ...] = ("world",)
    form: str = "plain"


@dataclass(frozen=True)
class StratifiedChange(Solver):
    """dP with most rays in the aperture region the frame's moving shapes, their shadows and their mirror
    images can reach; every stratum unbiased, frame and background paired ray by ray, bounces guided.

    Parameters
    ----------
    strata_shares : sequence of float
        Share of rays per stratum (region, each ring, rest).
    strata_expansions : sequence of float
        Scale factors of the nested rectangles about the region's centre, from 1.
    guide_bounces : bool
        Draw half the inter-reflection bounces toward spheres around the moving shapes.
    """

    name = "stratified"
    scenes: tuple[str, ...] = ("world",)
    form: str = "stratified"
    strata_shares: Sequence[float] = STRATA_SHARES
    strata_expansions: Sequence[float] = STRATA_EXPANSIONS
    guide_bounces: bool = True


@dataclass(frozen=True)
class PlaneReplay(Solver):
    """The :class:`Aperture` solver's rays traced once, and every frame replayed: for frames that only move one
    diffuse textured rectangle (``plane``, its ``to_world``) within its own plane, in a scene where every other
    shape is black (:class:`~.sliding_plane.SlidingPlane`). Slides give the Aperture solver's numbers to float32
    rounding; turns agree within the standard error.

    Parameters
    ----------
    plane : str
        The rectangle's element name (e.g. ``"road"``).
    """

    plane: str = "road"
    name = "plane_replay"
    scenes: tuple[str, ...] = field(default=("world",), kw_only=True)  # keyword-only: the plane comes first
    form: str = field(default="plane_replay", kw_only=True)


CHANGE_SOLVERS = (PlainChange, StratifiedChange)
