"""A passivity observer beside the loop: the energy the wall has exchanged with the operator.

The wall force ``u`` (N) computed at cycle ``k`` acts on the handle during the interval that
the loop delay ``d`` puts it in; the observer pairs it with the displacement over that
interval, estimated from the velocity samples at both ends (trapezoid, m).  Its sum is the
energy the wall has absorbed (J); a negative sum means the wall has given out more than it
took -- the run-time check of what the gate promised.  Counted, flagged, never hidden.
"""

from __future__ import annotations

from collections import deque


class PassivityObserver:
    """``energy`` (J) absorbed by the wall so far; ``active_cycles`` counts cycles it was < 0."""

    def __init__(self, period: float, delay: int, tolerance: float = 0.0) -> None:
        self.period = period
        self.tolerance = tolerance
        self._forces: deque[float] = deque([0.0] * (delay + 1), maxlen=delay + 1)
        self._last_velocity: float | None = None
        self.energy = 0.0
        self.active_cycles = 0
        self.least_energy = 0.0

    @property
    def flagged(self) -> bool:
        """True once the wall has given out more energy than it took (beyond ``tolerance`` J)."""
        return self.least_energy < -self.tolerance

    def update(self, velocity: float, force: float) -> float:
        """Account one cycle: the new velocity sample (m/s) and the force (N) just computed."""
        if self._last_velocity is not None:
            applied = self._forces[0]  # the force acting over the interval that just ended
            self.energy += applied * 0.5 * (self._last_velocity + velocity) * self.period
            if self.energy < self.least_energy:
                self.least_energy = self.energy
            if self.energy < -self.tolerance:
                self.active_cycles += 1
        self._last_velocity = velocity
        self._forces.append(force)
        return self.energy
