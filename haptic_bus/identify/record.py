"""What an identification run records each cycle, in the drive's integer units, and its SI view.

Cycle ``k``: 0x6064 and 0x606C sampled at SYNC ``k`` (``kT``), then the target torque 0x6071
written in answer (per mille of rated torque).  The integers are kept as they travelled, so the
fit sees exactly what the drive reported and exactly what it was told to apply (the controller
clips at the force limit itself, below 0x6072, so the drive never clips what was recorded).
A cycle whose inputs were not fresh (a CANopen master repeats the last ones when a TPDO misses
its timeout), or whose period a stall of the machine stretched, is marked, and the fit leaves
out every equation that touches it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from haptic_bus.errors import ParameterError


@dataclass(frozen=True)
class Scale:
    """Drive units at the handle: ``position`` m per 0x6064 increment, ``velocity`` m/s per 0x606C
    unit, ``force`` N per per-mille of 0x6071 (rated torque x transmission / 1000)."""

    position: float
    velocity: float
    force: float


@dataclass(frozen=True)
class Phases:
    """Cycle indices where the phases end: the probe ``[0, probe)``, the excitation
    ``[probe, excitation)``, the settling ``[excitation, end)``."""

    probe: int
    excitation: int


@dataclass(frozen=True)
class Record:
    """One run: per cycle the position and velocity counts sampled at SYNC ``k``, the torque
    (per mille) commanded in answer and whether the inputs were ``fresh``; ``period`` s; ``scale``;
    ``force_limit`` N; ``saturated``: cycles whose command the drive's clamp held at the force
    limit (the torque recorded is the one sent); ``phases``."""

    period: float
    position_counts: np.ndarray
    velocity_counts: np.ndarray
    torque_permille: np.ndarray
    fresh: np.ndarray
    scale: Scale
    force_limit: float
    saturated: int
    phases: Phases

    def __post_init__(self) -> None:
        sizes = {self.position_counts.size, self.velocity_counts.size, self.torque_permille.size, self.fresh.size}
        if len(sizes) != 1:
            raise ParameterError("record", sorted(sizes), "equally long position, velocity, torque and fresh columns")

    @property
    def cycles(self) -> int:
        """Cycles recorded."""
        return int(self.position_counts.size)

    @property
    def position(self) -> np.ndarray:
        """0x6064 in m."""
        return self.position_counts * self.scale.position

    @property
    def velocity(self) -> np.ndarray:
        """0x606C in m/s."""
        return self.velocity_counts * self.scale.velocity

    @property
    def force(self) -> np.ndarray:
        """The motor force at the handle commanded in each cycle, N (positive pushes towards +x)."""
        return self.torque_permille * self.scale.force

    @property
    def excitation_seconds(self) -> float:
        """How long the multisine ran, s."""
        return (self.phases.excitation - self.phases.probe) * self.period

    @property
    def seconds(self) -> float:
        """How long the handle was driven (probe, excitation and settling), s."""
        return self.cycles * self.period


class Recorder:
    """Collects the cycles of a run into preallocated integer columns (at most ``capacity``)."""

    def __init__(self, capacity: int) -> None:
        self._columns = np.zeros((4, capacity), dtype=np.int64)
        self._count = 0
        self.saturated = 0

    def append(self, position_counts: int, velocity_counts: int, torque_permille: int, fresh: bool = True,
               saturated: bool = False) -> None:
        """One cycle (counts as the drive sent them, the per mille sent, whether the inputs were this
        cycle's, whether the drive's clamp held the target at the force limit); beyond capacity: dropped."""
        if self._count < self._columns.shape[1]:
            self.saturated += saturated
            self._columns[:, self._count] = (position_counts, velocity_counts, torque_permille, fresh)
            self._count += 1

    def __len__(self) -> int:
        return self._count

    def record(self, period: float, scale: Scale, force_limit: float, phases: Phases) -> Record:
        """The cycles collected so far as a :class:`Record`."""
        position, velocity, torque, fresh = (column[: self._count].copy() for column in self._columns)
        return Record(period, position, velocity, torque, fresh.astype(bool), scale, force_limit, self.saturated, phases)
