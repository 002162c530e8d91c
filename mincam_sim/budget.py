"""How much Monte Carlo work a measurement gets: one :class:`Budget` for every solver (pure Python).

A budget is either explicit sample counts or a target relative standard error (with the counts then as the
first pilot), plus the number of independent replicates whose spread gives the standard error, the seed and a
cap. Solvers read what applies to them: rays per mixel per frame (``spp``) for the aperture, reference and
change solvers, samples per screen texel for response maps.

Every check of a budget's values lives here, so that a ``Budget(...)`` in Python and a ``[run]`` section in
a TOML file refuse the same values with the same words: :func:`field_problem` checks one field (the TOML
reader calls it for each ``[run]`` key) and ``Budget.__post_init__`` the fields together. A message names
the field first (``"spp must be ..."``); Python shows it as ``Budget.spp ...``, a TOML file as
``[run] spp ...``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from mincam_sim.errors import InputError

DEFAULT_SPP = 1 << 16  # rays per mixel per frame when a budget names none
DEFAULT_SAMPLES_PER_TEXEL = 64
DEFAULT_RAY_REPLICATES = 8  # replicates of the ray solvers (aperture, reference, changes) when a budget names none
DEFAULT_MAP_REPLICATES = 4  # blocks of samples per texel of response maps when a budget names none
MIN_REPLICATES = 2  # the standard error needs two estimates
MAX_REPLICATES = 4096
MIN_SAMPLES_PER_TEXEL = 2  # their spread gives the standard error
MAX_SEED = 2**63 - 1

#: The smallest value of each count field, and why (shown in the message).
_MINIMUM = {"spp": (1, ""), "samples_per_texel": (MIN_SAMPLES_PER_TEXEL, " (their spread gives the standard error)"),
            "replicates": (MIN_REPLICATES, " (the standard error needs two estimates)"), "max_spp": (1, ""),
            "seed": (0, "")}
_MAXIMUM = {"replicates": MAX_REPLICATES, "seed": MAX_SEED}


def _is_integer(value) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, np.integer))


def _shown(value) -> str:
    """``value`` for a message, with its TOML type (what a config file's reader shows too)."""
    kind = {bool: "boolean", int: "integer", float: "number", str: "string", list: "array", dict: "table",
            tuple: "array"}.get(type(value), type(value).__name__)
    text = repr(value)
    return f"{text[:57] + '...' if len(text) > 60 else text} ({kind})"


def field_problem(name: str, value) -> str | None:
    """What is wrong with one budget field's value (a sentence starting with the field's name), or None.

    ``name`` is a count (``spp``, ``samples_per_texel``, ``replicates``, ``max_spp``, ``seed``) or
    ``target_rel_stderr``; None (not given) is always fine.
    """
    if value is None:
        return None
    if name == "target_rel_stderr":
        number = not isinstance(value, bool) and isinstance(value, (int, float, np.floating, np.integer))
        if number and np.isfinite(value) and 0 <= value < 1:
            return None
        return f"target_rel_stderr must be a number in [0, 1) (0 = use the counts as given), got {_shown(value)}"
    minimum, why = _MINIMUM[name]
    bound = "> 0" if minimum == 1 else f">= {minimum}"
    if not _is_integer(value):
        hint = " (a whole number, no decimal point)" if isinstance(value, float) else ""
        return f"{name} must be an integer {bound}{why}{hint}, got {_shown(value)}"
    if value < minimum:
        return f"{name} must be an integer {bound}{why}, got {value!r}"
    if name in _MAXIMUM and value > _MAXIMUM[name]:
        return f"{name} must be at most {_MAXIMUM[name]}, got {value!r}"
    return None


@dataclass(frozen=True)
class Budget:
    """Sample counts or a target noise, replicates, seed and cap of one measurement.

    Parameters
    ----------
    spp : int, optional
        Rays per mixel per frame (aperture, reference and change solvers; default 65,536), at least the
        replicates (default 8). With a target, the first pilot's count.
    samples_per_texel : int, optional
        Samples per screen texel of response maps (default 64; at least 2 and at least the replicates, default
        4 blocks; rounded to ``replicates x k^2``, and the map's ``meta["samples_per_texel"]`` says what was
        traced).
    target_rel_stderr : float
        If > 0, pilots measure the noise and the counts are raised until the worst significant measurement
        reaches this relative standard error (or the cap); what was reached is in the result.
    replicates : int, optional
        Independent estimates per measurement (2 .. 4096); default 8 for rays, 4 blocks for response maps.
    seed : int
        Same seed, same numbers.
    max_spp : int, optional
        Cap of the target search of the ray solvers (``Aperture``, ``Reference``, the change solvers), rays per
        mixel per frame; default 2^28 for displays, 2^26 for changes. A run that reaches it says so (the target
        is missed, with what was reached). Response maps cap samples per texel instead.

    Raises
    ------
    InputError
        Naming the field (``Budget.spp ...``) and the fix; a ``[run]`` section of a TOML file is refused with
        the same words (``[run] spp ...``).
    """

    spp: int | None = None
    samples_per_texel: int | None = None
    target_rel_stderr: float = 0.0
    replicates: int | None = None
    seed: int = 0
    max_spp: int | None = None

    def __post_init__(self) -> None:
        for name in ("spp", "samples_per_texel", "replicates", "max_spp", "seed", "target_rel_stderr"):
            problem = field_problem(name, getattr(self, name))
            if problem is not None:
                raise InputError(f"Budget.{problem}")
        problem = self._counts_problem()
        if problem is not None:
            raise InputError(f"Budget.{problem}")

    def _counts_problem(self) -> str | None:
        """What is wrong with the counts together (each replicate needs samples of its own), or None."""
        if self.samples_per_texel is not None:
            blocks = self.replicates_or(DEFAULT_MAP_REPLICATES)
            if self.samples_per_texel < blocks:
                given = "its" if self.replicates is not None else "the default"
                fix = "lower replicates" if self.replicates is not None else f"give replicates = {MIN_REPLICATES}"
                return (f"samples_per_texel = {self.samples_per_texel} is fewer than {given} {blocks} replicates; "
                        f"each replicate needs samples of its own in every texel: raise samples_per_texel or "
                        f"{fix}")
        if self.spp is not None:
            replicates = self.replicates_or(DEFAULT_RAY_REPLICATES)
            if self.spp < replicates:
                given = "its" if self.replicates is not None else "the default"
                return (f"spp = {self.spp} is fewer than {given} {replicates} replicates; each replicate needs rays "
                        "of its own: raise spp or lower replicates")
        return None

    def rays(self, default: int = DEFAULT_SPP) -> int:
        """Rays per mixel per frame this budget gives (or ``default``)."""
        return int(self.spp if self.spp is not None else default)

    def replicates_or(self, default: int) -> int:
        return int(self.replicates if self.replicates is not None else default)

    def given_fields(self) -> list[str]:
        """The fields set to other than their default (what a caller asked for)."""
        return [name for name in BUDGET_FIELDS if getattr(self, name) != getattr(_DEFAULT_BUDGET, name)]

    def describe(self) -> dict:
        """JSON-friendly record of the budget."""
        return {k: v for k, v in asdict(self).items() if v is not None}


#: Every field of a budget, in the order messages name them.
BUDGET_FIELDS = ("spp", "samples_per_texel", "target_rel_stderr", "replicates", "seed", "max_spp")
_DEFAULT_BUDGET = Budget()
