"""A SIGTERM before ``run`` began, or once the command has ended.  A SIGTERM while the console script imports the command line is
noted (:func:`note_stop`: raising inside the import machinery would leave its files open) and acted on
once ``run`` starts; a SIGTERM while ``run`` prepares (the profile read and judged: seconds for a
coupled gate) raises :class:`StoppedBeforeStart` through :func:`stop_at_once`.  Either way the run
ends with :data:`STOPPED_BEFORE_START`, exit 0, nothing touched.  Installed by the console script's
entry (:mod:`haptic_bus.app.entry`) and by ``run`` itself (:func:`haptic_bus.app.cli._run`).  Once
the command has ended, the process about to exit ignores SIGTERM (:func:`exiting`); a program that
calls the command gets its own handlers back (:func:`handlers_kept`).  The standard library only, so
the entry can import it first.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

STOPPED_BEFORE_START = "ended: stopped before the run began; no bus touched, nothing written"
"""What ``run`` prints (stdout) when a SIGTERM ends it while it prepares."""

_noted = False


class StoppedBeforeStart(BaseException):  # control flow, as KeyboardInterrupt: no ``except Exception`` holds it
    """SIGTERM while ``run`` prepares (its imports, its profile read and judged): nothing touched yet."""


def signals_reach_this_thread() -> bool:
    """Whether this is the main thread: Python runs signal handlers there alone, and only there may
    they be installed.  A command a program calls from another thread installs none and leaves
    stopping it to the program (a run's stop request, ``ask``)."""
    return threading.current_thread() is threading.main_thread()


def note_stop(signum: int, frame: object) -> None:
    """SIGTERM handler while the command line is imported: noted, for :func:`stop_noted`."""
    global _noted
    _noted = True


def stop_noted() -> bool:
    """Whether a SIGTERM came while the command line was imported (:func:`note_stop`)."""
    return _noted


def stop_at_once(signum: int, frame: object) -> None:
    """SIGTERM handler while ``run`` prepares: raise :class:`StoppedBeforeStart`."""
    raise StoppedBeforeStart


def stop_at_once_on_sigterm() -> Any:
    """:func:`stop_at_once` for SIGTERM from now on, where signals reach this thread
    (:func:`signals_reach_this_thread`); the handler it replaced, None where none was installed."""
    return signal.signal(signal.SIGTERM, stop_at_once) if signals_reach_this_thread() else None


def exiting(status: int) -> int:
    """``status``, the process about to exit with it: from here a SIGTERM changes nothing.  A Python
    handler (``run``'s stop request) the interpreter puts back to the default action while it
    finalizes, and a SIGTERM then killed the process (status -15) after the command had said how it
    ended ("drive error", exit 1: found by the fuzz test, its SIGTERM late).  Only for a process that
    exits: :func:`haptic_bus.app.cli.main` called from a program leaves its signals as they were."""
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    return status


@contextmanager
def handlers_kept() -> Iterator[None]:
    """SIGINT's and SIGTERM's handlers put back as they were found when the block ends (``run``,
    ``identify`` and ``validate`` install their stop request for both; a handler C code installed,
    which Python cannot put back, is left)."""
    found = {signum: signal.getsignal(signum) for signum in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for signum, handler in found.items():
            if handler is not None and signal.getsignal(signum) is not handler:
                signal.signal(signum, handler)
