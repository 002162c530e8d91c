"""Progress bars for long steps (tqdm, on stderr).

Library functions take ``show_progress`` (default False: a library is quiet unless asked). The command line
shows bars by default and ``--quiet`` silences them; it passes its choice down as ``show_progress`` and also
sets the process-wide default (:func:`set_enabled`) that ``disable=None`` falls back on.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from typing import Any, TypeVar

from tqdm.auto import tqdm

T = TypeVar("T")

_enabled = {"default": False}


def set_enabled(enabled: bool) -> None:
    """Process-wide default for bars whose ``disable`` is None (the CLI: on unless ``--quiet``)."""
    _enabled["default"] = bool(enabled)


def enabled() -> bool:
    """The process-wide default (see :func:`set_enabled`)."""
    return _enabled["default"]


def _disabled(disable: bool | None) -> bool:
    return (not _enabled["default"]) if disable is None else bool(disable)


def progress(
    items: Iterable[T], desc: str = "", disable: bool | None = False, total: int | None = None, unit: str = "it"
) -> Iterable[T]:
    """Wrap ``items`` in a progress bar on stderr unless ``disable`` (None: the process-wide default)."""
    if _disabled(disable):
        return items
    return tqdm(items, desc=desc, total=total, unit=unit, dynamic_ncols=True, leave=False, file=sys.stderr)


class _NoBar:
    """Stands in for a bar when progress is off: accepts the calls, shows nothing."""

    n = 0

    def update(self, n: int = 1) -> None:
        self.n += n

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:
        pass

    def set_description(self, desc: str | None = None, refresh: bool = True) -> None:
        pass


@contextmanager
def bar(total: int | None, desc: str = "", disable: bool | None = False, unit: str = "it") -> Iterator[Any]:
    """A manual progress bar (``with bar(n, "tracing") as b: ... b.update(k)``) on stderr, or a silent stand-in.

    Parameters
    ----------
    total : int or None
        Number of steps (None: unknown, shows a counter).
    desc : str
        Label.
    disable : bool or None
        True hides it; None uses the process-wide default.
    unit : str
        Name of one step (``"texel"``, ``"frame"`` ...).
    """
    if _disabled(disable):
        yield _NoBar()
        return
    b = tqdm(total=total, desc=desc, unit=unit, dynamic_ncols=True, leave=False, file=sys.stderr)
    try:
        yield b
    finally:
        b.close()


__all__ = ["bar", "enabled", "progress", "set_enabled"]
