"""The controller's two clocks: virtual (lock-step, as fast as the CPU allows) and real time.

The real clock is a deadline scheduler: cycle ``k`` is due at ``start + k T``; it sleeps to
shortly before the deadline and spins the rest (``time.sleep`` alone overshoots by ~60 us on
Linux).  A cycle that starts later than its deadline plus ``T`` is an overrun; every start's
lateness is kept so that period error percentiles are reported, never hidden.
"""

from __future__ import annotations

import time

import numpy as np


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
    """Deadline scheduler at period ``T`` s on ``time.perf_counter_ns`` (sleep, then spin)."""

    name = "real (sleep to deadline - 200 us, then spin on perf_counter_ns)"
    _SPIN_NS = 200_000

    def __init__(self, period: float, capacity: int = 1_000_000) -> None:
        self.period = period
        self._period_ns = round(period * 1e9)
        self._start: int | None = None
        self._late = np.zeros(capacity)
        self._count = 0
        self.overruns = 0

    def wait_next(self, cycle: int) -> float:
        """Block until cycle ``cycle``'s deadline; return (and record) how late it started, s."""
        now = time.perf_counter_ns()
        if self._start is None:
            self._start = now
        deadline = self._start + cycle * self._period_ns
        remaining = deadline - now
        if remaining > self._SPIN_NS:
            time.sleep((remaining - self._SPIN_NS) / 1e9)
        while (now := time.perf_counter_ns()) < deadline:
            pass
        late = now - deadline
        if late > self._period_ns:
            self.overruns += 1
        lateness = late / 1e9
        if self._count < self._late.size:
            self._late[self._count] = lateness
            self._count += 1
        return lateness

    def lateness(self, last: int | None = None) -> np.ndarray:
        """How late each cycle started after its deadline, in s (the ``last`` ones only, if given)."""
        start = 0 if last is None else max(0, self._count - last)
        return self._late[start : self._count].copy()
