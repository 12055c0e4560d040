"""The passivity layer: every torque target fits the port's energy budget (DESIGN 3.6).

A force ``F`` (N) that the drive holds for ``tau`` s can take at most ``F^2 tau / (4 b)`` J
out of the port's energy ``E`` (:mod:`~haptic_bus.control.port_energy`): the least of
``b dx^2 / tau - F dx`` over every displacement.  So a new target keeps ``E >= 0`` for every
motion of the handle iff, at the moment it is decided,

    F_new^2 tau / (4 b) <= E_c - sum over the targets already sent and not yet paid of F_j^2 tau / (4 b),

with ``E_c`` the capped budget up to the latest sample.  "Not yet paid": the targets whose
periods have not ended at that sample -- with a loop delay of ``d`` whole samples the ``d``
targets sent before this one (one of them acting now, the others latched in turn), and with a
target that acts at an unknown instant within a period one more.  The layer lowers ``|F|`` to
the largest value that fits (rounded down to the drive's per-mille unit), and never raises it.

How long a target may be held is the mode's:

``guard``
    one period ``T``: what a drive latching every SYNC on time holds.  Exact when the timing
    is; a cycle that comes late holds its target longer than budgeted, which the observer
    then sees (the supervisor counts it).  For a wall the gate passes the budget is never
    reached under nominal timing: the layer acts only when the observer's budget nears zero.
``bound``
    ``hold`` s, the longest the drive can hold any target before its RPDO deadline (or Modbus
    watchdog) faults it: rigorous for any timing the machine produces, at the price of a
    budget ``hold / T`` times larger per target, i.e. a softer wall (README, "The passivity
    layer").
``off``
    the targets pass unchanged; the observer still watches.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from haptic_bus.errors import ParameterError

LAYER_MODES = ("off", "guard", "bound")


@dataclass(frozen=True)
class LayerPolicy:
    """``[passivity]`` of a profile: ``layer`` ("off", "guard", "bound"), ``budget_cap`` (J, the
    ceiling of the stored budget; None: :func:`default_budget_cap`), ``beyond_gate`` (with
    ``bound`` only: walls the gate refuses are run anyway, the layer guaranteeing passivity)."""

    layer: str = "guard"
    budget_cap: float | None = None
    beyond_gate: bool = False

    def __post_init__(self) -> None:
        if self.layer not in LAYER_MODES:
            raise ParameterError("layer", self.layer, " or ".join(map(repr, LAYER_MODES)), "passivity")
        if self.budget_cap is not None and not (isinstance(self.budget_cap, (int, float)) and 0 < self.budget_cap < math.inf):
            raise ParameterError("budget_cap", self.budget_cap, "a finite energy > 0 J", "passivity")
        if self.beyond_gate and self.layer != "bound":
            raise ParameterError("beyond_gate", self.beyond_gate, "false unless layer = \"bound\" (only the bound "
                                 "guarantees passivity for walls the gate refuses)", "passivity")


def default_budget_cap(force_limit: float, friction: float, hold: float, committed: int, softest_spring: float) -> float:
    """The budget's ceiling (J): what the layer needs to render the force limit (N) with every
    committed target held ``hold`` s, plus the energy a spring of ``softest_spring`` N/m (the
    scene's softest; 0: none) stores at that force -- so a wall pushed to the limit gets its
    energy back -- and nothing more to save up."""
    reserve = (committed + 1) * force_limit * force_limit * hold / (4.0 * friction)
    stored = force_limit * force_limit / (2.0 * softest_spring) if softest_spring > 0 else 0.0
    return reserve + stored


class PassivityLayer:
    """Lowers each torque target (per mille) to what the port's budget allows (module docstring).

    ``mode``: one of :data:`LAYER_MODES`; ``friction``: ``b_min`` N s/m; ``hold``: how long the
    drive may hold a target, s (``guard``: the period); ``committed``: the targets sent and not
    yet paid when a new one is decided (``d``, plus one for a change at an unknown instant);
    ``newton_per_permille``: the drive's force unit (N).
    """

    __slots__ = ("mode", "hold", "newton_per_permille", "interventions", "removed", "_scale", "_sent")

    def __init__(self, mode: str, friction: float, hold: float, committed: int, newton_per_permille: float) -> None:
        if mode not in LAYER_MODES:
            raise ParameterError("layer", mode, " or ".join(map(repr, LAYER_MODES)), "passivity")
        if not 0.0 < hold < math.inf:
            raise ParameterError("hold", hold, "a finite time > 0 s", "passivity")
        self.mode = mode
        self.hold = hold
        self.newton_per_permille = newton_per_permille
        self.interventions = 0  # cycles whose target the layer lowered
        self.removed = 0.0  # force the layer took off the latest target, N
        self._scale = 4.0 * friction / hold  # E -> F^2
        self._sent: deque[float] = deque([0.0] * committed, maxlen=committed) if committed else deque(maxlen=0)

    def limit(self, torque: int, budget: float) -> int:
        """The target to send instead of ``torque`` (per mille), given the capped budget ``budget`` (J)
        up to the latest sample; remembers it as sent."""
        unit = self.newton_per_permille
        force = torque * unit
        if self.mode != "off":
            reserve = 0.0
            for sent in self._sent:
                reserve += sent * sent
            allowed_squared = self._scale * budget - reserve
            if force * force > allowed_squared:
                allowed = math.floor(math.sqrt(allowed_squared) / unit) if allowed_squared > 0.0 else 0
                lowered = allowed if torque > 0 else -allowed
                self.interventions += 1
                self.removed = (torque - lowered) * unit
                torque, force = lowered, lowered * unit
            else:
                self.removed = 0.0
        if self._sent.maxlen:
            self._sent.append(force)
        return torque
