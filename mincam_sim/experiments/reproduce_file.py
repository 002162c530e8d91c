"""The reproduce file (``mincam-sim reproduce --config FILE``): its sections and its documented example.

A ``[setup]`` section (:class:`~mincam_sim.experiments.setup.Setup`) and one section per registered experiment
(its parameters dataclass); each key is a field, checked like the default's type, documented by the
dataclass's ``Attributes``. ``reproduce_example_toml`` (``mincam-sim config-example --reproduce``, and the
shipped ``scenes/experiments/reproduce.toml``) is written from the same dataclasses.
"""

from __future__ import annotations

import dataclasses
from typing import Any, get_args

from mincam_sim.configuration.schema import Part, Schema, toml_value
from mincam_sim.errors import ConfigError
from mincam_sim.experiments.registry import REGISTRY
from mincam_sim.experiments.setup import Setup

TITLE = (
    "mincam-sim reproduce --config FILE (written by `mincam-sim config-example --reproduce`).\n"
    "[setup] is shared by every experiment; one section per experiment. Every key is optional: the commented\n"
    "values are the full-mode defaults, (--quick: ...) the quick-mode value where it differs; --quick picks those\n"
    "first and a key set here applies after that, in both modes. Uncomment what you want to change.\n"
    "Units are in the key names: _m metres, _hz per second, _s seconds, _px display pixels, _w_m2_sr radiance."
)


def reproduce_schema() -> Schema:
    """The sections of a reproduce file: ``[setup]``, then each experiment of the registry."""
    parts = [Part("setup", Setup)]
    parts += [Part(name, type(experiment.params())) for name, experiment in REGISTRY.items()]
    return Schema(TITLE, tuple(parts))


def quick_notes() -> dict[str, dict[str, str]]:
    """``section -> key -> "(--quick: value)"`` for every value quick mode changes."""
    notes = {"setup": _differences(Setup(), Setup(quick=True))}
    for name, experiment in REGISTRY.items():
        notes[name] = _differences(experiment.params(False), experiment.params(True))
    return notes


def _differences(full, quick) -> dict[str, str]:
    return {f.name: f"(--quick: {toml_value(getattr(quick, f.name))})" for f in dataclasses.fields(full)
            if getattr(full, f.name) != getattr(quick, f.name)}


def reproduce_example_toml() -> str:
    """The documented reproduce file: every key of every section commented out at its default."""
    return reproduce_schema().example(notes=quick_notes(), commented_keys=True)


def check_reproduce(setup: Setup, params: dict[str, Any]) -> None:
    """Refuse, as one :class:`~mincam_sim.errors.ConfigError` line naming the section and key, the values of a
    reproduce file that the experiments would only refuse deep inside (after minutes, as a bare ``ValueError``):
    the set-up's mincam and screen, the tracking toys, the speed experiment's sampling of its mask."""
    from mincam_sim.model.optics import cross_layout

    try:
        cross_layout(setup.spacing_m, 8, setup.mask_size_m, d_f_m=setup.d_f_m, detector_size_m=setup.detector_size_m)
    except ValueError as err:
        raise ConfigError(f"[setup] detector_size_m = {setup.detector_size_m:g}, mask_size_m = "
                          f"{setup.mask_size_m:g}: {err}") from None
    try:
        setup.screen()
    except ValueError as err:
        raise ConfigError(f"[setup] screen_resolution = {list(setup.screen_resolution)}: {err}") from None
    if not (setup.table_light_radiance_w_m2_sr > 0 and setup.table_light_radiance_w_m2_sr < 1e30):
        raise ConfigError(f"[setup] table_light_radiance_w_m2_sr = {setup.table_light_radiance_w_m2_sr:g}: give the "
                          "table's light a radiance > 0 (an unlit table shows the mixels nothing to measure)")
    tabletop = [name for name in ("intrusion", "tracking") if name in params]
    if tabletop:
        _check_tabletop(setup, {name: params[name] for name in tabletop})
    if "tracking" in params:
        _check_toys(params["tracking"])
        _check_paths(setup, params["tracking"])
    if "speed" in params:
        _check_speed(setup, params["speed"])


def _check_tabletop(setup: Setup, experiments: dict[str, Any]) -> None:
    """The mincam under the table's light, and enough rays per pass for each tabletop experiment's replicates."""
    from mincam_sim.experiments.pipeline import STRATIFIED_SHARE, dp_rays_per_pass
    from mincam_sim.render.solvers.change import DEFAULT_REPLICATES
    from mincam_sim.scene.tabletop import Tabletop

    light_m = Tabletop.__dataclass_fields__["light_height_m"].default
    if not setup.depth_m < light_m:
        raise ConfigError(f"[setup] depth_m (--depth-m) = {setup.depth_m:g} m puts the mincam at or above the "
                          f"table's light, {light_m:g} m over the table, which hides the lit table from it "
                          f"({', '.join(experiments)}); give a depth below {light_m:g} m (the paper's: 0.5 m)")
    for name, params in experiments.items():
        fraction = getattr(params, "spp_fraction", 1.0)
        rays = dp_rays_per_pass(setup, fraction)
        if rays < DEFAULT_REPLICATES:
            share = STRATIFIED_SHARE if setup.dp_solver == "stratified_change" else 1
            least = -(-DEFAULT_REPLICATES * share // fraction) * (2 if setup.quick else 1)
            raise ConfigError(f"[setup] spp = {setup.spp} gives {name}'s dP {rays} rays per mixel per pass "
                              f"(spp{' / 2 in quick mode' if setup.quick else ''} x [{name}] spp_fraction = "
                              f"{fraction:g}{f' / {share}' if share > 1 else ''}), fewer than its "
                              f"{DEFAULT_REPLICATES} replicates; give spp >= {int(least)}")


def _check_paths(setup: Setup, tracking: Any) -> None:
    """Each toy's step a frame (speed x interval) must fit its walking area (``reach_fraction`` of the field)."""
    step = tracking.toy_speed_m_s * tracking.frame_interval_s
    side = 2 * tracking.reach_fraction * setup.field_m
    if not 2 * step < side:
        raise ConfigError(f"[tracking] toy_speed_m_s x frame_interval_s = {step:g} m a frame: a toy's walking area "
                          f"is {side:g} m across (reach_fraction x field_m, both ways), which must hold two steps; "
                          f"lower one of them (below {side / 2 / tracking.toy_speed_m_s:g} s a frame at this speed)")


def _check_toys(tracking: Any) -> None:
    from mincam_sim.scene.objects import windup_toy

    kinds = get_args(windup_toy.__annotations__.get("kind", "")) or ("robot", "chick", "frog")
    unknown = [t for t in tracking.toys if t not in kinds]
    if unknown:
        raise ConfigError(f"[tracking] toys = {list(tracking.toys)}: {', '.join(map(repr, unknown))} is no wind-up "
                          f"toy; choose from {', '.join(map(repr, kinds))}")


def _check_speed(setup: Setup, speed: Any) -> None:
    from mincam_sim.experiments.speed import check_nyquist

    try:
        check_nyquist(setup, speed)
    except ConfigError as err:
        raise ConfigError(f"with [speed] mask_period_m = {speed.mask_period_m:g} m: {err}") from None
