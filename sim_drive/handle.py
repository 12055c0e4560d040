"""The simulated drive's hardware: the handle ``m dv/dt + b v = w(t) + F - Fc sgn(v)``, the hand on it, and their energies.

``w`` is the operator's force (an :class:`~sim_drive.operator.OperatorModel`), ``F`` the motor
force at the handle and ``Fc`` the Coulomb friction (``coulomb_friction``, N).  A period ``T``
is cut into pieces at its events: the ``substeps`` sub-step starts (where the operator force is
re-evaluated and then held), the instant ``delta T`` a new motor force takes over (the
``reception`` timing) and the start ``T - TW`` of a velocity-differencing window.  Over each
piece every force is constant, so the motion is the exact zero-order-hold solution
(:func:`haptic_bus.analysis.plant.zoh_coefficients`, the steps of
:class:`~haptic_bus.analysis.plant.ExactPlant`) and the work ``w dx`` and ``F dx`` of each piece
is exact.  SI units: s, m, m/s, N, J.

**Coulomb friction** (the drive's hidden truth): while the handle moves, a force of constant
magnitude ``Fc`` opposes the motion; at rest it sticks as long as the other forces on it,
``|w + F| <= Fc`` (static and kinetic friction alike), else it starts in the direction of
``w + F``.  Within a piece ``w + F`` is constant, so the velocity is monotone and reaches 0 at
most once: at ``t* = (m u / g) log1p(y) / y``, ``y = b u / g`` (speed ``u``, net decelerating
force ``g = Fc -+ (w + F)``), solved in closed form; there the piece is split, the handle
stops exactly, and it sticks or slides back for the rest of the piece.  So the model is exact
to round-off for the held forces (no event is missed, no step size to choose); what it leaves
out is physics, not numerics: no stiction above ``Fc``, no Stribeck curve, no pre-sliding
displacement, and an operator force that varies within a sub-step is held like any other.

**Energy ledger** (J, all exact per piece): ``operator_energy = sum w dx``, ``wall_energy =
-sum F dx`` (what the motor took out), ``friction_energy = sum Fc |dx|`` (Coulomb
dissipation) and ``viscous_energy = b int v^2 dt`` (in closed form, from the piece's initial
velocity and net force), so ``operator_energy = kinetic energy change + viscous_energy +
friction_energy + wall_energy`` to round-off.

**Measurement states**: a velocity model that is not ``point`` (:mod:`sim_drive.sensor`) is a
:class:`Meter` the handle restarts at the window's start and updates over every stretch of
motion with that stretch's initial velocity, net force and displacement.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Generic, Protocol, TypeVar

from haptic_bus.analysis.plant import exp_divided_difference, phi1, phi2, stop_time, zoh_coefficients
from sim_drive.operator import LET_GO, NoOperator, OperatorModel
from sim_drive.parameters import DeviceParameters

_SERIES_BELOW = 1.0
_STRETCHED_KEPT = 4096  # interval lengths other than T whose pieces are kept
_STEPS_KEPT = 2 * _STRETCHED_KEPT  # piece lengths whose steps are kept (two of a stretched interval's pieces are new)
_SERIES_TERMS = 26  # (2c)^n / (n + 3)! < 1e-20 for c < 1


def _series_constants() -> tuple[tuple[float, float], ...]:
    """``(2^(n+1) - 1, (n + 3)!)`` of :func:`_exp_0_0_c_2c`'s terms, as floats computed as its loop computed them
    on every call (the factorial by the same products, so the same roundings: the same sum)."""
    constants, factorial = [], 6.0
    for n in range(_SERIES_TERMS):
        constants.append((2.0 ** (n + 1) - 1.0, factorial))
        factorial *= n + 4
    return tuple(constants)


_SERIES = _series_constants()


class Meter(Protocol):
    """A velocity measurement's state carried along the handle's motion (see :mod:`sim_drive.sensor`)."""

    @property
    def window(self) -> float | None:
        """The differencing window as a fraction ``TW/T`` of the period (``restart`` is due at ``1 - TW/T``), or None."""

    def coefficients(self, h: float) -> tuple[float, ...]:
        """The meter's constants for a stretch of ``h`` s (computed once per stretch length)."""

    def restart(self) -> None:
        """The window starts now."""

    def track(self, coefficients: tuple[float, ...], v0: float, net: float, dx: float) -> None:
        """A stretch: initial velocity ``v0`` m/s, net force ``net`` N held, displacement ``dx`` m."""


@dataclass(frozen=True, slots=True)
class Step:
    """Exact coefficients of a stretch of ``h`` s with the net force ``f`` held (SI units).

    ``v+ = a v + k1 f``, ``dx = p_v v + p_f f``; the viscous loss ``b int v^2 dt = q_vv v^2 +
    q_vf v f + q_ff f^2`` (J); ``meter`` the measurement's constants (:meth:`Meter.coefficients`).
    """

    h: float
    a: float
    k1: float
    p_v: float
    p_f: float
    q_vv: float
    q_vf: float
    q_ff: float
    meter: tuple[float, ...]


def _exp_0_0_c_2c(c: float) -> float:
    """``exp[0, 0, -c, -2c]`` (dimensionless, ``c >= 0``): positive, limit 1/6 at 0, without cancellation."""
    if c < _SERIES_BELOW:
        # sum_n h_n(0, 0, -c, -2c) / (n + 3)! with h_n = (-c)^n (2^(n+1) - 1)
        total, power = 0.0, 1.0
        for weight, factorial in _SERIES:
            total += power * weight / factorial
            power *= -c
        return total
    return (phi2(c) - exp_divided_difference(0.0, -c, -2.0 * c)) / (2.0 * c)


def viscous_coefficients(m: float, b: float, h: float) -> tuple[float, float, float]:
    """``(q_vv, q_vf, q_ff)`` (kg, s, s^2/kg): ``b int_0^h v^2 dt = q_vv v0^2 + q_vf v0 f + q_ff f^2`` (J), ``f`` N held.

    ``v = v0 a(t) + f k1(t)``, so ``b int v^2 = b (v0^2 int a^2 + 2 v0 f int a k1 + f^2 int k1^2)``
    with ``int a^2 = h phi1(2c)``, ``int a k1 = (h^2/m) exp[0, -c, -2c]`` and
    ``int k1^2 = (2 h^3/m^2) exp[0, 0, -c, -2c]`` (``c = b h / m``): positive terms, exact as ``b -> 0``.
    """
    c = b * h / m
    return (
        b * h * phi1(2.0 * c),
        2.0 * b * h * h / m * exp_divided_difference(0.0, -c, -2.0 * c),
        2.0 * b * h**3 / (m * m) * _exp_0_0_c_2c(c),
    )


StepT = TypeVar("StepT")


@dataclass(frozen=True, slots=True)
class Piece(Generic[StepT]):
    """One piece of the period: its step (a :class:`Step`, or what another plant keeps per piece, e.g. its
    length in s); ``offset`` (s after the SYNC) if a sub-step starts here (the operator force is
    evaluated there), else None; ``now``: the motor force is the new target (else the one before the
    switch); ``restart``: the measurement window starts here."""

    step: StepT
    offset: float | None
    now: bool
    restart: bool


def _nothing() -> None:
    """No measurement window to restart."""


class Handle:
    """The handle's exact motion over held motor forces, the operator, Coulomb friction and the energy ledger.

    ``time`` (s) counts the virtual time advanced so far; ``velocity`` (m/s) and ``position``
    (m) are the true state; the energies are the ledger of the module docstring (J).
    :meth:`advance` is chosen per configuration: the sub-steps inlined when nothing splits them
    (no force switch, no measurement state, no Coulomb friction), else the piece by piece path.
    """

    advance: Callable[[float, float], None]

    def __init__(
        self,
        parameters: DeviceParameters,
        operator: OperatorModel | None = None,
        meter: Meter | None = None,
        switch: float = 0.0,
    ) -> None:
        self.operator: OperatorModel = operator if operator is not None else NoOperator()
        self.hand_on = True  # False: the operator lets go (sim_drive.operator.LET_GO), the drive's torque being off
        self.time = 0.0
        self.velocity = 0.0
        self.position = 0.0
        self.operator_energy = 0.0
        self.wall_energy = 0.0
        self.friction_energy = 0.0
        self.viscous_energy = 0.0
        self.configure(parameters, meter, switch)

    def configure(self, parameters: DeviceParameters, meter: Meter | None = None, switch: float = 0.0) -> None:
        """Take new plant parameters, measurement ``meter`` (None: point) and the fraction ``switch``
        of the period at which a new motor force takes over (0: at the SYNC); the handle keeps its
        velocity and position."""
        m, b, period, substeps = parameters.mass, parameters.friction, parameters.period, parameters.substeps
        self._m, self._b, self._period = m, b, period
        self._coulomb = parameters.coulomb_friction
        self._track = meter.track if meter is not None else None
        self._restart = meter.restart if meter is not None else _nothing
        self._meter_coefficients = meter.coefficients if meter is not None else None
        self._switch, self._window, self._substeps = switch, meter.window if meter is not None else None, substeps
        self._steps: dict[float, Step] = {}  # by piece length: a stretched interval's pieces share lengths
        self._pieces = schedule(period, substeps, switch, self._window, self._kept_step)
        self._stretched: dict[float, list[Piece[Step]]] = {}
        self._offsets = tuple(j * (period / substeps) for j in range(substeps))
        whole = self._step(period / substeps)
        self._coefficients = (whole.a, whole.k1, whole.p_v, whole.p_f, whole.q_vv, whole.q_vf, whole.q_ff)
        plain = not switch and meter is None and not self._coulomb
        self.advance = self._advance_substeps if plain else self._advance_pieces

    def _step(self, h: float) -> Step:
        """The exact :class:`Step` over ``h`` s for the current plant and meter."""
        co = zoh_coefficients(self._m, self._b, h)
        meter = self._meter_coefficients(h) if self._meter_coefficients is not None else ()
        return Step(h, co.a, co.k1, co.p_v, co.p_f, *viscous_coefficients(self._m, self._b, h), meter)

    def _kept_step(self, h: float) -> Step:
        """:meth:`_step` over ``h`` s, kept (the same function of ``h``, so the same numbers): with the velocity
        over the whole period (``average``), an interval longer than ``T`` ends in a window piece exactly ``T``
        long (999 of the 1000 lengths 2.001-3 ms at T = 2 ms), computed once rather than on every SYNC whose
        interval is new (a wall clock's SYNCs: 500-800 new lengths in pre-flight and a 0.5 s run)."""
        step = self._steps.get(h)
        if step is None:
            if len(self._steps) > _STEPS_KEPT:
                self._steps.clear()
            step = self._steps[h] = self._step(h)
        return step

    def _advance_substeps(self, before: float, now: float) -> None:
        """One period with the motor force ``now`` (N) held throughout: the exact sub-steps, inlined."""
        a, k1, p_v, p_f, q_vv, q_vf, q_ff = self._coefficients
        operator = self.operator if self.hand_on else LET_GO
        t0 = self.time
        v, x = self.velocity, self.position
        operator_work = motor_work = loss = 0.0
        for offset in self._offsets:
            w = operator.force(t0 + offset, x, v)
            f = w + now
            dx = p_v * v + p_f * f
            loss += (q_vv * v + q_vf * f) * v + q_ff * f * f
            v = a * v + k1 * f
            x += dx
            operator_work += w * dx
            motor_work += now * dx
        self.velocity, self.position = v, x
        self.operator_energy += operator_work
        self.wall_energy -= motor_work
        self.viscous_energy += loss
        self.time = t0 + self._period

    def _advance_pieces(self, before: float, now: float) -> None:
        """One period: motor force ``before`` (N) until the switch, ``now`` after it, piece by piece."""
        self._run(self._pieces, self._period, before, now)

    def advance_for(self, duration: float, before: float, now: float) -> None:
        """An interval of ``duration`` s instead of one period (a SYNC that came late or early):
        the motor force ``before`` (N) until the switch, ``now`` after it.  The operator is
        evaluated on sub-steps as long as the period's, the switch comes as long after the
        interval's start as in a period (at its end at the latest), and a measurement window
        closes with the interval, as a drive sampling at its own rate does."""
        if duration == self._period:
            self.advance(before, now)
            return
        pieces = stretched_schedule(self._stretched, duration, self._period, self._substeps, self._switch, self._window,
                                    self._kept_step)
        self._run(pieces, duration, before, now)

    def _run(self, pieces: list[Piece[Step]], length: float, before: float, now: float) -> None:
        """The pieces of an interval of ``length`` s: ``before`` (N) until the switch, ``now`` after it."""
        operator = self.operator if self.hand_on else LET_GO
        t0 = self.time
        w = 0.0
        for piece in pieces:
            if piece.restart:
                self._restart()
            if piece.offset is not None:
                w = operator.force(t0 + piece.offset, self.position, self.velocity)
            motor = now if piece.now else before
            dx = self._move(piece.step, w + motor)
            self.operator_energy += w * dx
            self.wall_energy -= motor * dx
        self.time = t0 + length

    def _move(self, step: Step, force: float) -> float:
        """One piece with the external force ``force`` (N) held, Coulomb friction included; the displacement (m)."""
        coulomb = self._coulomb
        if not coulomb:
            return self._segment(step, force)
        v0 = self.velocity
        if v0 == 0.0:  # at rest: it sticks, or starts the way the force pushes (and cannot stop again)
            if abs(force) <= coulomb:
                return self._stick(step)
            direction = 1.0 if force > 0.0 else -1.0
            return self._slide(step, force - direction * coulomb, direction)
        direction = 1.0 if v0 > 0.0 else -1.0
        net = force - direction * coulomb
        if direction * net >= 0.0 or direction * (step.a * v0 + step.k1 * net) > 0.0:  # no stop in this piece
            return self._slide(step, net, direction)
        moving = stop_time(self._m, self._b, direction * v0, -direction * net)
        if moving >= step.h:  # stops at the piece's end (to round-off)
            dx = self._slide(step, net, direction)
            self.velocity = 0.0
            return dx
        dx = self._slide(self._step(moving), net, direction)
        self.velocity = 0.0
        rest = self._step(step.h - moving)
        if abs(force) <= coulomb:
            return dx + self._stick(rest)
        return dx + self._slide(rest, force + direction * coulomb, -direction)

    def _slide(self, step: Step, net: float, direction: float) -> float:
        """A stretch moving in ``direction`` (+-1) under ``net`` N (Coulomb included); its displacement (m)."""
        dx = self._segment(step, net)
        self.friction_energy += self._coulomb * direction * dx
        return dx

    def _stick(self, step: Step) -> float:
        """A stretch at rest (friction balances the forces): no motion, no work; 0 m."""
        if self._track is not None:
            self._track(step.meter, 0.0, 0.0, 0.0)
        return 0.0

    def _segment(self, step: Step, net: float) -> float:
        """The exact motion over ``step`` under the net force ``net`` (N); viscous loss and meter updated; dx (m)."""
        v0 = self.velocity
        dx = step.p_v * v0 + step.p_f * net
        self.viscous_energy += (step.q_vv * v0 + step.q_vf * net) * v0 + step.q_ff * net * net
        self.velocity = step.a * v0 + step.k1 * net
        self.position += dx
        if self._track is not None:
            self._track(step.meter, v0, net, dx)
        return dx


def stretched_schedule(
    kept: dict[float, list[Piece[StepT]]], duration: float, period: float, substeps: int, switch: float,
    window: float | None, step: Callable[[float], StepT]
) -> list[Piece[StepT]]:
    """The pieces of an interval of ``duration`` s standing for a period of ``period`` s (a late or
    early SYNC): sub-steps as long as the period's, the ``switch`` as long after the start (at the
    end at the latest), the window closing with the interval; kept in ``kept`` (bounded)."""
    pieces = kept.get(duration)
    if pieces is None:
        if len(kept) > _STRETCHED_KEPT:
            kept.clear()
        ratio = period / duration
        window = None if window is None else min(1.0, window * ratio)
        pieces = kept[duration] = schedule(duration, max(1, round(substeps / ratio)), min(1.0, switch * ratio), window,
                                           step)
    return pieces


def schedule(
    period: float, substeps: int, switch: float, window: float | None, step: Callable[[float], StepT]
) -> list[Piece[StepT]]:
    """The period's pieces between its events (fractions of ``period``): sub-step starts ``j/substeps``,
    the force ``switch`` and the window's start ``1 - window``.  A piece's length is taken from the
    nearer end of the period, and the window's last stretch is ``window`` itself, so a window of
    1e-9 T keeps its digits (as :func:`haptic_bus.analysis.sampled_loop.period_map` does)."""
    starts = {j / substeps: j for j in range(substeps)}
    events = {0.0, 1.0, switch, *starts}
    left: dict[float, float] = {}
    restart = None
    if window is not None:
        restart = 1.0 - window
        events.add(restart)
        left[restart] = window
    times = sorted(events)
    left = {t: 1.0 - t for t in times} | left
    steps: dict[float, StepT] = {}
    pieces = []
    for start, stop in itertools.pairwise(times):
        length = (stop - start if start < 0.5 else left[start] - left[stop]) * period
        if length not in steps:
            steps[length] = step(length)
        j = starts.get(start)
        pieces.append(Piece(steps[length], None if j is None else j * (period / substeps), start >= switch, start == restart))
    return pieces
