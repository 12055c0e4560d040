"""Energy from positions: the exact passivity observer on the drive's port (DESIGN 3.6).

In cyclic synchronous torque mode the drive changes its torque only at SYNC and samples 0x6064
at SYNC.  Over the interval between two position samples the motor force is known piece by
piece (the master sent every target and knows which SYNC latched it), the positions at both
ends are measured, and nothing else about the motion is.  The handle obeys
``m dv/dt + b v = w + F`` (``w`` the operator, ``F`` the motor force on the handle), so the
operator's work over an interval is ``dKE + int b v^2 dt - int F v dt``.

**One interval.**  Let the interval carry forces ``F_j`` (N) for durations ``tau_j`` (s),
``S = sum tau_j``, with a measured total displacement ``dx`` (m) and an unknown split of it
between the pieces.  Cauchy-Schwarz per piece, ``int v^2 >= dx_j^2 / tau_j``, and the least
value over every split ``sum dx_j = dx`` (a Lagrange multiplier ``lambda``):

    min sum (b dx_j^2 / tau_j - F_j dx_j) = ((2 b dx - A)^2 / S - Q) / (4 b),
    A = sum F_j tau_j,  Q = sum F_j^2 tau_j,  lambda = (2 b dx - A) / S.

One piece gives ``b dx^2 / T - F dx``, the design notes' term.  A target that changes at an
instant the master does not know (a drive that applies the target on reception, a Modbus
write) is a two-piece interval whose split fraction ``s`` is unknown; the expression is
``b dx^2 / S - (F2 + G s) dx - G^2 S s (1 - s) / (4 b)`` with ``G = F1 - F2``, convex in
``s``, and the observer takes its least value over ``s`` in [0, 1].  An interval whose end
sample is missing (a missed TPDO) joins the next one: its pieces add up.

**The sum.**  ``E(n) = E(0) + sum`` of those terms, with ``b = b_min`` (the profile's friction:
the lowest credible identified ``b``; any true ``b >= b_min`` and any Coulomb friction only
dissipate more).  The operator's work since the start is at least ``E(n) - E(0) - KE(0)``, for
any timing, delay or velocity model: ``E(n) >= 0`` for all ``n`` means passive.  ``E(0)`` is
the energy the walls hold at the start (a start in contact), as the gate's observer has it.

**Counts rounding.**  0x6064 is the true position rounded to a count ``q`` (m) by some
convention: the error ``e_k`` of a sample is within one count.  Each term is a quadratic in
``dx`` with slope ``lambda`` and curvature ``2 b / S >= 0``, so the true term is at least the
measured one minus ``lambda (e_k - e_(k-1))``; summed by parts the true ``E`` is at least the
measured one minus ``rounding = q (|lambda_first| + |lambda_last| + sum |lambda_k -
lambda_(k-1)|)`` (J), which the observer gives beside ``E`` (from the slopes it keeps).

**The budget** (:mod:`~haptic_bus.control.passivity_layer`) spends a capped copy of the same
sum: ``E_c(n) = min(E_c(n-1) + term, cap)`` is never above ``E(n)``, so ``E_c >= 0`` is as good
a proof, and friction paid during a long free motion cannot be saved up beyond ``cap`` for a
wall to spend later.
"""

from __future__ import annotations

import math

from haptic_bus.errors import ParameterError


def interval_energy(friction: float, displacement: float, forces: list[float], durations: list[float]) -> tuple[float, float]:
    """``(term, slope)``: the least ``sum (b dx_j^2 / tau_j - F_j dx_j)`` (J) over every split of
    ``displacement`` (m) among pieces with ``forces`` (N) held for ``durations`` (s), and its
    slope ``lambda`` (N) in the displacement (module docstring); ``friction`` b > 0 N s/m."""
    span = impulse = square = 0.0
    for force, tau in zip(forces, durations):
        span += tau
        impulse += force * tau
        square += force * force * tau
    return pieces_energy(friction, displacement, span, impulse, square)


def pieces_energy(friction: float, displacement: float, span: float, impulse: float, square: float) -> tuple[float, float]:
    """:func:`interval_energy` from the pieces' sums, each taken in the pieces' order from 0.0: ``span``
    ``S = sum tau_j`` (s), ``impulse`` ``A = sum F_j tau_j`` (N s), ``square`` ``Q = sum F_j^2 tau_j`` (N^2 s)."""
    slope = (2.0 * friction * displacement - impulse) / span
    return (slope * slope * span - square) / (4.0 * friction), slope


def switch_energy(friction: float, displacement: float, before: float, after: float, span: float) -> tuple[float, float]:
    """``(term, slope)`` for an interval of ``span`` s whose force changes from ``before`` to
    ``after`` (N) at an unknown instant: the least term over the split fraction in [0, 1]."""
    g = before - after
    if g == 0.0:
        return interval_energy(friction, displacement, [after], [span])
    # term(s) = b dx^2/S - (after + g s) dx - g^2 S s (1 - s) / (4 b): convex, least at s*
    curvature = g * g * span / (4.0 * friction)
    s = min(1.0, max(0.0, 0.5 + g * displacement / (2.0 * curvature)))
    return interval_energy(friction, displacement, [before, after], [s * span, (1.0 - s) * span])


class PortObserver:
    """The port energy ``E`` (J) from sampled positions and the forces applied between them.

    ``friction``: ``b_min`` > 0 N s/m; ``count``: one 0x6064 increment (m), the rounding bound's
    unit; ``initial_energy``: ``E(0)`` (J); ``cap``: the budget's ceiling (J, ``inf``: none);
    ``tolerance``: how far below zero ``E`` may go before a cycle counts as active (J).

    Feed it with :meth:`apply` (a force, N, held for a duration, s, or a change at an unknown
    instant) as the drive applies them, and :meth:`sample` (a position, m) when a sample
    arrives; :meth:`energy` etc. read the state.
    """

    __slots__ = ("friction", "count", "tolerance", "cap", "energy", "budget", "least", "active_cycles",
                 "_position", "_pieces", "_span", "_impulse", "_square", "_switches", "_slope_first", "_slope_last",
                 "_variation")

    def __init__(self, friction: float, count: float, *, initial_energy: float = 0.0, cap: float = math.inf,
                 tolerance: float = 0.0) -> None:
        if not (isinstance(friction, (int, float)) and 0.0 < friction < math.inf):
            raise ParameterError("friction", friction, "b_min > 0 N s/m (the port observer's dissipation credit)",
                                 "port observer")
        if not (isinstance(count, (int, float)) and 0.0 <= count < math.inf):
            raise ParameterError("count", count, "a position increment >= 0 m", "port observer")
        if not (isinstance(cap, (int, float)) and cap > 0.0):
            raise ParameterError("cap", cap, "a budget ceiling > 0 J (inf: none)", "port observer")
        self.friction = float(friction)
        self.count = float(count)
        self.tolerance = tolerance
        self.cap = float(cap)
        self.energy = initial_energy
        self.budget = min(initial_energy, self.cap)
        self.least = initial_energy
        self.active_cycles = 0
        self._position: float | None = None
        self._pieces = 0  # forces applied since the last sample, kept as the sums pieces_energy takes (no list a cycle)
        self._span = self._impulse = self._square = 0.0
        self._switches: list[tuple[float, float, float]] = []  # (before, after, span) of unknown-instant changes
        self._slope_first: float | None = None
        self._slope_last = 0.0
        self._variation = 0.0

    def apply(self, force: float, duration: float) -> None:
        """The drive held ``force`` (N, on the handle, in the direction of +x) for ``duration`` s."""
        self._pieces += 1
        self._span += duration
        self._impulse += force * duration
        self._square += force * force * duration

    def switch(self, before: float, after: float, duration: float) -> None:
        """Over ``duration`` s the force changed from ``before`` to ``after`` (N) at an unknown instant."""
        self._switches.append((before, after, duration))

    def sample(self, position: float) -> float:
        """A position sample (m) at the end of what was applied since the last one; returns ``E`` (J).
        The first sample only sets the origin."""
        last = self._position
        self._position = position
        switches = self._switches
        pieces, span, impulse, square = self._pieces, self._span, self._impulse, self._square
        if pieces:
            self._pieces = 0
            self._span = self._impulse = self._square = 0.0
        if last is None:  # the origin: whatever was applied before it is no interval
            switches.clear()
            return self.energy
        displacement = position - last
        friction = self.friction
        if not switches:
            term, slope = pieces_energy(friction, displacement, span, impulse, square)
        elif len(switches) == 1 and not pieces:
            term, slope = switch_energy(friction, displacement, *switches[0])
            switches.clear()
        else:  # a missed sample across a change at an unknown instant: each piece's worst case, dx dropped
            term = -square / (4.0 * friction)
            term -= sum(max(a * a, b * b) * s for a, b, s in switches) / (4.0 * friction)
            slope = 0.0
            switches.clear()
        if self._slope_first is None:
            self._slope_first = slope
        else:
            self._variation += abs(slope - self._slope_last)
        self._slope_last = slope
        energy = self.energy = self.energy + term
        budget = self.budget + term
        self.budget = budget if budget < self.cap else self.cap
        if energy < self.least:
            self.least = energy
        if energy < -self.tolerance:
            self.active_cycles += 1
        return energy

    @property
    def rounding(self) -> float:
        """The counts rounding bound (J) of ``E`` so far (module docstring): ``q (|lambda_first| + |lambda_last| +
        sum |lambda_k - lambda_(k-1)|)``, 0 before the first interval; read when asked (a run's summary), not kept
        up to date every cycle."""
        first = self._slope_first
        return 0.0 if first is None else self.count * (abs(first) + abs(self._slope_last) + self._variation)

    @property
    def flagged(self) -> bool:
        """True once ``E`` went more than ``tolerance`` below zero."""
        return self.least < -self.tolerance
