"""One identification run, cycle by cycle: probe, excitation, settling -- bus-free.

The caller runs the cycle (read the inputs, :meth:`Session.step` with the sampled position,
write the force it returns) until :attr:`Session.done`; whatever drives it (a CANopen or Modbus
drive, the simulated drive in-process) sees the same forces for the same positions.

1. **probe** (:mod:`~haptic_bus.identify.probe`): refuses a handle that is not free to move;
2. **excitation** for ``duration`` s: the multisine times the servoed amplitude plus the holding
   loop around the start position (:mod:`~haptic_bus.identify.excitation`); it ends early if
   the handle leaves the travel envelope;
3. **settling** for :data:`SETTLE_SECONDS`: the multisine faded out, the holding loop alone slows
   the handle before the drive is disabled.

The forces are asked, not clipped: the caller's drive clamps each at the plan's force limit
(:class:`drives.base.TorqueClamp`, the one place a target is saturated), and the torque recorded
is the one it sent.  Units: s, m, N.
"""

from __future__ import annotations

import math
from collections.abc import Generator
from dataclasses import dataclass

from haptic_bus.errors import ParameterError
from haptic_bus.identify.bounds import DURATION_RANGE, TRAVEL_RANGE
from haptic_bus.identify.excitation import (
    GUARD_SECONDS,
    TARGET_SHARE,
    AmplitudeServo,
    HoldingLoop,
    excursion_per_newton,
    fade,
    multisine_for,
)
from haptic_bus.identify.probe import REST_SECONDS, ProbeResult, ProbeSettings, probe
from haptic_bus.identify.record import Phases
from haptic_bus.validation import real_in_range

SETTLE_SECONDS = 0.5
PROBE_SHARE = 0.1  # of the travel: how far the probe moves the handle
MIN_PROBE_COUNTS = 20  # position increments the probe must see at least
AMPLITUDE_SHARE = 0.7  # of the force limit: the multisine's ceiling (the rest holds the handle)


@dataclass(frozen=True)
class Plan:
    """What a run may do: ``period`` s, ``force_limit`` N, ``travel`` m (the excursion allowed either
    side of the start), ``duration`` s of excitation, ``mass`` kg (the profile's, for the holding loop
    and the probe's bound), ``position_resolution`` m per 0x6064 increment."""

    period: float
    force_limit: float
    travel: float
    duration: float
    mass: float
    position_resolution: float

    def __post_init__(self) -> None:
        real_in_range("duration", self.duration, *DURATION_RANGE, unit="s", context="identify")
        real_in_range("travel", self.travel, *TRAVEL_RANGE, unit="m", context="identify")
        if self.probe_target > 0.5 * self.travel:
            allowed = (f"at least {2 * self.probe_target:g} m: the probe moves {MIN_PROBE_COUNTS} increments of "
                       f"{self.position_resolution:g} m, at most half the travel")
            raise ParameterError("travel", self.travel, allowed, "identify")

    @property
    def probe_target(self) -> float:
        """How far the probe moves the handle, m."""
        return max(PROBE_SHARE * self.travel, MIN_PROBE_COUNTS * self.position_resolution)

    @property
    def cycles(self) -> int:
        """The most cycles a run can take (probe at its longest, excitation, settling)."""
        settings = self.probe_settings()
        per_push = 2 * settings.push_samples(settings.levels()[0]) + math.ceil(REST_SECONDS / self.period)
        return 2 * len(settings.levels()) * per_push + math.ceil((self.duration + SETTLE_SECONDS) / self.period) + 1

    def probe_settings(self) -> ProbeSettings:
        """The probe's numbers for this plan."""
        return ProbeSettings(self.period, self.force_limit, self.probe_target, self.mass)


class Session:
    """The run's controller: :meth:`step` per cycle until :attr:`done`; then :attr:`probe`,
    :attr:`phases` and :attr:`left_envelope` say what happened."""

    def __init__(self, plan: Plan) -> None:
        self.plan = plan
        self.done = False
        self.probe: ProbeResult | None = None
        self.left_envelope = False
        self.cycles = 0
        self._probe_end = 0
        self._excitation_end = 0
        self._script = self._run()
        next(self._script)

    @property
    def refused(self) -> bool:
        """The probe found the handle not free to move (nothing was excited)."""
        return self.probe is not None and not self.probe.free

    @property
    def phases(self) -> Phases:
        """Where the probe and the excitation ended (cycle indices)."""
        return Phases(self._probe_end, self._excitation_end)

    def step(self, position: float) -> float:
        """The force (N; the drive holds it within the force limit) for the cycle whose sampled position
        is ``position`` m; 0 once :attr:`done` (then nothing is to be written any more)."""
        try:
            force = self._script.send(position)
        except StopIteration:
            self.done = True
            return 0.0
        self.cycles += 1
        return force

    def _run(self) -> Generator[float, float, None]:
        plan = self.plan
        x = yield 0.0  # primed: the first cycle's position
        origin = x
        self.probe, x = yield from probe(x, plan.probe_settings())
        self._probe_end = self.cycles
        self._excitation_end = self.cycles
        if not self.probe.free:
            return
        hold = HoldingLoop(plan.mass, plan.period, origin)
        wave = multisine_for(plan.period)
        start = TARGET_SHARE * plan.travel / excursion_per_newton(wave, plan.period, self.probe.apparent_mass, hold)
        servo = AmplitudeServo(start, AMPLITUDE_SHARE * plan.force_limit, plan.travel, wave.size,
                               max(1, round(GUARD_SECONDS / plan.period)))
        cycles = round(plan.duration / plan.period)
        for k in range(cycles):
            faded = fade(k, cycles, plan.period)
            amplitude = servo.update(abs(x - origin), steady=faded == 1.0) * faded
            if servo.left_envelope:
                self.left_envelope = True
                break
            x = yield amplitude * wave[k % wave.size] + hold.force(x)
        self._excitation_end = self.cycles
        for _ in range(round(SETTLE_SECONDS / plan.period)):
            x = yield hold.force(x)
