"""The multi-axis controller: a scene in space rendered through several drives on one SYNC.

Each cycle (``T`` for every axis): ``read`` -- one SYNC, every axis' TPDOs (status,
velocity, position) before any torque goes out (:class:`drives.canopen.axes.CanopenAxes`) ->
per axis, the port's energy over the period that sample closed (:class:`PortAccount`) and the
joint position as an exact integer sum of 0x606C counts (``q_k = q_{k-1} + T v_k``, the seed's
backward difference per axis, from ``q_0`` = the first cycle's 0x6064: the handle may have
moved while the drives were enabled) -> the handle's position and velocity ``x = f(q)``, ``v = J q_dot``
(:mod:`~haptic_bus.control.kinematics`) -> the scene's wall force ``u(x, v)``
(:mod:`~haptic_bus.control.space_scene`) -> the joint efforts ``J^T u`` -> per axis: the torque
target in per mille of its own rated torque, saturated by its own drive's clamp
(:class:`~drives.base.TorqueClamp`, the one place a target is saturated: at the axis' force
limit, or its 0x6072 where that is lower; counted in that drive's stats), lowered by its own
passivity layer -> sent for every axis.  The cycles run in the axes' cyclic phase
(:meth:`drives.canopen.axes.CanopenAxes.cyclic`), entered once per :meth:`AxesController.run`.
Beside it: the supervisor (lateness of the cycle -- its oldest input: a missing axis makes the
whole cycle late -- and the whole port's energy), one bounded record per axis and the run's
events.  Scene uploads pass the coupled gate
(:class:`~haptic_bus.control.space_gate.SpaceGate`) in the caller's thread and take effect whole
at the next cycle boundary; a refused one leaves the running scene untouched.

**The port, per axis and whole.**  The energy the operator puts into the device is, for any
timing, at least ``E = sum_i E_i``, each ``E_i`` the port observer of axis ``i`` from its own
0x6064 and its own applied force (DESIGN 3.6).  Why the sum: the operator's work is the change
of the kinetic energy plus the friction losses minus the motors' work.  The motors' work is
the sum over axes of ``F_i dq_i`` (each drive's own force along its own joint coordinate, for
any kinematics: ``tau = J^T F`` is what makes that sum the work on the handle), the viscous
losses are per joint (``b_i``), and the kinetic energy, however the axes' inertias couple, is
never negative -- so each axis' lower bound of its own losses minus its own motor work adds up
to a lower bound for the whole port.  (On a Cartesian device each ``E_i`` is even a lower bound
of the operator's work on axis ``i`` alone, the mass matrix being diagonal; on a coupled
mechanism only the sum is.)

**Why a layer per axis is enough.**  Each axis' layer keeps its own ``E_i``'s budget: the
target it sends satisfies ``F_i^2 tau / (4 b_i) <= E_c,i - (targets in flight)``, so ``E_i >= 0``
whatever the handle does along that axis (:mod:`~haptic_bus.control.passivity_layer`).  Every
``E_i >= 0`` gives ``E = sum E_i >= 0``: the whole port stays passive.  It is sufficient, not
necessary: one budget for the whole port (``sum_i F_i^2 / b_i <= 4 E_c / tau``) would let an
axis spend what another axis' friction paid and so lower the force less; per axis each drive's
budget needs nothing but its own cycle, and an axis that stalls or drops out never borrows.
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from drives.base import AxesDriveCycle, DriveScaling
from haptic_bus.control.clock import CycleClock, VirtualClock
from haptic_bus.control.controller import PositionIntegrator
from haptic_bus.control.cycle_loop import CycleLoop, RunSummary
from haptic_bus.control.kinematics import Cartesian, Kinematics
from haptic_bus.control.passivity_layer import LayerPolicy
from haptic_bus.control.port_account import PortAccount
from haptic_bus.control.record import EventLog, RunRecord
from haptic_bus.control.space_gate import SpaceDecision, SpaceGate, SpaceGateRefusal
from haptic_bus.control.space_scene import SpaceScene
from haptic_bus.control.supervisor import Action, Alarm, Supervisor, SupervisorPolicy
from haptic_bus.errors import ParameterError

logger = logging.getLogger(__name__)


class AxesDrive(Protocol):
    """What the controller needs of several drives on one SYNC (:class:`drives.canopen.axes.CanopenAxes`)."""

    name: str

    @property
    def scalings(self) -> tuple[DriveScaling, ...]:
        """Every axis' drive-unit scaling, in axis order."""
        ...

    def cyclic(self, torque_limits: Sequence[int | None] | None = None
               ) -> contextlib.AbstractContextManager[AxesDriveCycle]:
        """The cyclic phase of every axis (one SYNC per cycle; any axis' fault trips every axis), each
        axis' clamp held within its ``torque_limits`` entry (per mille; None: its drive's own)."""
        ...

    def disable(self) -> None:
        """Zero torque and every drive disabled."""
        ...


class SceneHistory:
    """The scenes a run had in effect, each with an id, the time it was adopted and the gate's decision."""

    def __init__(self, scene: SpaceScene, decision: SpaceDecision) -> None:
        self.entries: list[tuple[int, float, SpaceScene, SpaceDecision]] = [(0, 0.0, scene, decision)]
        self.staged: tuple[SpaceScene, SpaceDecision] | None = None

    @property
    def running(self) -> tuple[int, float, SpaceScene, SpaceDecision]:
        """The scene in effect: ``(id, adopted at s, scene, decision)``."""
        return self.entries[-1]

    def adopt(self, now: float) -> tuple[int, SpaceScene]:
        """At a cycle boundary: the staged scene, if any, takes effect whole; ``(id, scene)`` in effect."""
        staged, self.staged = self.staged, None
        if staged is not None:
            self.entries.append((len(self.entries), now, *staged))
        scene_id, _, scene, _ = self.entries[-1]
        return scene_id, scene


class AxesController(CycleLoop[AxesDriveCycle]):
    """Renders a gated scene in space on the drives ``axes`` every period.

    ``gate``: the coupled gate of these axes (its ``axes`` give each axis' ``b``, ``T`` and loop
    delay); ``scene`` must pass it.  ``names``: the axes' names; ``force_limits`` (N) saturate
    each axis' force (its drive's clamp holds the torque target at it); ``clock``,
    ``record_capacity``, ``shared_records`` (each axis' record), ``supervisor``, ``passivity`` and ``hold`` (s) as
    :class:`~haptic_bus.control.controller.WallController` takes them; ``kinematics``: the device
    (default Cartesian).  Every axis' inputs must carry 0x6064 (the port observer reads it).
    """

    def __init__(
        self,
        axes: AxesDrive,
        gate: SpaceGate,
        scene: SpaceScene,
        *,
        names: Sequence[str],
        force_limits: Sequence[float],
        clock: CycleClock | None = None,
        record_capacity: int = 200_000,
        shared_records: bool = False,
        supervisor: SupervisorPolicy | None = None,
        passivity: LayerPolicy | None = None,
        hold: float | None = None,
        kinematics: Kinematics | None = None,
    ) -> None:
        loops = gate.axes
        size = len(loops)
        scalings = axes.scalings
        if not (len(names) == len(force_limits) == len(scalings) == size):
            raise ParameterError("axes", len(scalings), f"{size} drives, names and force limits (the gate's axes)",
                                 "multi-axis controller")
        if supervisor is not None and Action.DERATE.value in (supervisor.on_late, supervisor.on_observer):
            raise ParameterError("supervisor", "derate", '"warn" or "stop" (no derate search for coupled axes)',
                                 "multi-axis controller")
        self.axes = axes
        self.gate = gate
        self.names = tuple(names)
        self.period = loops[0].T
        self.kinematics = kinematics if kinematics is not None else Cartesian(size)
        self.clock = clock if clock is not None else VirtualClock(self.period)
        self.events = EventLog()
        self.scenes = SceneHistory(scene, gate.admit(scene))
        policy = passivity if passivity is not None else LayerPolicy()
        self.passivity = policy
        self.hold = hold if policy.layer == "bound" and hold is not None else self.period
        limits = [min(limit, s.max_force) for limit, s in zip(force_limits, scalings)]
        self.torque_limits = [s.torque_limit(limit) for limit, s in zip(force_limits, scalings)]  # each drive's clamp
        softest = min((obj.stiffness for obj in scene.objects if obj.stiffness > 0), default=0.0)
        self.ports = tuple(
            PortAccount(f"axis {name}", friction=loop.b, count=s.position_per_count, newton_per_permille=s.newton_per_permille,
                        delay=loop.delay, clock=self.clock, policy=policy, hold=self.hold, force_limit=limit,
                        softest_spring=softest)
            for name, loop, s, limit in zip(self.names, loops, scalings, limits))
        self.integrators = tuple(PositionIntegrator(self.period, s.velocity_per_count) for s in scalings)
        self._scalings = scalings
        self.supervisor = Supervisor(supervisor, self.period, max(loop.delay for loop in loops)) \
            if supervisor is not None else None
        self.records = tuple(RunRecord(record_capacity, shared=shared_records) for _ in range(size))
        self.cycles = 0
        self.saturated_cycles = 0
        self.peak_force = 0.0
        self.energy = 0.0  # the whole port's E = sum E_i, J
        self.least_energy = 0.0
        self.observer_active_cycles = 0
        self.stopped_on_error = False
        self._joints = np.zeros((2, size))  # q (m) and q_dot (m/s) of the latest cycle
        self._cycle: AxesDriveCycle | None = None  # the axes' cyclic phase while run() runs

    # ------------------------------------------------------------------ gated changes

    def now(self) -> float:
        """The run's clock: virtual time of the current cycle, s."""
        return self.cycles * self.period

    @property
    def scene(self) -> SpaceScene:
        """The scene in effect."""
        return self.scenes.running[2]

    def upload_scene(self, scene: SpaceScene) -> SpaceDecision:
        """Judge ``scene`` by the coupled gate (in the caller's thread) and stage it for the next cycle
        boundary; a refusal raises :class:`SpaceGateRefusal` and leaves the running scene as it was."""
        try:
            decision = self.gate.admit(scene)
        except SpaceGateRefusal as refusal:
            self.events.add(self.now(), "refused", str(refusal))
            raise
        self.scenes.staged = (scene, decision)
        self.events.add(self.now(), "upload", f"scene of {len(scene.objects)} object(s) accepted, least margin "
                                              f"{decision.worst_margin} N s/m")
        return decision

    # ------------------------------------------------------------------ the cycle

    def step(self, lateness: float = 0.0) -> None:
        """One cycle of every axis (module docstring); ``lateness`` (s): how late it started."""
        if self._cycle is None:
            with self._cyclic():
                self.step(lateness)
            return
        cycle = self._cycle
        scene_id, scene = self.scenes.adopt(self.now())
        inputs = cycle.read()
        started = time.perf_counter()
        wall_clock = time.time()
        q, q_dot = self._joints
        energy = 0.0
        age = 0
        first = not self.cycles
        for i, (found, port, integrator, scaling) in enumerate(zip(inputs, self.ports, self.integrators, self._scalings)):
            energy += port.account(found, scaling.position_per_count)
            if first:  # the joint starts where its encoder says at the first SYNC the run answers
                integrator.origin = (found.position or 0) * scaling.position_per_count
                q[i] = integrator.origin
            else:
                q[i] = integrator.add(found.velocity)
            q_dot[i] = found.velocity * scaling.velocity_per_count
            age = max(age, found.age)  # the whole cycle is as late as its oldest input
        kinematics = self.kinematics
        jacobian = kinematics.jacobian(q)
        wall = jacobian.T @ scene.force(kinematics.position(q), jacobian @ q_dot)  # joint efforts of the wall force
        forces: list[float] = wall.tolist()
        targets = [scaling.torque_permille(-force) for scaling, force in zip(self._scalings, forces)]  # against the wall
        sent = cycle.saturate(targets)
        saturated = sent != targets
        for i, (target, torque, scaling) in enumerate(zip(targets, sent, self._scalings)):
            if torque != target:
                forces[i] = -torque * scaling.newton_per_permille  # the force asked of the drive
        torques = [port.limit(torque) for port, torque in zip(self.ports, sent)]
        cycle.write(torques)
        compute = time.perf_counter() - started
        late, alarm = self.supervisor.cycle(lateness, energy, age) if self.supervisor is not None else (False, None)
        self._account(energy, forces, saturated)
        t = self.cycles * self.period
        for i, (record, port, found) in enumerate(zip(self.records, self.ports, inputs)):
            record.append(t, wall_clock, started, lateness, found.statusword, found.velocity, found.age, q[i], q_dot[i],
                          forces[i], torques[i], port.observer.energy, scene_id, 1.0, late, compute, port.layer.removed)
        self.cycles += 1
        if alarm is not None:
            self._act(alarm)

    def _account(self, energy: float, forces: list[float], saturated: bool) -> None:
        self.energy = energy
        if energy < self.least_energy:
            self.least_energy = energy
        if energy < -(self.supervisor.policy.observer_limit if self.supervisor is not None else 0.0):
            self.observer_active_cycles += 1
        self.saturated_cycles += saturated
        magnitude = float(np.hypot.reduce(forces)) if forces else 0.0
        if magnitude > self.peak_force:
            self.peak_force = magnitude

    def _act(self, alarm: Alarm) -> None:
        self.events.add(self.now(), "alarm", alarm.message, alarm=alarm.kind, action=alarm.action.value)
        if alarm.action is Action.WARN:
            logger.warning("supervisor: %s", alarm.message)
            return
        raise alarm.broken(self.supervisor.assumed_delay if self.supervisor is not None else 0.0)

    def _phase(self) -> contextlib.AbstractContextManager[AxesDriveCycle]:
        """The axes' cyclic phase, each clamp at its axis' torque limit."""
        return self.axes.cyclic(self.torque_limits)

    def _disable(self) -> None:
        self.axes.disable()

    def summary(self, exit_reason: str = "completed", error: str | None = None) -> RunSummary:
        """The whole device's summary: the port's energy is the sum over axes (each axis' in :meth:`axis_summaries`)."""
        return self._summary(exit_reason, error, energy=self.energy, least_energy=self.least_energy,
                             rounding_bound=sum(port.observer.rounding for port in self.ports),
                             observer_active_cycles=self.observer_active_cycles, layer=self.passivity.layer,
                             layer_interventions=sum(port.layer.interventions for port in self.ports),
                             compute=self.records[0].column("compute_s"))

    def axis_summaries(self) -> list[dict[str, float | int | str]]:
        """Per axis: its name, its port energy ``E_i`` (J, the last and the least), its counts rounding
        bound (J), and how often its layer lowered a target."""
        return [{"axis": name, "energy_j": port.observer.energy, "least_energy_j": port.observer.least,
                 "rounding_bound_j": port.observer.rounding, "layer_interventions": port.layer.interventions,
                 "budget_cap_j": port.observer.cap}
                for name, port in zip(self.names, self.ports)]
