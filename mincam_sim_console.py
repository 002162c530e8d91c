"""The ``mincam-sim`` console entry: Ctrl-C is obeyed from the first instant.

Python imports the package (numpy, scipy, typer, Mitsuba's loader: about a second, more on a loaded machine)
before the command line is read. A Ctrl-C in that second would print the traceback of an import; here it gets
the CLI's answer for an interrupt instead: one line and exit code 130. This module lives outside the package
because importing anything inside ``mincam_sim`` runs the package's own imports first.

A Ctrl-C that lands inside a C extension's own import (numpy's core importing ``datetime``) reaches Python as an
``ImportError``, not a ``KeyboardInterrupt``, and one that lands in an import guard catching ``BaseException`` is
swallowed; the signal is therefore recorded when it arrives, and an import error that follows one, or a
successful import during which one arrived, is the interrupt's. Any other import error is shown as it is.
"""

import signal
import sys

INTERRUPTED_WHILE_STARTING = "error: interrupted while starting; nothing was run"


def main() -> None:
    """Console-script entry point: import the CLI, then run it (``mincam_sim.cli.main``)."""
    interrupted = []

    def on_sigint(signum, frame):
        interrupted.append(signum)
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGINT, on_sigint)
    try:
        from mincam_sim.cli import main as cli_main
    except KeyboardInterrupt:
        print(INTERRUPTED_WHILE_STARTING, file=sys.stderr)
        raise SystemExit(130) from None
    except ImportError:
        if not interrupted:
            raise
        print(INTERRUPTED_WHILE_STARTING, file=sys.stderr)
        raise SystemExit(130) from None
    finally:
        signal.signal(signal.SIGINT, previous)
    if interrupted:  # swallowed on the way (an import guard that catches BaseException): nothing has run yet
        print(INTERRUPTED_WHILE_STARTING, file=sys.stderr)
        raise SystemExit(130)
    cli_main()


if __name__ == "__main__":
    main()
