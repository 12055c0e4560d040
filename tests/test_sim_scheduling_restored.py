"""The simulated drive run in-process leaves its caller's scheduling as it found it.

``sim_drive.cli.main`` asks for SCHED_FIFO 70 for the calling thread (every thread it starts
inherits it).  Run from a test or a tool, the caller's thread used to stay under SCHED_FIFO
after main returned, and so did every thread it started afterwards (seen: a pytest process's
main thread, its writer and upload threads at FIFO 70 minutes after the drive had stopped).
"""

from __future__ import annotations

import os
import signal
import threading

from sim_drive import cli


def test_main_puts_the_callers_scheduling_back() -> None:
    before = os.sched_getscheduler(0), os.sched_getparam(0).sched_priority
    stopper = threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGTERM))  # the drive serves until SIGTERM
    stopper.start()
    try:
        status = cli.main(["--interface", "virtual", "--channel", "sched-restored", "--node-id", "5"])
    finally:
        stopper.cancel()
    assert status == 0
    assert (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority) == before
