"""The simulated drive's bus-load meter, on the bit-time model of :mod:`haptic_bus.analysis.can_timing`
(worst-case ``55 + 10 n`` bit times for a standard frame with ``n`` data bytes).

The wire carries one frame at a time; :class:`BusLoadMeter` adds up what one SYNC cycle puts
on it (SYNC, TPDOs, RPDOs, anything else seen) to report bus load and the cycle's latency
(the frames sent back to back, no arbitration losses, no processing time).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from haptic_bus.analysis.can_timing import (
    MAX_DATA_BYTES,
    checked_bitrate,
    checked_period,
    cycle_bits,
    frame_bits,
    frame_time,
)
from haptic_bus.errors import ParameterError

__all__ = ["BusLoadMeter", "cycle_bits", "frame_bits", "frame_time"]


@dataclass
class BusLoadMeter:
    """Accumulates the frames of each SYNC cycle at ``bitrate`` bit/s over period ``T`` s.

    Call :meth:`frame` for every frame on the wire and :meth:`sync` at each SYNC (which closes
    the previous cycle and counts the SYNC frame itself into the new one).
    """

    bitrate: float
    period: float
    cycle_bit_counts: list[int] = field(default_factory=list)
    _current: int | None = None

    def __post_init__(self) -> None:
        self.bitrate = checked_bitrate(self.bitrate)
        self.period = checked_period(self.period)

    def sync(self, data_bytes: int = 0) -> None:
        """A SYNC frame (0 or 1 data byte): close the running cycle, start a new one."""
        if self._current is not None:
            self.cycle_bit_counts.append(self._current)
        self._current = frame_bits(data_bytes)

    def frame(self, data_bytes: int) -> None:
        """Any other frame seen or sent during the running cycle."""
        if self._current is None:
            return  # before the first SYNC there is no cycle to charge it to
        self._current += frame_bits(min(data_bytes, MAX_DATA_BYTES))

    def latencies(self) -> list[float]:
        """Per closed cycle, the time in s its frames held the bus (SYNC to last frame's end)."""
        return [bits / self.bitrate for bits in self.cycle_bit_counts]

    def load(self) -> float:
        """Mean bus load over the closed cycles (fraction of ``period``); 0 with none closed."""
        if not self.cycle_bit_counts:
            return 0.0
        return sum(self.cycle_bit_counts) / len(self.cycle_bit_counts) / (self.bitrate * self.period)

    def worst_latency(self) -> float:
        """The longest closed cycle's bus time in s; raises if no cycle closed yet."""
        if not self.cycle_bit_counts:
            raise ParameterError("cycles", 0, "at least one closed SYNC cycle", "bus load meter")
        return max(self.cycle_bit_counts) / self.bitrate
