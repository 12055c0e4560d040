"""How long the interval a SYNC closes was: virtual time, or the wall clock between SYNC frames.

A :data:`SyncClock` maps a SYNC frame's reception timestamp (s, python-can's ``msg.timestamp``)
to the length of the interval that SYNC closes, s, or None for exactly one period ``T``
(virtual time: the plant advances ``T`` per SYNC however fast the master runs).
:class:`WallSyncClock` takes the time between SYNC receptions instead, as a real drive's
handle lives it: a SYNC that comes late holds the latched torque that much longer.  On
``udp_multicast`` python-can stamps a frame with the kernel's reception time (``SIOCGSTAMP``),
so a stalled simulator thread does not stretch the interval it reports.  Intervals are taken to
the microsecond (:data:`RESOLUTION`): a drive's own clock is no finer, and a few hundred distinct
lengths let the plant reuse its exact coefficients instead of computing them every period.
"""

from __future__ import annotations

from collections.abc import Callable

SyncClock = Callable[[float], "float | None"]
SYNC_CLOCKS = ("virtual", "wall")
RESOLUTION = 1e-6  # s: the wall clock's intervals are rounded to this
IDLE = 1.0  # s: a longer interval closes one period: the master was away (every drive watchdog expires sooner)


class WallSyncClock:
    """Interval lengths from SYNC reception timestamps (s, to the microsecond); the first SYNC closes
    one period (None), and so does one after more than :data:`IDLE` s without any (a Modbus master's
    first cycle after idle time: that drive has no reset to restart its cycle, and stepping the plant
    through the idle time, about 4 ms of this process per idle second, stalled the answer)."""

    def __init__(self) -> None:
        self._last: float | None = None

    def __call__(self, timestamp: float) -> float | None:
        """The time since the previous SYNC's ``timestamp``, s (never negative; None: one period)."""
        last, self._last = self._last, timestamp
        if last is None or timestamp - last > IDLE:
            return None
        return max(0.0, round((timestamp - last) / RESOLUTION) * RESOLUTION)

    def restart(self) -> None:
        """The next SYNC closes no interval, as the first does: a drive reset restarts its cycle, and the
        plant is not stepped over the idle time before it (pieces as long as a period, about 4 ms of
        this process per idle second: 45 s idle stalled the next SYNC's answer 174 ms, longer than the
        3 missed TPDOs a master tolerates)."""
        self._last = None


def sync_clock(kind: str) -> SyncClock | None:
    """The clock of ``kind`` (:data:`SYNC_CLOCKS`): None for virtual time, else a fresh :class:`WallSyncClock`."""
    if kind not in SYNC_CLOCKS:
        raise ValueError(f"sync clock {kind!r}; allowed: {', '.join(SYNC_CLOCKS)}")
    return WallSyncClock() if kind == "wall" else None
