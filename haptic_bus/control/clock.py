"""The controller's two clocks: virtual (lock-step, as fast as the CPU allows) and real time.

The real clock is a deadline scheduler: cycle ``k`` is due at ``start + k T``.  It sleeps to
``spin`` before the deadline and spins the rest on ``perf_counter_ns``: ``time.sleep`` wakes
late by about the thread's timer slack (50 us by default on Linux, so the default spin covers
it) plus the scheduler's wake-up latency (10-40 us here); with the timer slack at 1 ns
(:mod:`haptic_bus.app.realtime`) a 60 us spin covers the wake-up alone, so the thread holds the
CPU (and the GIL) for 60 us of every period instead of 200 us.  A cycle that starts later than
its deadline plus ``T`` is an overrun; every start's lateness is kept, so that period error
percentiles are reported, never hidden.

When the automatic garbage collector is off (a real-time session turns it off after
``gc.freeze()``), the clock collects in the slack before a deadline, never inside a cycle: a
young-generation collection when the young generation is over its threshold and at least
:data:`GC_SLACK` s remain (older generations by the collector's own counting).

The clock also keeps the process CPU time (all threads) at each cycle's start, so a run (or
any stretch of it) can report the share of a core it used.
"""

from __future__ import annotations

import ctypes
import functools
import gc
import sys
import time

import numpy as np

SPIN_FLOOR = 60e-6  # s: spun before every deadline beyond the thread's timer slack
GC_SLACK = 300e-6  # s: the least time left before a deadline for a collection in the slack
_DEFAULT_SLACK_NS = 50_000  # Linux's default timer slack, assumed where the thread's cannot be read
PR_GET_TIMERSLACK = 30  # prctl option (linux/prctl.h)


@functools.cache
def libc() -> ctypes.CDLL | None:
    """The C library already loaded in this process (Linux; None elsewhere), for ``prctl`` and ``mlockall``."""
    if not sys.platform.startswith("linux"):
        return None
    return ctypes.CDLL(None, use_errno=True)


def timer_slack() -> float:
    """The calling thread's timer slack (s): how late the kernel may wake a sleep on purpose."""
    c = libc()
    if c is None:
        return _DEFAULT_SLACK_NS * 1e-9
    zero = ctypes.c_ulong(0)
    return int(c.prctl(PR_GET_TIMERSLACK, zero, zero, zero, zero)) * 1e-9


class VirtualClock:
    """Lock-step with the simulated drive: no waiting; time is ``k T``."""

    name = "virtual (lock-step, no pacing)"

    def __init__(self, period: float) -> None:
        self.period = period
        self.overruns = 0

    def wait_next(self, cycle: int) -> float:
        """Return at once (lateness 0 s): the drive's plant advances exactly ``T`` per SYNC."""
        return 0.0

    def lateness(self, last: int | None = None) -> np.ndarray:
        """Virtual time is never late."""
        return np.zeros(0)


class RealClock:
    """Deadline scheduler at period ``T`` s on ``time.perf_counter_ns`` (sleep, then spin).

    ``spin`` (s): how long before each deadline the sleep ends (None: :data:`SPIN_FLOOR` plus
    the thread's timer slack when the first cycle starts).  ``capacity``: the cycles whose
    lateness and CPU time are kept (the first ones).
    """

    def __init__(self, period: float, capacity: int = 1_000_000, spin: float | None = None) -> None:
        self.period = period
        self._period_ns = round(period * 1e9)
        self._spin = spin
        self._spin_ns = 0
        self._start: int | None = None
        self._late = np.zeros(capacity)
        self._cpu = np.zeros(capacity, dtype=np.int64)  # process CPU time at each cycle start, ns
        self._at = np.zeros(capacity, dtype=np.int64)  # perf_counter at each cycle start, ns
        self._count = 0
        self.overruns = 0
        self.slack_collections = 0

    @property
    def name(self) -> str:
        """How the clock waits (for the run's summary)."""
        if self._start is not None:
            spin = self._spin_ns * 1e-9
        else:
            spin = self._spin if self._spin is not None else SPIN_FLOOR + timer_slack()
        return f"real (sleep to deadline - {spin * 1e6:.0f} us, then spin on perf_counter_ns)"

    def wait_next(self, cycle: int) -> float:
        """Block until cycle ``cycle``'s deadline; return (and record) how late it started, s."""
        if self._start is None:
            self._spin_ns = round(1e9 * (self._spin if self._spin is not None else SPIN_FLOOR + timer_slack()))
            self._start = time.perf_counter_ns()  # cycle 0 is due now
            now = self._start
        else:
            now = time.perf_counter_ns()
        deadline = self._start + cycle * self._period_ns
        remaining = deadline - now
        if remaining > 0:
            if remaining > self._spin_ns:
                if remaining > GC_SLACK * 1e9 and not gc.isenabled():
                    self._collect()
                remaining = deadline - time.perf_counter_ns()
                if remaining > self._spin_ns:
                    time.sleep((remaining - self._spin_ns) * 1e-9)
            while (now := time.perf_counter_ns()) < deadline:
                pass
        late = now - deadline
        if late > self._period_ns:
            self.overruns += 1
        lateness = late * 1e-9
        count = self._count
        if count < self._late.size:
            self._late[count] = lateness
            self._at[count] = now
            self._cpu[count] = time.process_time_ns()
            self._count = count + 1
        return lateness

    def _collect(self) -> None:
        """A collection the automatic collector would have made by now, in the slack before a deadline."""
        counts, thresholds = gc.get_count(), gc.get_threshold()
        if counts[0] < thresholds[0]:
            return
        generation = 2 if counts[2] >= thresholds[2] > 0 else 1 if counts[1] >= thresholds[1] else 0
        gc.collect(generation)
        self.slack_collections += 1

    def lateness(self, last: int | None = None) -> np.ndarray:
        """How late each cycle started after its deadline, in s (the ``last`` ones only, if given)."""
        start = 0 if last is None else max(0, self._count - last)
        return self._late[start : self._count].copy()

    def usage(self, first: int = 0, last: int | None = None) -> tuple[float, float]:
        """``(wall, cpu)``: seconds from the ``first`` kept cycle's start to the ``last`` one's
        (default: the latest kept), and the process CPU time (every thread) spent in between;
        ``cpu / wall`` is the share of a core the run used.  ``(0, 0)`` for fewer than two cycles."""
        last = self._count - 1 if last is None else min(last, self._count - 1)
        if last <= first:
            return 0.0, 0.0
        return float(self._at[last] - self._at[first]) * 1e-9, float(self._cpu[last] - self._cpu[first]) * 1e-9
