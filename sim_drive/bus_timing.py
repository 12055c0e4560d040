"""Bit-time model of classic CAN: worst-case frame lengths, bus load and cycle latency.

A standard (11-bit identifier) data frame with ``n`` data bytes is, on the wire:

==========================================  ===========
field                                       bits
==========================================  ===========
SOF 1, identifier 11, RTR 1, IDE 1, r0 1    15
DLC 4, data 8 n, CRC 15                     19 + 8 n
==========================================  ===========

These first ``34 + 8 n`` bits are subject to bit stuffing: after five equal bits the sender
inserts a complementary bit.  In the worst case (a stuff bit itself starting the next run of
five) there is one stuff bit after the first 5 bits and then one after every further 4, i.e.
``floor((34 + 8 n - 1) / 4)`` stuff bits = ``8 + 2 n``.  Then come the unstuffed CRC
delimiter 1, ACK slot 1, ACK delimiter 1, end of frame 7, and the inter-frame space 3: 13
bits.  Total ``34 + 8 n + 8 + 2 n + 13 = 55 + 10 n`` bit times (DESIGN section 6): 55 for
an empty frame (SYNC), 75 for 2 bytes, 135 for 8 bytes.

The wire carries one frame at a time; :class:`BusLoadMeter` adds up what one SYNC cycle puts
on it (SYNC, TPDOs, RPDOs, anything else seen) to report bus load and the cycle's latency
(the frames sent back to back, no arbitration losses, no processing time).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from drives.errors import ParameterError
from haptic_bus.validation import real_in_range, whole_in_range

MAX_DATA_BYTES = 8
BITRATE_RANGE = (1_000.0, 1_000_000.0)  # bit/s: classic CAN


def frame_bits(data_bytes: int) -> int:
    """Worst-case bit times of a standard data frame with ``data_bytes`` bytes, IFS included."""
    n = whole_in_range("data_bytes", data_bytes, 0, MAX_DATA_BYTES, context="CAN frame")
    return 55 + 10 * n


def frame_time(data_bytes: int, bitrate: float) -> float:
    """Worst-case time in s one such frame holds the bus at ``bitrate`` bit/s."""
    return frame_bits(data_bytes) / _bitrate(bitrate)


def cycle_bits(data_lengths: Sequence[int]) -> int:
    """Bit times of a cycle made of frames with these data lengths (sent back to back)."""
    return sum(frame_bits(n) for n in data_lengths)


def _bitrate(bitrate: float) -> float:
    return real_in_range("bitrate", bitrate, *BITRATE_RANGE, unit="bit/s", context="CAN bus")


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
        self.bitrate = _bitrate(self.bitrate)
        self.period = real_in_range("period", self.period, 0.0, 10.0, low_inclusive=False, unit="s", context="CAN bus")

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
