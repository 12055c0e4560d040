"""Benchmark 6: real time, ``T = 1 ms`` against the in-process simulated drive.

The product's controller with :class:`haptic_bus.control.clock.RealClock` (a deadline scheduler:
sleep to 200 us before the deadline, then spin) runs the ``cia402-handle`` profile against
:func:`haptic_bus.app.rig.simulated_canopen` for 10 s (2 s with ``--quick``).  Reported:
lateness of each cycle start after its deadline, the period error (the difference of
consecutive starts minus ``T``), both as percentiles p50/p99/p99.9/max, the overrun count
(a start later than deadline + ``T``) -- and the same for the bare clock (no drive, no
controller: what the OS and the machine give a sleeping Python thread), the scheduler (the clock's name, the OS scheduling
policy) and the kernel's timer slack where readable.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Callable

import numpy as np

from haptic_bus.app.profiles import load_profile
from haptic_bus.control.clock import RealClock
from haptic_bus.control.controller import WallController

PROFILE = "cia402-handle"
_POLICIES = {getattr(os, n): n for n in ("SCHED_OTHER", "SCHED_FIFO", "SCHED_RR", "SCHED_BATCH", "SCHED_IDLE")
             if hasattr(os, n)}


def _percentiles(values: np.ndarray) -> dict[str, float]:
    if values.size == 0:
        return {}
    p50, p99, p999 = np.percentile(values, [50, 99, 99.9])
    return {"p50": float(p50), "p99": float(p99), "p99.9": float(p999), "max": float(np.max(values))}


def scheduler_info() -> dict:
    """OS scheduling policy, nice, CPU affinity and timer slack (ns) of this process, where readable."""
    info: dict = {}
    try:
        info["policy"] = _POLICIES.get(os.sched_getscheduler(0), str(os.sched_getscheduler(0)))
    except (AttributeError, OSError):
        info["policy"] = None
    try:
        info["nice"] = os.nice(0)
    except OSError:
        info["nice"] = None
    try:
        info["affinity"] = sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        info["affinity"] = None
    try:
        info["timer_slack_ns"] = int(Path("/proc/self/timerslack_ns").read_text().strip())
    except (OSError, ValueError):
        info["timer_slack_ns"] = None
    return info


def run(quick: bool, tick: Callable[[str], None] = lambda _: None) -> dict:
    """Benchmark 6; returns its section of ``bench.json``."""
    from haptic_bus.app.rig import simulated_canopen

    duration = 2.0 if quick else 10.0
    profile = load_profile(PROFILE)
    period = profile.loop.period
    cycles = round(duration / period)
    clock = RealClock(period, capacity=cycles + 10)
    with simulated_canopen(profile) as (_, drive):
        controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit,
                                    clock=clock)
        summary = controller.run(cycles)
    tick("real time")
    bare = RealClock(period, capacity=cycles + 10)  # the same clock with no drive and no controller
    for k in range(cycles):
        bare.wait_next(k)
    bare_late = bare.lateness()
    late = clock.lateness()
    period_error = np.diff(late)  # start_k - start_{k-1} - T
    return {
        "description": f"T = {period * 1e3:g} ms for {duration:g} s against the in-process simulated drive "
                       "(virtual bus) with RealClock",
        "period_s": period, "duration_s": duration, "cycles": summary.cycles, "error": summary.error,
        "clock": clock.name, "scheduler": scheduler_info(),
        "lateness_s": _percentiles(late),
        "period_error_abs_s": _percentiles(np.abs(period_error)),
        "overruns": summary.overruns,
        "compute_s": summary.compute_percentiles,
        "late_over_100us": int(np.sum(late > 100e-6)),
        "bare_clock": {"lateness_s": _percentiles(bare_late), "overruns": bare.overruns,
                       "late_over_100us": int(np.sum(bare_late > 100e-6))},
    }
