"""The controller's clocks: virtual (lock-step, as fast as the CPU allows), real time, and a
scheduled one that replays a given timing in virtual time (adversarial timing, exactly).

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
import math
import sys
import time
from collections.abc import Callable

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

    def period_bound(self, sampled_by_ns: int) -> float:
        """The length of the period that the latest sample closed: exactly ``T`` s."""
        return self.period

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
        self._previous_ns = 0  # perf_counter_ns at the start of the cycle before the current one
        self._current_ns = 0
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
        self._previous_ns, self._current_ns = self._current_ns, now
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

    def since_start(self) -> float:
        """How long ago (s) the latest cycle started (0.0 before the first)."""
        return (time.perf_counter_ns() - self._current_ns) * 1e-9 if self._count else 0.0

    def period_bound(self, sampled_by_ns: int) -> float:
        """An upper bound (s) of the period that the latest sample closed: from the start of the cycle
        before (the SYNC that opened the period left after it) to ``sampled_by_ns`` (the drive had
        sampled by then; 0: unknown, then to the current cycle's start plus one period, the longest
        a cycle's request takes before the loop counts it late)."""
        previous = self._previous_ns
        if not previous:
            return self.period
        end = sampled_by_ns if sampled_by_ns else self._current_ns + self._period_ns
        return (end - previous) * 1e-9

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


class ScheduledClock:
    """Virtual time that keeps a timing it is given: cycle ``k`` starts (and its SYNC goes out) at
    ``starts[k]`` s, so that stalls, late cycles and jitter are replayed exactly and repeatably.

    The simulated drive must live the same timing: :meth:`sync_clock` is its
    :data:`sim_drive.sync_clock.SyncClock` (the interval the current cycle's SYNC closes).
    """

    name = "scheduled (virtual time, a given timing)"

    def __init__(self, period: float, starts: np.ndarray) -> None:
        starts = np.asarray(starts, dtype=float)
        if starts.ndim != 1 or starts.size < 1 or not np.all(np.diff(starts) >= 0):
            raise ValueError("starts: a non-decreasing 1-D array of cycle start times (s)")
        self.period = period
        self.starts = starts
        self.overruns = 0
        self._cycle = -1

    def wait_next(self, cycle: int) -> float:
        """Cycle ``cycle`` starts at ``starts[cycle]``: its lateness after ``cycle * T``, s."""
        self._cycle = cycle
        late = float(self.starts[cycle]) - cycle * self.period
        if late > self.period:
            self.overruns += 1
        return late

    def period_bound(self, sampled_by_ns: int) -> float:
        """The length (s) of the period the current cycle's SYNC closes, exactly."""
        k = self._cycle
        return self.period if k < 1 else float(self.starts[k] - self.starts[k - 1])

    def sync_clock(self) -> Callable[[float], float | None]:
        """The simulated drive's view of the same timing (None before the first cycle: ``T``)."""
        def interval(timestamp: float) -> float | None:
            return None if self._cycle < 1 else self.period_bound(0)

        return interval

    def lateness(self, last: int | None = None) -> np.ndarray:
        """Each started cycle's lateness (s), the ``last`` ones only if given."""
        count = self._cycle + 1
        late = self.starts[:count] - np.arange(count) * self.period
        return late if last is None else late[max(0, count - last):]


def adversarial_starts(period: float, cycles: int, seed: int, *, stall_probability: float = 0.01,
                       stall: tuple[float, float] = (2e-3, 20e-3), late_probability: float = 0.05,
                       late: tuple[float, float] = (0.5, 1.0), jitter: float = 20e-6, busy: float = 50e-6) -> np.ndarray:
    """Cycle start times (s) of a deadline scheduler on a machine that misbehaves, seeded:
    cycle ``k`` is due at ``k T`` but starts no earlier than ``busy`` s after the one before (it
    catches up after a stall, cycle after cycle), plus a jitter (exponential, mean ``jitter`` s),
    plus with probability ``late_probability`` a lateness of ``late`` (fractions of ``T``,
    uniform) and with probability ``stall_probability`` a stall of ``stall`` s (uniform)."""
    rng = np.random.default_rng(seed)
    extra = rng.exponential(jitter, cycles) if jitter > 0 else np.zeros(cycles)
    extra += np.where(rng.random(cycles) < late_probability, rng.uniform(*late, cycles) * period, 0.0)
    extra += np.where(rng.random(cycles) < stall_probability, rng.uniform(*stall, cycles), 0.0)
    starts = np.empty(cycles)
    previous = -math.inf
    for k in range(cycles):
        previous = starts[k] = max(k * period, previous + busy) + extra[k]
    return starts


CycleClock = VirtualClock | RealClock | ScheduledClock
"""Any of the controller's clocks."""
