"""The simulated drive's hardware: the handle ``m dv/dt + b v = w(t) + F``, the hand on it, and their energies.

``w`` is the operator's force (an :class:`~sim_drive.operator.OperatorModel`), ``F`` the
motor force at the handle, held constant over each interval the drive gives it.  Each
interval is split into ``substeps`` exact zero-order-hold steps with the operator force
re-evaluated at the start of each, so the work ``w * dx`` and ``F * dx`` of every step is
exact (:class:`haptic_bus.analysis.plant.ExactPlant`).  SI units: s, m, m/s, N, J.
"""

from __future__ import annotations

from haptic_bus.analysis.plant import ExactPlant
from sim_drive.operator import NoOperator, OperatorModel
from sim_drive.parameters import DeviceParameters


class Handle:
    """The handle's exact motion over held motor forces, the operator, and the energy ledger.

    ``time`` (s) counts the virtual time advanced so far; ``operator_energy`` (J) is what the
    operator put in, ``wall_energy`` (J) what the motor took out (``-sum F dx``).
    """

    def __init__(self, parameters: DeviceParameters, operator: OperatorModel | None = None) -> None:
        self.operator: OperatorModel = operator if operator is not None else NoOperator()
        self.time = 0.0
        self.operator_energy = 0.0
        self.wall_energy = 0.0
        self._plant = ExactPlant(parameters.m, parameters.b, parameters.period / parameters.substeps)
        self._substeps = parameters.substeps
        self._period = parameters.period

    def configure(self, parameters: DeviceParameters) -> None:
        """Take new plant parameters; the handle keeps its velocity and position."""
        plant = self._plant
        self._plant = ExactPlant(parameters.m, parameters.b, parameters.period / parameters.substeps,
                                 plant.velocity, plant.position)
        self._substeps = parameters.substeps
        self._period = parameters.period

    @property
    def velocity(self) -> float:
        """The handle's true velocity in m/s."""
        return self._plant.velocity

    @property
    def position(self) -> float:
        """The handle's true position in m."""
        return self._plant.position

    def advance(self, motor_force: float) -> None:
        """One period with ``motor_force`` (N) held, in exact sub-steps; energies updated."""
        plant = self._plant
        operator = self.operator
        step = plant.step
        t0 = self.time
        for j in range(self._substeps):
            w = operator.force(t0 + j * step, plant.position, plant.velocity)
            dx = plant.advance(w + motor_force)
            self.operator_energy += w * dx
            self.wall_energy -= motor_force * dx
        self.time = t0 + self._period
