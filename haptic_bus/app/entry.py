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
This module imports nothing of the project but
:mod:`~haptic_bus.app.early_stop` (the standard library only), so the window left is Python's own
start-up.

**One BLAS thread.**  numpy's and scipy's OpenBLAS each start a pool of worker threads at import
(one per further CPU), which ``top -H`` and ``/proc/PID/task/*/comm`` show under the process's name
beside the named threads of a run, and which burnt 0.1 s of CPU each while a three-axis run started
(measured here, 2 CPUs).  The project's matrices are 6 x 6 at most and its long arrays are
elementwise (no BLAS), so the pools buy nothing: before anything imports numpy, :func:`one_blas_thread`
asks each BLAS library the wheels ship for one thread, unless the environment already names a count
(the user's choice is kept, and passed to the run's writer and judge processes as this one's is).
"""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Sequence

from haptic_bus.app.early_stop import exiting, note_stop

EXIT_INTERRUPTED = 130  # haptic_bus.app.arguments.EXIT_INTERRUPTED, which is what this guards the import of
BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")  # the thread counts numpy's and scipy's BLAS libraries read


def one_blas_thread() -> None:
    """One thread for each BLAS library this process will load, where the environment names no count
    (module docstring); only before numpy is imported does it change anything."""
    for name in BLAS_THREADS:
        os.environ.setdefault(name, "1")


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

