"""``haptic-bus`` as a real-time run's process whose pre-flight measures fewer cycles than the product's
500, for the tests whose point is a real process killed or stopped, not this machine's timing: not a
test module.

:func:`command` is ``python -m haptic_bus.app.cli``'s own lines (its ``main``, then
:func:`~haptic_bus.app.early_stop.exiting`) with :data:`haptic_bus.app.preflight.PREFLIGHT_CYCLES`
set first; pre-flight judges ``T`` on those cycles as on 500
(:func:`~haptic_bus.app.preflight.allowed_overruns`: 2 overruns of 100, 5 of 500).
"""

from __future__ import annotations

import sys

CYCLES = 100  # pre-flight's cycles: 0.3 s at T = 3 ms, 0.8 s at T = 8 ms (500: 1.5 s and 4 s)


def command(cycles: int = CYCLES) -> list[str]:
    """The argv that starts ``haptic-bus`` (arguments follow) with ``cycles`` pre-flight cycles."""
    code = ("import sys; from haptic_bus.app import preflight; "
            f"preflight.PREFLIGHT_CYCLES = {int(cycles)}; "
            "from haptic_bus.app.cli import main; from haptic_bus.app.early_stop import exiting; "
            "sys.exit(exiting(main()))")
    return [sys.executable, "-c", code]
