"""The ``mincam-sim`` console entry: Ctrl-C is obeyed from the first instant.

Python imports the package (numpy, scipy, typer, Mitsuba's loader: about a second, more on a loaded machine)
before the command line is read. A Ctrl-C in that second would print the traceback of an import; here it gets
the CLI's answer for an interrupt instead: one line and exit code 130. This module lives outside the package
because importing anything inside ``mincam_sim`` runs the package's own imports first.
"""

import sys

INTERRUPTED_WHILE_STARTING = "error: interrupted while starting; nothing was run"


def main() -> None:
    """Console-script entry point: import the CLI, then run it (``mincam_sim.cli.main``)."""
    try:
        from mincam_sim.cli import main as cli_main
    except KeyboardInterrupt:
        print(INTERRUPTED_WHILE_STARTING, file=sys.stderr)
        raise SystemExit(130) from None
    cli_main()


if __name__ == "__main__":
    main()
