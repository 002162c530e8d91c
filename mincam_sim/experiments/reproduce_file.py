"""The reproduce file (``mincam-sim reproduce --config FILE``): its sections and its documented example.

A ``[setup]`` section (:class:`~mincam_sim.experiments.setup.Setup`) and one section per registered experiment
(its parameters dataclass); each key is a field, checked like the default's type, documented by the
dataclass's ``Attributes``. ``reproduce_example_toml`` (``mincam-sim config-example --reproduce``, and the
shipped ``scenes/experiments/reproduce.toml``) is written from the same dataclasses.
"""

from __future__ import annotations

import dataclasses

from mincam_sim.configuration.schema import Part, Schema, toml_value
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


__all__ = ["quick_notes", "reproduce_example_toml", "reproduce_schema"]
