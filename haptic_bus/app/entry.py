"""The ``haptic-bus`` console script's entry: :func:`main` imports the command line, then runs it.

Importing the command line and building its parser takes about 0.1 s (argparse, logging, the
option modules; a command's handler imports what it runs), more under load.  A Ctrl-C in that
time used to raise KeyboardInterrupt out of the console script's import, before the command's own
handling (:func:`haptic_bus.app.cli.main`) existed, and Python printed a traceback.  Here it ends
as a Ctrl-C ends every command: one line on stderr, exit 130.

A SIGTERM in that time killed ``run`` silently (status 143) before ``run`` installed its own stop
handling: for ``run``, :func:`main` first installs :func:`~haptic_bus.app.early_stop.note_stop`,
which notes it, and ``run`` (:func:`haptic_bus.app.cli._run`) ends with
:data:`~haptic_bus.app.early_stop.STOPPED_BEFORE_START`, exit 0, before it touches anything.
This module imports nothing of the project but :mod:`~haptic_bus.app.early_stop` and
:mod:`~haptic_bus.app.blas_threads` (the standard library only), so the window left is Python's
own start-up.

Before anything imports numpy, it asks for one BLAS thread (:mod:`~haptic_bus.app.blas_threads`).
"""

from __future__ import annotations

import signal
import sys
from collections.abc import Sequence

from haptic_bus.app.blas_threads import one_blas_thread
from haptic_bus.app.early_stop import exiting, note_stop

EXIT_INTERRUPTED = 130  # haptic_bus.app.arguments.EXIT_INTERRUPTED, which is what this guards the import of


def _command(argv: Sequence[str]) -> str | None:
    """The subcommand of ``argv`` (the top level's options, ``-v``, ``-q``, ``--version``, take no value)."""
    return next((word for word in argv if not word.startswith("-")), None)


def main() -> int:
    """Entry point of the ``haptic-bus`` console script; returns the exit status."""
    one_blas_thread()
    if _command(sys.argv[1:]) == "run":
        signal.signal(signal.SIGTERM, note_stop)
    try:
        from haptic_bus.app.cli import main as command_line

        return exiting(command_line())
    except KeyboardInterrupt:
        print("haptic-bus: interrupted", file=sys.stderr)
        return exiting(EXIT_INTERRUPTED)

