"""One drive's port, cycle by cycle: the observer's energy and the passivity layer's budget.

What a controller does with each drive every cycle (DESIGN 3.6): when the cycle's sample comes
in, close the period it ends with the force(s) the drive applied over it
(:mod:`~haptic_bus.control.port_energy`: with a loop delay of ``d`` whole samples the target
sent ``d`` cycles before acted; with a fractional delay the target changed at an unknown instant
within the period); when the cycle's target goes out, lower it to what the budget allows
(:mod:`~haptic_bus.control.passivity_layer`) and remember it.  A one-axis controller keeps one
:class:`PortAccount`; a multi-axis controller one per axis.
"""

from __future__ import annotations

import math
from collections import deque

from drives.base import CyclicInputs
from haptic_bus.control.clock import CycleClock
from haptic_bus.control.passivity_layer import LayerPolicy, PassivityLayer, default_budget_cap
from haptic_bus.control.port_energy import PortObserver
from haptic_bus.errors import DriveProtocolError


class PortAccount:
    """The port of the drive ``name``: ``observer`` (energy, J) and ``layer`` (the budget's guard).

    ``friction``: ``b_min`` N s/m; ``count``: one 0x6064 increment, m; ``newton_per_permille``: the
    drive's force unit, N; ``delay``: the loop delay the gate assumed, samples; ``clock``: what
    bounds each period's length; ``policy``: the layer's; ``hold``: how long a target may be held,
    s; ``force_limit`` (N) and ``softest_spring`` (N/m, 0: none) size the default budget cap;
    ``initial_energy``: the energy the walls hold at the start, J; ``tolerance``: how far below
    zero the energy may go before a cycle counts as active, J.
    """

    def __init__(self, name: str, *, friction: float, count: float, newton_per_permille: float, delay: float,
                 clock: CycleClock, policy: LayerPolicy, hold: float, force_limit: float, softest_spring: float,
                 initial_energy: float = 0.0, tolerance: float = 0.0) -> None:
        whole = math.floor(delay)
        self.name = name
        self.clock = clock
        self.newton_per_permille = newton_per_permille
        self._latency = whole  # targets sent before the one a period carries (latched at SYNC)
        self._switching = delay != whole  # the target changes at an unknown instant within a period
        committed = whole + self._switching
        cap = policy.budget_cap if policy.budget_cap is not None else default_budget_cap(
            force_limit, friction, hold, committed, softest_spring)
        self.observer = PortObserver(friction, count, initial_energy=initial_energy, cap=cap, tolerance=tolerance)
        self.layer = PassivityLayer(policy.layer, friction, hold, committed, newton_per_permille)
        self._sent: deque[float] = deque([0.0] * (whole + 2), maxlen=whole + 2)  # forces sent, N, newest last
        self._first = True

    def account(self, inputs: CyclicInputs, position_per_count: float) -> float:
        """The port's energy (J) up to this cycle's sample: the period it closes, with the force(s)
        the drive applied over it; a stale input closes none (the next fresh one closes both)."""
        observer = self.observer
        position = inputs.position
        if position is None:
            raise DriveProtocolError(self.name, "the cyclic inputs carry no position (0x6064): the port "
                                                "observer and the passivity layer need it mapped")
        if self._first:
            self._first = False
        else:
            fresh = not inputs.age
            duration = self.clock.period_bound(inputs.sampled_by_ns if fresh else 0)
            sent, latency = self._sent, self._latency
            if self._switching:
                observer.switch(sent[-2 - latency], sent[-1 - latency], duration)
            else:
                observer.apply(sent[-1 - latency], duration)
            if not fresh:
                return observer.energy
        return observer.sample(position * position_per_count)

    def limit(self, torque: int) -> int:
        """The target to send instead of ``torque`` (per mille): lowered to what the budget allows,
        and remembered as sent."""
        torque = self.layer.limit(torque, self.observer.budget)
        self._sent.append(torque * self.newton_per_permille)
        return torque
