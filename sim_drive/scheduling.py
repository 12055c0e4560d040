"""The simulated drive answers as hardware does: under real-time scheduling where the OS grants it.

A servo drive answers SYNC within microseconds whatever the PC beside it does.  The simulated
drive stands in for one, so its process asks for ``SCHED_FIFO`` at :data:`DRIVE_PRIORITY` (below
the controller's control thread, :data:`haptic_bus.app.realtime.FIFO_PRIORITY`) before it starts
a thread: every thread it starts (the bus's receiver, the SYNC clock, the heartbeat) inherits
the policy.  Its threads wait on the bus and never spin, so they take the CPU only while a frame
is being answered.  A process the OS does not grant it (no ``CAP_SYS_NICE``, no
``RLIMIT_RTPRIO``) runs on as an ordinary one; the line that says the drive serves says which: measured on this
project's 2-core machine beside other work, three simulated axes then answered a SYNC in 1.7 ms
(median) where the controller's period was 2 ms.

:func:`scheduling_restored` puts the calling thread's policy back when the simulated drive
stops, so that a process that ran it in-process (``sim_drive.cli.main`` from a test, or a
tool) does not go on under ``SCHED_FIFO``, nor hand it to every thread it starts afterwards.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager, suppress

DRIVE_PRIORITY = 70  # SCHED_FIFO priority of the simulated drive's threads (1..99)


@contextmanager
def scheduling_restored() -> Iterator[None]:
    """This thread's scheduling policy and priority as they were once the block ends: ``haptic-bus
    sim``'s main, called in a process that goes on (a test, a script), leaves it as it found it."""
    try:
        before = os.sched_getscheduler(0), os.sched_getparam(0)
    except (OSError, AttributeError):
        yield
        return
    try:
        yield
    finally:
        with suppress(OSError):  # lowering one's own priority is always allowed; a policy that cannot come back stays
            os.sched_setscheduler(0, *before)


def answer_in_real_time() -> str:
    """Put this thread, and every thread it starts from now on, under ``SCHED_FIFO`` at
    :data:`DRIVE_PRIORITY`; what was got, in words for the serving line."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(DRIVE_PRIORITY))
    except (OSError, AttributeError) as exc:
        return f"no real-time scheduling (SCHED_FIFO {DRIVE_PRIORITY} not granted: {exc})"
    return f"SCHED_FIFO {DRIVE_PRIORITY}"
