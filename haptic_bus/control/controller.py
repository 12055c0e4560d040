"""The haptic wall controller: one cycle per period ``T`` over any :class:`drives.base.Drive`.

Each cycle: ``read_inputs`` (on CANopen: SYNC out, the drive's TPDO back) -> the port's energy
over the period that sample closed (:mod:`~haptic_bus.control.port_energy`: the measured
position, the force the drive applied, the period's length) -> integrate the position exactly
as the seed's backward difference does, ``x_k = x_{k-1} + T v_k``, but in the drive's integer
velocity units (an exact integer sum, so ten million cycles add no rounding) -> the scene's
force, times the start ramp's scale -> torque target in per mille -> saturated by the drive's
clamp (:class:`~drives.base.TorqueClamp`, the one place a target is saturated: at the profile's
force limit, or 0x6072 where that is lower; counted) -> the passivity layer lowers it to what the
energy budget allows (:mod:`~haptic_bus.control.passivity_layer`) -> sent.  The cycles run in
the drive's cyclic phase (:meth:`drives.base.Drive.cyclic`), entered once per :meth:`run`.  Beside it: the supervisor
(lateness and the observer against the gate's assumptions,
:mod:`~haptic_bus.control.supervisor`), a bounded record and the run's events.  Wall changes
pass the gate first, in the caller's thread, and take effect whole at the next cycle boundary
(:mod:`~haptic_bus.control.scenes`); a refused change leaves the running scene untouched.

A run ends with torque zero and the drive disabled whatever ends it: the cycles done, the stop
flag, a drive error, an assumption broken, Ctrl-C; the summary says which (``exit_reason``;
the loop is :class:`~haptic_bus.control.cycle_loop.CycleLoop`'s).
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from collections.abc import Callable

from drives.base import Drive, DriveCycle
from drives.cia402 import POSITION_ACTUAL
from haptic_bus.control.clock import CycleClock, VirtualClock
from haptic_bus.control.cycle_loop import CycleLoop, RunSummary
from haptic_bus.control.gate import GateDecision, PassivityGate
from haptic_bus.control.passivity_layer import LayerPolicy
from haptic_bus.control.port_account import PortAccount
from haptic_bus.control.record import EventLog, RunRecord
from haptic_bus.control.scene import CompiledScene
from haptic_bus.control.scenes import SceneEntry, SceneSwitch
from haptic_bus.control.supervisor import Action, Alarm, Supervisor, SupervisorPolicy
from haptic_bus.errors import ParameterError

logger = logging.getLogger(__name__)

Derate = Callable[[CompiledScene, float], "tuple[PassivityGate, CompiledScene, GateDecision] | None"]
"""Given the running scene and the observed loop delay (samples): a gate for that loop, the scene
scaled down so that it passes it, and the decision; None if no scale passes."""


def encoder_origin(drive: Drive) -> float:
    """The handle's absolute position (m) from 0x6064, read once, acyclically, before cycling."""
    return drive.read_object(POSITION_ACTUAL) * drive.scaling.position_per_count


class PositionIntegrator:
    """``x_k = x_0 + T * velocity_per_count * sum(v_counts)``: an exact integer sum, one rounding."""

    __slots__ = ("counts", "origin", "step")

    def __init__(self, period: float, velocity_per_count: float, origin: float = 0.0) -> None:
        self.step = period * velocity_per_count  # m per (count * cycle)
        self.origin = origin
        self.counts = 0

    def add(self, velocity_counts: int) -> float:
        """Accumulate one velocity sample (0x606C units); return the position in m."""
        self.counts += velocity_counts
        return self.origin + self.step * self.counts


class WallController(CycleLoop[DriveCycle]):
    """Renders a gated scene on ``drive`` every ``period`` s.

    ``force_limit`` (N) saturates the wall force (the drive's clamp holds the torque target at it);
    ``clock`` is a :class:`VirtualClock` (default),
    :class:`RealClock` or :class:`ScheduledClock`; ``record_capacity`` bounds the record, kept in
    shared memory with ``shared_record`` (a writer process streams it);
    ``origin`` (m) is the handle's position at the first cycle; ``supervisor`` the policy (None: no supervision);
    ``ramp_time`` (s) scales the force from 0 to 1 over the first seconds (0: none; the caller
    proves every scaled wall passive); ``derate`` is what a "derate" alarm calls; ``passivity``
    the layer's policy and ``hold`` (s) the longest the drive may hold a target before its
    watchdog faults it (the ``bound`` layer's budget per target; default one period).  The port
    observer needs the drive's cyclic inputs to carry the position (0x6064).
    """

    def __init__(
        self,
        drive: Drive,
        gate: PassivityGate,
        scene: CompiledScene,
        *,
        force_limit: float,
        clock: CycleClock | None = None,
        record_capacity: int = 200_000,
        shared_record: bool = False,
        origin: float = 0.0,
        supervisor: SupervisorPolicy | None = None,
        ramp_time: float = 0.0,
        derate: Derate | None = None,
        passivity: LayerPolicy | None = None,
        hold: float | None = None,
    ) -> None:
        if not (isinstance(ramp_time, (int, float)) and 0.0 <= ramp_time < math.inf):
            raise ParameterError("ramp_time", ramp_time, "a finite time >= 0 s", "controller")
        self.drive = drive
        self.period = gate.device.T
        self.force_limit = force_limit
        self.clock = clock if clock is not None else VirtualClock(self.period)
        self.events = EventLog()
        policy = passivity if passivity is not None else LayerPolicy()
        self.passivity = policy
        self.scenes = SceneSwitch(gate, scene, self.events, self.now, beyond_gate=policy.beyond_gate)
        self.integrator = PositionIntegrator(self.period, drive.scaling.velocity_per_count, origin)
        device = gate.device
        self.hold = hold if policy.layer == "bound" and hold is not None else self.period
        scaling = drive.scaling
        self.port = PortAccount(drive.name, friction=device.b, count=scaling.position_per_count,
                                newton_per_permille=scaling.newton_per_permille, delay=device.delay, clock=self.clock,
                                policy=policy, hold=self.hold, force_limit=min(force_limit, scaling.max_force),
                                softest_spring=min((k for k, _ in scene.contacts() if k > 0), default=0.0),
                                initial_energy=scene.stored_energy(origin),
                                tolerance=supervisor.observer_limit if supervisor is not None else 0.0)
        self.observer, self.layer = self.port.observer, self.port.layer
        self.supervisor = Supervisor(supervisor, self.period, device.delay) if supervisor is not None else None
        self.record = RunRecord(record_capacity, shared=shared_record)
        self.ramp_cycles = round(ramp_time / self.period)
        self._derate = derate
        self.cycles = 0
        self.saturated_cycles = 0
        self.peak_force = 0.0
        self.stopped_on_error = False
        self.torque_limit = scaling.torque_limit(force_limit)  # per mille: the drive's clamp holds targets within it
        self._cycle: DriveCycle | None = None  # the drive's cyclic phase while run() runs

    # ------------------------------------------------------------------ gated changes

    def now(self) -> float:
        """The run's clock: virtual time of the current cycle, s."""
        return self.cycles * self.period

    @property
    def gate(self) -> PassivityGate:
        """The gate every change passes (a derate's, after a derate)."""
        return self.scenes.gate

    @property
    def decision(self) -> GateDecision:
        """The gate's decision on the scene running now."""
        return self.scenes.running.decision

    @property
    def scene(self) -> CompiledScene:
        """The scene the loop renders now."""
        return self.scenes.running.scene

    @property
    def latest_scene(self) -> CompiledScene:
        """The scene of the last accepted upload (running, or staged for the next cycle)."""
        return self.scenes.latest.scene

    @property
    def applied_scenes(self) -> int:
        """Scenes adopted after the first."""
        return self.scenes.applied

    def upload_scene(self, scene: CompiledScene) -> GateDecision:
        """Gate ``scene`` and stage it for the next cycle boundary; raise GateRefusal if refused."""
        return self.scenes.upload(scene)

    def set_wall(self, name: str, stiffness: float, damping: float) -> GateDecision:
        """Change one object's ``K`` (N/m) and ``B`` (N s/m) together, through the gate."""
        return self.scenes.set_walls({name: (stiffness, damping)})

    def set_walls(self, changes: dict[str, tuple[float, float]]) -> GateDecision:
        """Change several objects' ``(K, B)`` as one upload: all pass the gate, or none applies."""
        return self.scenes.set_walls(changes)

    # ------------------------------------------------------------------ the cycle

    def step(self, lateness: float = 0.0) -> None:
        """One cycle: inputs, position, force, saturation, torque out, observer, supervisor, record.

        ``lateness`` (s) is how late the cycle started (the clock's); an alarm the supervisor
        raises acts after the cycle is recorded.
        """
        if self._cycle is None:
            with self._cyclic():
                self.step(lateness)
            return
        cycle = self._cycle
        entry: SceneEntry = self.scenes.adopt()  # one read: the whole accepted scene, never half of one
        inputs = cycle.read()
        started = time.perf_counter()
        wall_clock = time.time()
        scaling = self.drive.scaling
        energy = self.port.account(inputs, scaling.position_per_count)
        v = inputs.velocity * scaling.velocity_per_count
        x = self.integrator.add(inputs.velocity)
        force = entry.scene.force(x, v)
        scale = 1.0 if self.cycles >= self.ramp_cycles else (self.cycles + 1) / self.ramp_cycles
        force *= scale
        target = scaling.torque_permille(-force)  # the motor pushes against the wall
        torque = cycle.saturate(target)
        if torque != target:
            self.saturated_cycles += 1
            force = -torque * scaling.newton_per_permille  # the force asked of the drive
        torque = self.port.limit(torque)
        cycle.write(torque)
        compute = time.perf_counter() - started
        supervisor = self.supervisor
        late, alarm = supervisor.cycle(lateness, energy, inputs.age) if supervisor is not None else (False, None)
        if abs(force) > self.peak_force:
            self.peak_force = abs(force)
        self.record.append(self.cycles * self.period, wall_clock, started, lateness, inputs.statusword, inputs.velocity,
                           inputs.age, x, v, force, torque, energy, entry.scene_id, scale, late, compute,
                           self.layer.removed)
        self.cycles += 1
        if alarm is not None:
            self._act(alarm)

    def _act(self, alarm: Alarm) -> None:
        self.events.add(self.now(), "alarm", alarm.message, alarm=alarm.kind, action=alarm.action.value)
        if alarm.action is Action.WARN:
            logger.warning("supervisor: %s", alarm.message)
            return
        assumed = self.supervisor.assumed_delay if self.supervisor is not None else 0.0
        if alarm.action is Action.DERATE and alarm.observed_delay is not None and self._derate is not None:
            derated = self._derate(self.scene, alarm.observed_delay)
            if derated is not None:
                gate, scene, decision = derated
                origin = f"derate to a loop delay of {alarm.observed_delay:.3g} samples"
                entry = self.scenes.replace(gate, scene, decision, origin)
                self.events.add(self.now(), "derate", f"scene {entry.scene_id}: {entry.origin}",
                                scene_id=entry.scene_id, worst_margin=decision.worst_margin)
                logger.warning("supervisor: %s; derated (scene %d)", alarm.message, entry.scene_id)
                return
        raise alarm.broken(assumed)

    def _phase(self) -> contextlib.AbstractContextManager[DriveCycle]:
        """The drive's cyclic phase, its clamp at this controller's torque limit."""
        return self.drive.cyclic(self.torque_limit)

    def _disable(self) -> None:
        self.drive.disable()

    def summary(self, exit_reason: str = "completed", error: str | None = None) -> RunSummary:
        """The summary of everything run so far."""
        observer = self.observer
        return self._summary(exit_reason, error, energy=observer.energy, least_energy=observer.least,
                             rounding_bound=observer.rounding, observer_active_cycles=observer.active_cycles,
                             layer=self.layer.mode, layer_interventions=self.layer.interventions,
                             compute=self.record.column("compute_s"),
                             warnings=self.scenes.history[0].decision.warnings)
