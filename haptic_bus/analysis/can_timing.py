"""Bit-time model of classic CAN, and the bus load of a SYNC cycle against its ceiling (issue 22).

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

**The load of a cycle** (:func:`bus_load`): one SYNC (0 bytes) per period serves every axis;
each axis adds its TPDO and RPDO frames.  The load is the cycle's bits over ``bitrate T``;
above ``LOAD_CEILING`` (70 %) the cycle has no room left for SDO, EMCY, heartbeats and
retransmissions, and :func:`check_bus_load` refuses it, naming the load and the smallest ``T``
that fits.  Pure arithmetic: used by the benchmark, the simulated drive's load meter
(``sim_drive.bus_timing``) and a multi-axis profile's check on load.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from haptic_bus.errors import ParameterError
from haptic_bus.validation import real_in_range, whole_in_range

MAX_DATA_BYTES = 8
BITRATE_RANGE = (1_000.0, 1_000_000.0)  # bit/s: classic CAN
LOAD_CEILING = 0.7
_PERIOD_RANGE = (0.0, 10.0)  # s, exclusive low


def frame_bits(data_bytes: int) -> int:
    """Worst-case bit times of a standard data frame with ``data_bytes`` bytes, IFS included."""
    n = whole_in_range("data_bytes", data_bytes, 0, MAX_DATA_BYTES, context="CAN frame")
    return 55 + 10 * n


def frame_time(data_bytes: int, bitrate: float) -> float:
    """Worst-case time in s one such frame holds the bus at ``bitrate`` bit/s."""
    return frame_bits(data_bytes) / checked_bitrate(bitrate)


def cycle_bits(data_lengths: Sequence[int]) -> int:
    """Bit times of a cycle made of frames with these data lengths (sent back to back)."""
    return sum(frame_bits(n) for n in data_lengths)


def checked_bitrate(bitrate: float) -> float:
    """``bitrate`` (bit/s) as a float in :data:`BITRATE_RANGE`, else ParameterError."""
    return real_in_range("bitrate", bitrate, *BITRATE_RANGE, unit="bit/s", context="CAN bus")


def checked_period(period: float) -> float:
    """A SYNC period ``T`` (s) in (0, 10], else ParameterError."""
    return real_in_range("period", period, *_PERIOD_RANGE, low_inclusive=False, unit="s", context="CAN bus")


def axes_that_fit(per_axis: int, bitrate: float, period: float, ceiling: float = LOAD_CEILING) -> int:
    """How many axes of ``per_axis`` bits each fit with the SYNC in ``ceiling`` of the bus over ``period`` s."""
    budget = ceiling * checked_bitrate(bitrate) * checked_period(period) - frame_bits(0)
    return max(0, math.floor(budget / per_axis))


@dataclass(frozen=True)
class BusLoad:
    """One SYNC cycle on the wire: ``bits`` per cycle (worst-case stuffing), ``load`` (fraction of
    ``bitrate T``), the ``ceiling``, and ``smallest_period`` (s), the least ``T`` under the ceiling."""

    axes: int
    bits: int
    bitrate: float
    period: float
    load: float
    ceiling: float
    smallest_period: float

    @property
    def fits(self) -> bool:
        """Whether the load stays at or under the ceiling."""
        return self.load <= self.ceiling

    def describe(self) -> str:
        """``bus load 84.8 % of 125 kbit/s at T = 1 ms (3 axes, 850 bits per cycle)``."""
        return (f"bus load {100 * self.load:.1f} % of {self.bitrate / 1000:g} kbit/s at T = {1000 * self.period:g} ms "
                f"({self.axes} {'axis' if self.axes == 1 else 'axes'}, {self.bits} bits per cycle, worst-case stuffing)")


def bus_load(frames_per_axis: Sequence[Sequence[int]], bitrate: float, period: float,
             ceiling: float = LOAD_CEILING) -> BusLoad:
    """The load of one SYNC plus every axis' frames (data lengths in bytes) at ``bitrate`` bit/s every ``period`` s."""
    bitrate, period = checked_bitrate(bitrate), checked_period(period)
    bits = frame_bits(0) + sum(cycle_bits(frames) for frames in frames_per_axis)
    return BusLoad(len(frames_per_axis), bits, bitrate, period, bits / (bitrate * period), ceiling,
                   bits / (ceiling * bitrate))


def check_bus_load(frames_per_axis: Sequence[Sequence[int]], bitrate: float, period: float,
                   ceiling: float = LOAD_CEILING) -> BusLoad:
    """:func:`bus_load`, or ParameterError naming the load and the smallest ``T`` that fits when above ``ceiling``."""
    load = bus_load(frames_per_axis, bitrate, period, ceiling)
    if not load.fits:
        raise ParameterError("period", period, f"a bus load <= {100 * ceiling:g} % ({load.describe()}): "
                             f"T >= {1000 * load.smallest_period:.4g} ms at this bitrate", "bus load")
    return load
