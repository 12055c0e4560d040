"""``run``'s stop before it began.  A SIGTERM while the console script imports the command line is
noted (:func:`note_stop`: raising inside the import machinery would leave its files open) and acted on
once ``run`` starts; a SIGTERM while ``run`` prepares (the profile read and judged: seconds for a
coupled gate) raises :class:`StoppedBeforeStart` through :func:`stop_at_once`.  Either way the run
ends with :data:`STOPPED_BEFORE_START`, exit 0, nothing touched.  Installed by the console script's
entry (:mod:`haptic_bus.app.entry`) and by ``run`` itself (:func:`haptic_bus.app.cli._run`); the
standard library only, so the entry can import it first.
"""

from __future__ import annotations

STOPPED_BEFORE_START = "ended: stopped before the run began; no bus touched, nothing written"
"""What ``run`` prints (stdout) when a SIGTERM ends it while it prepares."""

_noted = False


class StoppedBeforeStart(BaseException):  # control flow, as KeyboardInterrupt: no ``except Exception`` holds it
    """SIGTERM while ``run`` prepares (its imports, its profile read and judged): nothing touched yet."""


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
