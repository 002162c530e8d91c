"""Checks of an experiment's set-up and parameters that the experiments would only make deep inside (after
minutes, as a bare ``ValueError``), made before anything runs: by ``reproduce`` for its file and options, and by a
study for each of its points. Each refusal is one :class:`~mincam_sim.errors.ConfigError` naming the section and
key."""

from __future__ import annotations

from typing import Any, get_args

from mincam_sim.errors import ConfigError
from mincam_sim.experiments.setup import Setup

#: The brightest table light a set-up may have [W m^-2 sr^-1]
_MAX_RADIANCE_W_M2_SR = 1e30


def check_reproduce(setup: Setup, params: dict[str, Any]) -> None:
    """Refuse, as one :class:`~mincam_sim.errors.ConfigError` line naming the section and key, the values of a
    reproduce file that the experiments would only refuse deep inside (after minutes, as a bare ``ValueError``):
    the set-up's mincam and screen, the tracking toys, the speed experiment's sampling of its mask."""
    from mincam_sim.configuration.config import MAX_MINCAM_LENGTH_M
    from mincam_sim.model.optics import cross_layout

    for key, option in (("spacing_m", " (--spacing-m)"), ("d_f_m", ""), ("detector_size_m", ""), ("mask_size_m", "")):
        value = getattr(setup, key)
        if value > MAX_MINCAM_LENGTH_M:  # a unit mistake, and the layout's arithmetic would overflow
            raise ConfigError(f"[setup] {key}{option} = {value:g} m: a mincam's lengths are at most "
                              f"{MAX_MINCAM_LENGTH_M:g} m; give it in metres (the default: {getattr(Setup(), key):g} "
                              "m)")
    try:
        cross_layout(setup.spacing_m, 8, setup.mask_size_m, d_f_m=setup.d_f_m, detector_size_m=setup.detector_size_m)
    except ValueError as err:
        raise ConfigError(f"[setup] detector_size_m = {setup.detector_size_m:g}, mask_size_m = "
                          f"{setup.mask_size_m:g}, d_f_m = {setup.d_f_m:g}, spacing_m = {setup.spacing_m:g}: "
                          f"{err}") from None
    try:
        setup.screen()
    except ValueError as err:
        raise ConfigError(f"[setup] screen_resolution = {list(setup.screen_resolution)}: {err}") from None
    if not setup.table_light_radiance_w_m2_sr > 0:
        raise ConfigError(f"[setup] table_light_radiance_w_m2_sr = {setup.table_light_radiance_w_m2_sr:g}: give the "
                          "table's light a radiance > 0 (an unlit table shows the mixels nothing to measure)")
    if not setup.table_light_radiance_w_m2_sr < _MAX_RADIANCE_W_M2_SR:
        raise ConfigError(f"[setup] table_light_radiance_w_m2_sr = {setup.table_light_radiance_w_m2_sr:g}: give the "
                          f"table's light a radiance below {_MAX_RADIANCE_W_M2_SR:g} W m^-2 sr^-1 (its light, "
                          "squared in the estimates, must stay a finite float)")
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
