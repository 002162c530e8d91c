"""Progress bars for long steps (tqdm, on stderr).

Library functions take ``show_progress`` (default False: a library is quiet unless asked). The command line
shows bars by default and ``--quiet`` silences them; it passes its choice down as ``show_progress`` and also
sets the process-wide default (:func:`set_enabled`) that ``disable=None`` falls back on.

When stderr is not a terminal (a log file, a pipe, a batch job), a bar is written as whole lines instead of
carriage-return updates: one when it starts, one at most every ``MINCAM_PROGRESS_INTERVAL_S`` seconds (default
30) and one when it ends, each in tqdm's format (``desc: 40%|... | 4/10 [00:12<00:18, 0.33frame/s]``).
"""

from __future__ import annotations

import os
import sys
import time
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


ENV_INTERVAL = "MINCAM_PROGRESS_INTERVAL_S"
DEFAULT_INTERVAL_S = 30.0


def _is_terminal(stream: Any) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False


def _interval_s() -> float:
    try:
        value = float(os.environ.get(ENV_INTERVAL, DEFAULT_INTERVAL_S))
    except ValueError:
        return DEFAULT_INTERVAL_S
    return value if value >= 0 else DEFAULT_INTERVAL_S


class LineBar:
    """A progress report as periodic whole lines (for a stderr that is not a terminal): tqdm's format, one line
    at the start, then at most one per ``interval_s`` seconds, and one at the end."""

    def __init__(self, total: int | None, desc: str = "", unit: str = "it", interval_s: float | None = None,
                 file: Any = None) -> None:
        self.total, self.desc, self.unit, self.n = total, desc, unit, 0
        self.interval_s = _interval_s() if interval_s is None else interval_s
        self.file = sys.stderr if file is None else file
        self.postfix = ""
        self._start = self._last = time.monotonic()
        self._shown = -1
        self._emit()

    def _emit(self) -> None:
        line = tqdm.format_meter(self.n, self.total, time.monotonic() - self._start, prefix=self.desc,
                                 unit=self.unit, postfix=self.postfix or None, ncols=100,
                                 ascii=True)
        print(line.strip(), file=self.file, flush=True)
        self._last, self._shown = time.monotonic(), self.n

    def update(self, n: int = 1) -> None:
        self.n += n
        if time.monotonic() - self._last >= self.interval_s:
            self._emit()

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:
        self.postfix = s

    def set_description(self, desc: str | None = None, refresh: bool = True) -> None:
        self.desc = desc or ""

    def close(self) -> None:
        if self._shown != self.n:
            self._emit()


def _lines(items: Iterable[T], desc: str, total: int | None, unit: str) -> Iterator[T]:
    if total is None:
        try:
            total = len(items)  # type: ignore[arg-type]
        except TypeError:
            total = None
    b = LineBar(total, desc, unit)
    try:
        for item in items:
            yield item
            b.update(1)
    finally:
        b.close()


def progress(
    items: Iterable[T], desc: str = "", disable: bool | None = False, total: int | None = None, unit: str = "it"
) -> Iterable[T]:
    """Wrap ``items`` in a progress bar on stderr unless ``disable`` (None: the process-wide default); periodic
    lines instead of a bar when stderr is not a terminal."""
    if _disabled(disable):
        return items
    if not _is_terminal(sys.stderr):
        return _lines(items, desc, total, unit)
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
    if not _is_terminal(sys.stderr):
        lines = LineBar(total, desc, unit)
        try:
            yield lines
        finally:
            lines.close()
        return
    b = tqdm(total=total, desc=desc, unit=unit, dynamic_ncols=True, leave=False, file=sys.stderr)
    try:
        yield b
    finally:
        b.close()


__all__ = ["LineBar", "bar", "enabled", "progress", "set_enabled"]
