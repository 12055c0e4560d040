"""The supervisor's derate, prepared before a one-axis run: for delays beyond the assumed one, the
largest scale of the scene the gate still passes (the control loop never waits for the gate).

Units: loop delays in samples, scales dimensionless in (0, 1].
"""

from __future__ import annotations

import dataclasses

from haptic_bus.control.controller import Derate
from haptic_bus.control.gate import GateDecision, PassivityGate
from haptic_bus.control.scene import CompiledScene

DERATE_SCALE_STEPS = 40  # bisection steps of the derate's margin search inside a passive interval: 2^-40
DERATE_EXTRA_DELAYS = (0.25, 0.5, 1.0, 2.0, 3.0)  # samples beyond the assumed delay a derated scene is prepared for


def prepare_derate(gate: PassivityGate, scene: CompiledScene) -> Derate:
    """The supervisor's derate, prepared before the run (the control loop never waits for the gate):
    for each loop delay :data:`DERATE_EXTRA_DELAYS` beyond the assumed one, the largest scale of
    ``scene`` the gate passes at that delay, judged again whole.  An observed delay is served by
    the first prepared delay at or above it; beyond the table it gets None (the supervisor stops)."""
    assumed = gate.device.delay
    table = [(assumed + extra, _largest_passing_scale(
        PassivityGate(dataclasses.replace(gate.device, delay=assumed + extra), gate.policy), scene))
        for extra in DERATE_EXTRA_DELAYS]

    def derate(running: CompiledScene, observed_delay: float) -> tuple[PassivityGate, CompiledScene, GateDecision] | None:
        return next((entry for delay, entry in table if delay >= observed_delay), None)

    return derate


def _largest_passing_scale(gate: PassivityGate, scene: CompiledScene) -> tuple[PassivityGate, CompiledScene, GateDecision] | None:
    """The scene scaled by the largest ``s`` in (0, 1] that ``gate`` accepts, or None.

    The passive scales are exact intervals (:meth:`PassivityGate.passive_scales`); inside the
    highest one whose lower end the gate accepts, a bisection finds where the policy's safety
    margin is last met.
    """
    if gate.passes(scene):
        return gate, scene, gate.admit(scene)
    for low, high in reversed(gate.passive_scales(scene)):
        low = max(low, 2.0 ** -DERATE_SCALE_STEPS)  # scale 0 is no wall at all: not a derate
        if low > high or not gate.passes(scene.scaled(low)):
            continue
        for _ in range(DERATE_SCALE_STEPS):
            middle = 0.5 * (low + high)
            low, high = (middle, high) if gate.passes(scene.scaled(middle)) else (low, middle)
        scaled = scene.scaled(low)
        decision = gate.judge(scaled)
        if decision.accepted:
            return gate, scaled, decision
    return None
