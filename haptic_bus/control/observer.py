"""A passivity observer beside the loop: the energy exchanged with the operator, at run time.

The wall force ``u`` (N) computed at cycle ``k`` acts on the handle during the interval that
the loop delay ``d`` puts it in; the observer pairs it with the displacement over that
interval: estimated from the velocity samples at both ends (trapezoid, m), or, when the drive's
velocity is the encoder difference over the cycle (``average_velocity``), exactly ``T y_k``.
Two sums, in J:

* ``wall_energy`` -- what the wall has absorbed, ``sum u v T``.  With a loop delay a passive
  interface may well have a wall that gives energy back (the handle's friction takes it), so
  this one is reported, not alarmed on.
* ``interface_energy`` -- what the operator has put into the interface as the gate models
  it, plus what the interface held at the start: the wall's energy plus the configured
  friction's ``b sum v^2 T`` plus the handle's kinetic energy ``m v^2 / 2`` plus
  ``initial_energy`` (the springs the run starts in contact with, ``sum K (x0 - a)^2 / 2``).
  Passivity says the operator can never take out more than that: the sum never goes
  negative.  When it does, the observer counts the cycle and keeps the lowest value.  It
  trusts the configured ``m`` and ``b``: a wrong effective ``b`` is invisible to it (it only
  sees sampled velocity).
"""

from __future__ import annotations

from collections import deque


class PassivityObserver:
    """Energies in J; ``active_cycles`` counts cycles with ``interface_energy < -tolerance``."""

    def __init__(self, period: float, delay: int, mass: float, friction: float, tolerance: float = 0.0,
                 initial_energy: float = 0.0, average_velocity: bool = False) -> None:
        self.period = period
        self.average_velocity = average_velocity
        self.mass = mass
        self.friction = friction
        self.tolerance = tolerance
        self.initial_energy = initial_energy
        self._forces: deque[float] = deque([0.0] * (delay + 1), maxlen=delay + 1)
        self._last_velocity: float | None = None
        self.wall_energy = 0.0
        self.dissipated = 0.0
        self.interface_energy = initial_energy
        self.least_interface_energy = initial_energy
        self.active_cycles = 0

    @property
    def flagged(self) -> bool:
        """True once the interface has given the operator more energy than it took."""
        return self.least_interface_energy < -self.tolerance

    def update(self, velocity: float, force: float) -> float:
        """Account one cycle: the new velocity sample (m/s) and the force (N) just computed;
        returns the interface energy (J)."""
        last = self._last_velocity
        if last is not None:
            T = self.period
            travelled = velocity * T if self.average_velocity else 0.5 * (last + velocity) * T
            self.wall_energy += self._forces[0] * travelled  # the force held over the interval just ended
            self.dissipated += self.friction * 0.5 * (last * last + velocity * velocity) * T
            kinetic = 0.5 * self.mass * velocity * velocity
            self.interface_energy = self.initial_energy + self.wall_energy + self.dissipated + kinetic
            if self.interface_energy < self.least_interface_energy:
                self.least_interface_energy = self.interface_energy
            if self.interface_energy < -self.tolerance:
                self.active_cycles += 1
        self._last_velocity = velocity
        self._forces.append(force)
        return self.interface_energy
