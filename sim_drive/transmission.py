"""A handle that is not rigid: a motor-side mass coupled to the handle by a spring and a damper (hidden truth).

``haptic-bus sim --transmission STIFFNESS:DAMPING:MOTOR_MASS`` (N/m, N s/m, kg) puts a belt,
cable or gearbox between the motor, where the encoder and the torque are, and the handle, where
the operator is::

    M dv_m/dt = F - k (x_m - x_h) - c (v_m - v_h)
    m dv_h/dt = w - b v_h + k (x_m - x_h) + c (v_m - v_h)

``M`` the motor-side mass, ``m`` and ``b`` the handle's mass and viscous friction (the profile's),
``k``/``c`` the transmission's stiffness and damping, ``F`` the motor force (held by the drive),
``w`` the operator's force (held over each sub-step).  With the handle free the transmission
resonates at ``sqrt(k (1/M + 1/m))`` rad/s (k 20000 N/m, M 0.3 kg, m 1 kg: 46.9 Hz).

Between events the state ``[v_m, x_m, v_h, x_h]`` moves exactly: one matrix exponential of the
system augmented by its two held inputs per piece length (cached), as the rigid
:class:`~sim_drive.handle.Handle` does in closed form.  The encoder (0x6064, 0x606C) reads the
motor side: :attr:`TwoMassHandle.velocity` and :attr:`TwoMassHandle.position` are the motor's,
:attr:`TwoMassHandle.handle_velocity` and :attr:`TwoMassHandle.handle_position` the handle's (m/s, m).

Energy ledger (J): ``operator_energy = sum w dx_h``, ``wall_energy = -sum F dx_m`` (exact per
piece), ``viscous_energy`` what ``b`` and ``c`` dissipated together, from the balance
``operator work + motor work - change of kinetic and spring energy``.  Not modelled with a
transmission (refused by :class:`~sim_drive.parameters.DeviceParameters`): Coulomb friction and a
low-pass velocity filter.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import numpy as np

from haptic_bus.analysis.transmission import Transmission
from sim_drive.handle import Meter, Piece, schedule, stretched_schedule
from sim_drive.operator import LET_GO, NoOperator, OperatorModel

if TYPE_CHECKING:
    from sim_drive.parameters import DeviceParameters

@functools.lru_cache(maxsize=256)
def _discrete(m: float, b: float, transmission: Transmission, h: float) -> tuple[np.ndarray, np.ndarray]:
    """``(Ad, Bd)`` over ``h`` s: ``s+ = Ad s + Bd [F, w]`` for ``s = [v_m, x_m, v_h, x_h]`` (SI units), exact."""
    from scipy.linalg import expm  # lazily: only a simulated drive with a transmission needs scipy here

    k, c, big = transmission.stiffness, transmission.damping, transmission.motor_mass
    block = np.zeros((6, 6))
    block[:4, :4] = [[-c / big, -k / big, c / big, k / big],
                     [1.0, 0.0, 0.0, 0.0],
                     [c / m, k / m, -(b + c) / m, -k / m],
                     [0.0, 0.0, 1.0, 0.0]]
    block[0, 4] = 1.0 / big  # the motor force acts on the motor side
    block[2, 5] = 1.0 / m  # the operator's on the handle
    e = expm(block * h)
    return e[:4, :4].copy(), e[:4, 4:].copy()


class TwoMassHandle:
    """The motor and the handle moving together through the transmission (module docstring).

    The same interface as :class:`~sim_drive.handle.Handle` (``advance``, ``advance_for``,
    ``configure``, ``time`` s, ``velocity`` m/s and ``position`` m of what the encoder sees, the
    energy ledger in J) so that the drive and its sensor do not know which one they move.
    """

    def __init__(self, transmission: Transmission, operator: OperatorModel | None = None) -> None:
        self.transmission = transmission
        self.operator: OperatorModel = operator if operator is not None else NoOperator()
        self.hand_on = True  # False: the operator lets go (sim_drive.operator.LET_GO), the drive's torque being off
        self.time = 0.0
        self.state = np.zeros(4)
        self.operator_energy = 0.0
        self.wall_energy = 0.0
        self.friction_energy = 0.0  # no Coulomb friction with a transmission
        self.viscous_energy = 0.0
        self._stretched: dict[float, list[Piece[float]]] = {}

    @property
    def velocity(self) -> float:
        """The motor side's velocity, m/s (what 0x606C measures)."""
        return float(self.state[0])

    @property
    def position(self) -> float:
        """The motor side's position, m (what 0x6064 counts)."""
        return float(self.state[1])

    @property
    def handle_velocity(self) -> float:
        """The handle's velocity, m/s (where the operator is)."""
        return float(self.state[2])

    @property
    def handle_position(self) -> float:
        """The handle's position, m."""
        return float(self.state[3])

    def place(self, velocity: float, position: float) -> None:
        """Both sides moving at ``velocity`` m/s at ``position`` m, the spring relaxed (taking over a rigid handle)."""
        self.state = np.array([velocity, position, velocity, position], dtype=float)

    def mechanical_energy(self) -> float:
        """Kinetic energy of both masses plus the transmission spring's, J."""
        v_m, x_m, v_h, x_h = self.state
        return float(0.5 * (self.transmission.motor_mass * v_m * v_m + self._m * v_h * v_h
                            + self.transmission.stiffness * (x_m - x_h) ** 2))

    def configure(self, parameters: DeviceParameters, meter: Meter | None = None, switch: float = 0.0) -> None:
        """Take the handle's mass, friction, period and sub-steps from ``parameters``, a differencing
        ``meter`` (None: point) and the fraction ``switch`` of the period at which a new motor force
        takes over; the state is kept."""
        self._m, self._b = parameters.mass, parameters.friction
        self._period, self._substeps = parameters.period, parameters.substeps
        self._meter = meter
        self._switch = switch
        self._window = meter.window if meter is not None else None
        self._pieces = schedule(self._period, self._substeps, switch, self._window, float)
        self._stretched.clear()
        for piece in self._pieces:  # the period's exponentials now (and scipy imported): no first SYNC seconds late
            _discrete(self._m, self._b, self.transmission, piece.step)

    def advance(self, before: float, now: float) -> None:
        """One period: motor force ``before`` (N) until the switch, ``now`` after it."""
        self._run(self._pieces, self._period, before, now)

    def advance_for(self, duration: float, before: float, now: float) -> None:
        """An interval of ``duration`` s instead of one period, as :meth:`~sim_drive.handle.Handle.advance_for` does."""
        if duration == self._period:
            self.advance(before, now)
            return
        pieces = stretched_schedule(self._stretched, duration, self._period, self._substeps, self._switch, self._window,
                                    float)
        self._run(pieces, duration, before, now)

    def _run(self, pieces: list[Piece[float]], length: float, before: float, now: float) -> None:
        """The pieces of an interval of ``length`` s, each exact with its forces held."""
        operator, meter, transmission = self.operator if self.hand_on else LET_GO, self._meter, self.transmission
        t0 = self.time
        w = 0.0
        energy = self.mechanical_energy()
        for piece in pieces:
            if piece.restart and meter is not None:
                meter.restart()
            if piece.offset is not None:
                w = operator.force(t0 + piece.offset, self.handle_position, self.handle_velocity)
            motor = now if piece.now else before
            ad, bd = _discrete(self._m, self._b, transmission, piece.step)
            old = self.state
            self.state = ad @ old + bd @ np.array([motor, w])
            dx_m, dx_h = self.state[1] - old[1], self.state[3] - old[3]
            if meter is not None:
                meter.track((), float(old[0]), 0.0, float(dx_m))
            self.operator_energy += w * dx_h
            self.wall_energy -= motor * dx_m
            self.viscous_energy += w * dx_h + motor * dx_m
        after = self.mechanical_energy()
        self.viscous_energy -= after - energy
        self.time = t0 + length
