"""The ``haptic-bus`` console script's entry: :func:`main` imports the command line, then runs it.

Importing the command line takes about 0.1 s (argparse, logging, the option modules).  A Ctrl-C
in that time used to raise KeyboardInterrupt out of the console script's import, before the
command's own handling (:func:`haptic_bus.app.cli.main`) existed, and Python printed a
traceback.  Here it ends as a Ctrl-C ends every command: one line on stderr, exit 130.  This
module imports nothing of the project, so the window left is Python's own start-up.
"""

from __future__ import annotations

import sys

EXIT_INTERRUPTED = 130  # haptic_bus.app.arguments.EXIT_INTERRUPTED, which is what this guards the import of


def main() -> int:
    """Entry point of the ``haptic-bus`` console script; returns the exit status."""
    try:
        from haptic_bus.app.cli import main as command_line
    except KeyboardInterrupt:
        print("haptic-bus: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    return command_line()
