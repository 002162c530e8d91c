"""The project's own error types (pure Python).

Every error a user can cause by what they give (a config, an option, a file, an output location, a backend this
machine lacks) is a :class:`MincamError`; the command line turns it into one line ``error: ...`` and exit code 2.
Errors that also are a ``ValueError`` (bad values) subclass both, so ``except ValueError`` keeps working.
"""

from __future__ import annotations

import math
from numbers import Real


class MincamError(Exception):
    """Base class of mincam_sim's user-facing errors; the message says what is wrong and how to fix it."""


class ConfigError(MincamError, ValueError):
    """A configuration value is missing, unknown or out of range; the message names the field and the fix."""


class InputError(MincamError, ValueError):
    """A value handed to the Python API is unusable (a scene element, a parameter update, a budget); the message
    names it and the fix."""


class StoreError(MincamError):
    """An output directory or one of its files cannot be used (torn, foreign, unwritable ...)."""


class StaleResultError(StoreError, ValueError):
    """An output directory holds results of a different run; the message names what changed."""


class OutDirLockedError(StoreError):
    """Another process is writing into the same output directory."""


class BackendUnavailableError(MincamError, RuntimeError):
    """A Mitsuba variant was asked for that this machine cannot run (e.g. ``cuda_ad_mono`` without a GPU)."""


class IgnoredSettingWarning(UserWarning):
    """A setting (a TOML key, a CLI option, a :class:`~mincam_sim.budget.Budget` field) that the rest of the input
    makes ineffective: it is ignored, and one warning says so."""


def is_finite_real(value) -> bool:
    """True for a finite real number (numpy's scalars included); False for a boolean, a string, NaN or an
    infinity: what a boundary checks before it compares a user's number with its range."""
    return isinstance(value, Real) and not isinstance(value, bool) and math.isfinite(value)


__all__ = [
    "BackendUnavailableError",
    "ConfigError",
    "IgnoredSettingWarning",
    "InputError",
    "MincamError",
    "OutDirLockedError",
    "StaleResultError",
    "StoreError",
    "is_finite_real",
]

