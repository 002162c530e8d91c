"""Whether a Ctrl-C (SIGINT) has reached this process, whatever became of its ``KeyboardInterrupt``.

A ``KeyboardInterrupt`` raised inside an import can be swallowed or turned into another error on the way out (a
module left half-imported answers the next use with a ``NameError``). The command line installs
:func:`recording_handler` for its whole run and asks :func:`arrived` when a command fails: an error after a
Ctrl-C is reported as the interrupt (one line, exit code 130), not as a bug's traceback.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

_count = {"sigint": 0}

#: What a Ctrl-C says before a study has started (its modules imported, its file read): nothing was written.
STUDY_NOT_STARTED = ("interrupted before the study started: nothing was written; run the same command again to "
                     "start it")


def note() -> None:
    """Count one SIGINT (for a handler of its own that replaces :func:`recording_handler` for a while)."""
    _count["sigint"] += 1


def recording_handler(signum, frame) -> None:
    """Python's own SIGINT behaviour (raise ``KeyboardInterrupt``), counted first."""
    note()
    signal.default_int_handler(signum, frame)


def arrived() -> bool:
    """True once a SIGINT has been counted in this process."""
    return _count["sigint"] > 0


def reset() -> None:
    """Forget the SIGINTs counted so far (a command line run in-process again, as the tests do)."""
    _count["sigint"] = 0


@contextmanager
def held() -> Iterator[None]:
    """Hold a Ctrl-C while native code runs that a ``KeyboardInterrupt`` must not cross (loading Dr.Jit and the
    Mitsuba variant: one raised inside aborted the process), and raise it once the block is done. Only the main
    thread receives signals; elsewhere the block runs as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    arrivals: list[int] = []

    def hold(signum, frame) -> None:
        note()
        arrivals.append(signum)

    previous = signal.signal(signal.SIGINT, hold)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous if previous is not None else signal.default_int_handler)
    if arrivals:
        raise KeyboardInterrupt
