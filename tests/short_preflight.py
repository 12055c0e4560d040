"""``haptic-bus`` as its own process with shorter waits than the product's, for the tests whose point is a
real process (killed, stopped, or meeting no drive), not this machine's timing: not a test module.

:func:`command` is the command line's own lines (:func:`haptic_bus.app.cli.main`, then
:func:`~haptic_bus.app.early_stop.exiting`) with :data:`haptic_bus.app.preflight.PREFLIGHT_CYCLES`
set first (pre-flight judges ``T`` on those cycles as on 500,
:func:`~haptic_bus.app.preflight.allowed_overruns`: 2 overruns of 100, 5 of 500) and, if given, the
CANopen master's default ``boot_timeout`` (its waits for a drive that does not answer).
"""

from __future__ import annotations

import sys

CYCLES = 100  # pre-flight's cycles: 0.3 s at T = 3 ms, 0.8 s at T = 8 ms (500: 1.5 s and 4 s)


def command(cycles: int = CYCLES, boot_timeout: float | None = None) -> list[str]:
    """The argv that starts ``haptic-bus`` (arguments follow) with ``cycles`` pre-flight cycles and, unless
    None, ``boot_timeout`` (s) for :class:`~drives.canopen.drive.CanopenDrive`'s default."""
    code = ("import sys; from haptic_bus.app import preflight; "
            f"preflight.PREFLIGHT_CYCLES = {int(cycles)}; ")
    if boot_timeout is not None:
        code += ("from drives.canopen.drive import CanopenDrive; "
                 f"CanopenDrive.__init__.__kwdefaults__['boot_timeout'] = {float(boot_timeout)!r}; ")
    code += ("from haptic_bus.app.cli import main; from haptic_bus.app.early_stop import exiting; "
             "sys.exit(exiting(main()))")
    return [sys.executable, "-c", code]
