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
    if "tracking" in params:
        _check_toys(params["tracking"])
    if "speed" in params:
        _check_speed(setup, params["speed"])


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
