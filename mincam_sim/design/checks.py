"""Range checks of the design tasks' size records (:class:`~.tracking.TrackingTask`, :class:`~.scene_tasks.Sizes`),
in one place: every numeric field is refused up front, before anything is traced, written or locked, with one
:class:`FieldError` naming the field, its allowed range and why. Pure Python/numpy.

The bounds shared by every task (geometry, film, seed: :data:`SHARED`) live here; each record adds the ranges of
its own sizes (:func:`check_ranges`). A :class:`FieldError` says ``Record.field must be ..., got ...`` to a
Python caller; the command line names the option or the ``[tracking]`` key instead (:meth:`FieldError.named`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from mincam_sim import paper
from mincam_sim.errors import ConfigError

MAX_SEED = 2**32 - 1  # seeds of the design runs: any unsigned 32-bit integer
MEMORY_LIMIT_BYTES = 8 * 2**30  # [B] the largest array one design run may build (frames x texels, frames x dots)


class FieldError(ConfigError):
    """A field (or a combination of fields) of a design task's record is out of range.

    Parameters
    ----------
    owner : str
        The record's class (``TrackingTask``, ``Sizes``).
    fields : tuple of str
        The fields at fault, the first the one the rule is about.
    rule : str
        What they must be (``must be an integer from 1 to 100000``), with the reason where one helps.
    values : tuple
        Their values, in ``fields`` order.
    """

    def __init__(self, owner: str, fields: tuple[str, ...], rule: str, values: tuple) -> None:
        self.owner, self.fields, self.rule, self.values = owner, tuple(fields), rule, tuple(values)
        super().__init__(self.named(lambda name: f"{owner}.{name}" if name == fields[0] else name))

    def __reduce__(self) -> tuple:
        return type(self), (self.owner, self.fields, self.rule, self.values)

    def named(self, name_of: Callable[[str], str]) -> str:
        """The message with each field called ``name_of(field)`` (an option, ``[tracking] key`` ...)."""
        got = ", ".join(_shown(v) for v in self.values)
        return f"{' and '.join(name_of(f) for f in self.fields)} {self.rule}, got {got}"


def _shown(value: Any) -> str:
    if isinstance(value, tuple):
        return "(" + ", ".join(_shown(v) for v in value) + ("," if len(value) == 1 else "") + ")"
    if isinstance(value, float | np.floating):
        return f"{float(value):g}"
    return repr(value)


def _is_integer(value: Any) -> bool:
    return not isinstance(value, bool) and isinstance(value, int | np.integer)


def _is_number(value: Any) -> bool:
    return not isinstance(value, bool) and isinstance(value, int | float | np.integer | np.floating)


@dataclass(frozen=True)
class Range:
    """The allowed values of one numeric field: an integer or a finite number in ``[low, high]`` (``(low, high]``
    with ``low_open``).

    Attributes
    ----------
    low, high : float
        Bounds, in the field's unit.
    integer : bool
        Whole numbers only (a float, even 2.0, is refused).
    low_open : bool
        ``low`` itself is refused (``> 0``).
    unit : str
        Shown after the bounds (``" m"``).
    why : str
        Why the bounds are what they are, shown in parentheses.
    """

    low: float
    high: float
    integer: bool = False
    low_open: bool = False
    unit: str = ""
    why: str = ""

    def rule(self) -> str:
        """``must be ...``: the range in words."""
        why = f" ({self.why})" if self.why else ""
        if self.integer:
            return f"must be an integer from {int(self.low)} to {int(self.high)}{self.unit}{why}"
        if self.low_open:
            return f"must be a number > {self.low:g} and <= {self.high:g}{self.unit}{why}"
        return f"must be a number from {self.low:g} to {self.high:g}{self.unit}{why}"

    def accepts(self, value: Any) -> bool:
        if not (_is_integer(value) if self.integer else _is_number(value) and np.isfinite(value)):
            return False
        return (self.low < value if self.low_open else self.low <= value) and value <= self.high


def check_ranges(record: Any, ranges: Mapping[str, Range]) -> None:
    """Raise a :class:`FieldError` for the first field of ``record`` outside its range in ``ranges``."""
    for name, allowed in ranges.items():
        value = getattr(record, name)
        if not allowed.accepts(value):
            raise FieldError(type(record).__name__, (name,), allowed.rule(), (value,))


def refuse(record: Any, fields: Iterable[str], rule: str) -> None:
    """Raise a :class:`FieldError` about ``fields`` of ``record`` (a rule on several fields, or not a range)."""
    names = tuple(fields)
    raise FieldError(type(record).__name__, names, rule, tuple(getattr(record, n) for n in names))


#: Bounds shared by every design task: the mincam's geometry, the printed film and the seed.
SHARED: dict[str, Range] = {
    "seed": Range(0, MAX_SEED, integer=True),
    "spacing_m": Range(0.005, 0.2, unit=" m", why="distance of each mixel from the centre"),
    "d_f_m": Range(2e-4, 0.02, unit=" m", why="0.2-20 mm from the mask to the detector"),
    "dpi": Range(50, 4800, unit=" dots per inch", why="a printer resolution"),
    "film_t_min": Range(0, 1, why="the film's darkest transmission"),
    "film_t_max": Range(0, 1, low_open=True, why="the film's clearest transmission"),
}


def lowest_printable_dpi(side_m: float = paper.MASK_SIZE_M) -> int:
    """[dots per inch] the smallest dpi at which a ``side_m`` [m] mask prints as at least
    :data:`~mincam_sim.masks.printing.MIN_PRINT_DOTS` dots a side (102 for the design tasks' 2 mm masks)."""
    from mincam_sim.masks.printing import METRES_PER_INCH, MIN_PRINT_DOTS, few_print_dots

    dpi = int(np.ceil(MIN_PRINT_DOTS * METRES_PER_INCH / side_m))
    while few_print_dots(side_m, side_m, dpi) is not None:  # the dot grid rounds: the first dpi that gives them
        dpi += 1
    return dpi


def check_shared(record: Any) -> None:
    """The checks of :data:`SHARED`, ``film_t_min < film_t_max`` and a dpi that prints every mask (2 mm a side)
    as enough dots to show it, on ``record`` (any design task's sizes)."""
    check_ranges(record, SHARED)
    if not record.film_t_min < record.film_t_max:
        refuse(record, ("film_t_min", "film_t_max"), "must satisfy 0 <= t_min < t_max <= 1")
    lowest = lowest_printable_dpi()
    if record.dpi < lowest:
        from mincam_sim.masks.printing import MIN_PRINT_DOTS

        refuse(record, ("dpi",), f"must be at least {lowest} dots per inch to print each {1e3 * paper.MASK_SIZE_M:g} "
                                 f"mm mask as at least {MIN_PRINT_DOTS} dots a side")


def memory_bytes(*counts: float) -> float:
    """[B] of a float64 array with these dimensions."""
    return 8.0 * float(np.prod([float(c) for c in counts]))


def check_memory(record: Any, fields: tuple[str, ...], n_bytes: float, what: str) -> None:
    """Refuse ``fields`` of ``record`` when ``what`` would take more than :data:`MEMORY_LIMIT_BYTES`."""
    if n_bytes > MEMORY_LIMIT_BYTES:
        refuse(record, fields, f"make {what} of {n_bytes / 2**30:.1f} GiB (at most {MEMORY_LIMIT_BYTES / 2**30:g} "
                               "GiB): lower them")


__all__ = ["MAX_SEED", "MEMORY_LIMIT_BYTES", "SHARED", "FieldError", "Range", "check_memory", "check_ranges",
           "check_shared", "lowest_printable_dpi", "memory_bytes", "refuse"]
