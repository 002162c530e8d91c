"""Whether a Ctrl-C (SIGINT) has reached this process, whatever became of its ``KeyboardInterrupt``.

A ``KeyboardInterrupt`` raised inside an import can be swallowed or turned into another error on the way out (a
module left half-imported answers the next use with a ``NameError``). The command line installs
:func:`recording_handler` for its whole run and asks :func:`arrived` when a command fails: an error after a
Ctrl-C is reported as the interrupt (one line, exit code 130), not as a bug's traceback.
"""

from __future__ import annotations

import signal

_count = {"sigint": 0}


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
