"""The joints' positions: where each starts, from its drive's 0x6064 (m), and where it is after each
cycle, integrated from its 0x606C as the seed's backward difference does, ``q_k = q_{k-1} + T v_k``,
in the drive's integer velocity units (an exact integer sum, so ten million cycles add no rounding).
"""

from __future__ import annotations

from drives.base import AxesDrive, Drive
from drives.cia402 import POSITION_ACTUAL


def encoder_origin(drive: Drive, sampled: bool = False) -> float:
    """The handle's absolute position (m) from 0x6064, read once, acyclically, before cycling;
    ``sampled``: the one the drive's last cyclic inputs carried where they carry it (right after
    pre-flight's cycles: no SDO round trip between their last RPDO and the enable)."""
    last = drive.last_inputs if sampled else None
    counts = last.position if last is not None and last.position is not None else drive.read_object(POSITION_ACTUAL)
    return counts * drive.scaling.position_per_count


def encoder_origins(axes: AxesDrive, sampled: bool = False) -> list[float]:
    """Every axis' joint position (m) from its 0x6064 (:func:`encoder_origin`)."""
    return [encoder_origin(drive, sampled) for drive in axes.drives]


class PositionIntegrator:
    """``x_k = x_0 + T * velocity_per_count * sum(v_counts)``: an exact integer sum, one rounding
    (``x_0``, m: 0 until :meth:`start` sets it from the first sample)."""

    __slots__ = ("counts", "origin", "step")

    def __init__(self, period: float, velocity_per_count: float) -> None:
        self.step = period * velocity_per_count  # m per (count * cycle)
        self.origin = 0.0
        self.counts = 0

    def add(self, velocity_counts: int) -> float:
        """Accumulate one velocity sample (0x606C units); return the position in m."""
        self.counts += velocity_counts
        return self.origin + self.step * self.counts

    @property
    def position(self) -> float:
        """The position (m) after the latest sample."""
        return self.origin + self.step * self.counts

    def start(self, position: float, velocity_counts: int) -> float:
        """The first sample: the joint is at ``position`` (m, its 0x6064), and the sum starts with this
        sample's velocity (0x606C units); returns the position in m."""
        self.origin = position - self.step * velocity_counts
        return self.add(velocity_counts)
