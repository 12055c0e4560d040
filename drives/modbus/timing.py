"""Loop timing of a Modbus poll, and the loop delay (samples, real) the passivity gate assumes.

A Modbus poll is not a CANopen SYNC.  On CANopen every drive samples at the SYNC and applies
the torque at the next one: one whole sample, by construction.  A Modbus drive samples when
the read request reaches it and applies the torque when the write lands; nothing lines the two
up with the controller's period ``T``.

**Reasoning.**  The seed's loop (``D = 0``) has the force computed from the sample ``v_k`` act
over ``[t_k, t_k + T)``, starting at the very instant of the sample.  On a real poll the
sample is taken at ``s_k`` (the read arrives), the torque lands at ``s_k + R`` (the write
arrives), with ``0 < R <= round trip`` (read answer back, compute, write out: ``R`` is less
than the whole cycle's round trip measured at the controller), and it is held until the next
write lands.  The force answering ``v_k`` acts over ``[s_k + R, s_k + R + T)``: a loop delay
of ``D = R / T`` samples, a real number (the analysis takes ``D = d + delta`` exactly, see
:mod:`haptic_bus.analysis.sampled_loop`; rounding it up to whole samples would refuse walls
that are passive).  The gate assumes

    ``D = SAFETY_FACTOR * p99(round trip) / T``

with :data:`SAFETY_FACTOR` = 1.5: the round trip already bounds ``R`` from above, the p99 of a
few hundred polls leaves 1 % of cycles slower, and the factor covers that tail and the drift
between commissioning and the run.  The run's supervisor watches the lateness it then meets.

Two refinements:

- ``cycle="fc23"`` (one read/write request per cycle) reads the next cycle's inputs together
  with this cycle's write.  In a loop paced at ``T`` those inputs are up to ``T`` old when
  they are used: one more sample (:meth:`PollTiming.assumed_delay` adds it).
- The simulated drive (``sim_drive.modbus``) runs in virtual time whatever the wall
  clock does: its plant advances only when the output block is written, so its loop delay is
  its timing's, 0 (``ideal``), 1 (``cia402``) or its reception delay ``delta`` (``reception``),
  read from its registers 0x0050 and 0x0060 (:attr:`ModbusDrive.simulated_delay`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from drives.base import OneAxis
from drives.modbus.drive import ModbusDrive
from drives.ranges import real_in_range

if TYPE_CHECKING:
    from drives.modbus.axes import ModbusAxes

__all__ = ["PollTiming", "SAFETY_FACTOR", "assumed_delay", "measure_poll", "loop_delay", "time_cycles"]

SAFETY_FACTOR = 1.5
"""The gate's loop delay is this many times the p99 round trip (module docstring)."""


def assumed_delay(round_trip_p99: float, T: float) -> float:
    """The loop delay in samples (real) for a poll with this p99 round trip (s) at period ``T`` (s):
    ``SAFETY_FACTOR * round_trip_p99 / T``.  ParameterError for a negative or non-finite round
    trip or a non-positive period."""
    real_in_range("T", T, 0.0, math.inf, low_inclusive=False, unit="s", context="Modbus loop delay")
    real_in_range("round_trip_p99", round_trip_p99, 0.0, math.inf, unit="s", context="Modbus loop delay")
    return SAFETY_FACTOR * round_trip_p99 / T


@dataclass(frozen=True)
class PollTiming:
    """Round trips (s) of ``cycles`` polls (read_inputs + write_outputs) and requests per cycle."""

    cycles: int
    cycle_mode: str
    requests_per_cycle: float
    p50: float
    p99: float
    max: float
    mean: float
    wall_time: float  # s for all cycles

    @property
    def cycles_per_second(self) -> float:
        """Polls per second of wall time (virtual time: as fast as the link allows)."""
        return self.cycles / self.wall_time if self.wall_time > 0 else math.inf

    def assumed_delay(self, T: float) -> float:
        """The real-time loop delay in samples at period ``T`` s: from the p99 round trip, plus
        one sample for fc23 (module docstring)."""
        return assumed_delay(self.p99 + (T if self.cycle_mode == "fc23" else 0.0), T)

    def summary(self) -> str:
        """One line: cycles/s, requests/cycle, round-trip percentiles in microseconds."""
        return (f"{self.cycle_mode}: {self.cycles} cycles, {self.cycles_per_second:.0f} cycles/s, "
                f"{self.requests_per_cycle:.2f} requests/cycle, round trip p50 {self.p50 * 1e6:.0f} us, "
                f"p99 {self.p99 * 1e6:.0f} us, max {self.max * 1e6:.0f} us")


def measure_poll(drive: ModbusDrive | ModbusAxes, cycles: int = 1000, *, time_limit: float = 10.0) -> PollTiming:
    """Poll ``drive`` (one drive, or every axis of :class:`~drives.modbus.axes.ModbusAxes` in one
    cycle) ``cycles`` times back to back (bounded by ``time_limit`` s); the round trips.

    Each cycle is the cyclic phase's read then its write of zero torque, timed from before the
    read to after the (last) write.  Call it before enabling: it then writes the safe outputs
    (DISABLE VOLTAGE, zero torque), and against the simulated drive each cycle advances its
    virtual time by one period.
    """
    axes = OneAxis(drive) if isinstance(drive, ModbusDrive) else drive
    with axes.cyclic() as phase:
        zeros = [0] * len(phase.clamps)

        def poll() -> None:
            phase.read()
            phase.saturate_and_write(zeros)

        return time_cycles(drive, poll, cycles, time_limit)


def time_cycles(drive: ModbusDrive | ModbusAxes, cycle: Callable[[], object], cycles: int, time_limit: float) -> PollTiming:
    """Run ``cycle`` (one exchange with ``drive``) ``cycles`` times back to back, or until one ends
    more than ``time_limit`` s after the first began; each cycle timed (``time.perf_counter``, s)."""
    if cycles < 1:
        raise ValueError(f"cycles = {cycles!r} is invalid; allowed: >= 1")
    samples = np.empty(cycles)
    clock = time.perf_counter
    requests_before = drive.stats.cyclic_requests
    started = clock()
    deadline = started + time_limit
    done = 0
    for i in range(cycles):
        t0 = clock()
        cycle()
        t1 = clock()
        samples[i] = t1 - t0
        done = i + 1
        if t1 > deadline:
            break
    wall = clock() - started
    used = samples[:done]
    p50, p99 = np.percentile(used, [50, 99])
    return PollTiming(
        cycles=done,
        cycle_mode=drive.cycle,
        requests_per_cycle=(drive.stats.cyclic_requests - requests_before) / done,
        p50=float(p50),
        p99=float(p99),
        max=float(used.max()),
        mean=float(used.mean()),
        wall_time=wall,
    )


def loop_delay(drive: ModbusDrive, T: float, poll: PollTiming | None = None) -> float:
    """The loop delay in samples (real) the gate must assume for ``drive`` at period ``T`` s.

    The simulated drive (it announces its timing in register 0x0050): its timing's delay, 0, 1
    or its reception delay, whatever the wall clock.  A real drive: :meth:`PollTiming.assumed_delay`
    of the measured poll (``poll``, from :func:`measure_poll`; required).
    """
    if drive.simulated_delay is not None:
        return drive.simulated_delay
    if poll is None:
        raise ValueError(f"{drive.name} is not the simulated drive: measure its poll first (measure_poll) and pass it")
    return poll.assumed_delay(T)
