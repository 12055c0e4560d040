"""``run``'s stop before it began: a SIGTERM while ``run`` prepares (the console script's import of the
command line, the profile read and judged) raises :class:`StoppedBeforeStart` through
:func:`stop_at_once`, and the run ends with :data:`STOPPED_BEFORE_START`, exit 0, nothing touched.
Installed by the console script's entry (:mod:`haptic_bus.app.entry`) and by ``run`` itself
(:func:`haptic_bus.app.cli._run`); the standard library only, so the entry can import it first.
"""

from __future__ import annotations

STOPPED_BEFORE_START = "ended: stopped before the run began; no bus touched, nothing written"
"""What ``run`` prints (stdout) when a SIGTERM ends it while it prepares."""


class StoppedBeforeStart(Exception):
    """SIGTERM while ``run`` prepares (its imports, its profile read and judged): nothing touched yet."""


def stop_at_once(signum: int, frame: object) -> None:
    """SIGTERM handler while ``run`` prepares: raise :class:`StoppedBeforeStart`."""
    raise StoppedBeforeStart
