"""The haptic wall controller: one cycle per period ``T`` over N drives on one SYNC, N = 1 the scalar case.

What it renders and what judges it are protocols (:mod:`~haptic_bus.control.protocols`): one axis
renders a 1-D :class:`~haptic_bus.control.scene.CompiledScene` judged by the
:class:`~haptic_bus.control.gate.PassivityGate`; several axes a scene in space
(:class:`~haptic_bus.control.space_scene.SpaceScene`) judged by the coupled
:class:`~haptic_bus.control.space_gate.SpaceGate`.  The drives are one cyclic phase of the
N-shape (:class:`drives.base.AxesDriveCycle`: one SYNC, every axis' inputs before any torque goes
out); one :class:`~drives.base.Drive` is N = 1 (:class:`drives.base.OneAxis`), whose phase
carries the drive's own :class:`~drives.base.DriveCycle` for the scalar path.

Each cycle: ``read`` -> per axis, the port's energy over the period that sample closed
(:class:`~haptic_bus.control.port_account.PortAccount`: the measured position, the force the
drive applied, the period's length) and the joint position integrated as the seed's backward
difference does, ``q_k = q_{k-1} + T v_k``, in the drive's integer velocity units (an exact
integer sum, so ten million cycles add no rounding) -> the handle's position and velocity
``x = f(q)``, ``v = J q_dot`` (:mod:`~haptic_bus.control.kinematics`; one axis: ``x = q``) ->
the scene's wall force ``u(x, v)``, times the start ramp's scale (along each contact normal:
the whole force is scaled) -> the joint efforts ``J^T u`` -> per axis the torque target in per
mille of its rated torque, saturated by its drive's clamp (:class:`~drives.base.TorqueClamp`,
the one place a target is saturated: at the axis' force limit, or 0x6072 where that is lower;
counted) -> lowered by its own passivity layer to what its port's budget allows
(:mod:`~haptic_bus.control.passivity_layer`) -> sent for every axis.  One axis with a 1-D
scene (the 1-D gate's) takes the scalar path: the same steps in floats, no array and no tuple a cycle.

Beside it: the supervisor (lateness of the cycle -- its oldest input: a missing axis makes the
whole cycle late -- and the whole port's energy, :mod:`~haptic_bus.control.supervisor`), one
bounded record per axis and the run's events.  Wall changes pass the gate first, in the
caller's thread, and take effect whole at the next cycle boundary
(:mod:`~haptic_bus.control.scene_switch`); a refused change leaves the running scene untouched.  A
"derate" alarm replaces the scene by the one ``derate`` prepared for the observed delay (the
scene scaled down to what the gate -- 1-D or coupled -- passes there:
:mod:`haptic_bus.app.derate_table`); without one it stops.

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
whatever the handle does along that axis.  Every ``E_i >= 0`` gives ``E = sum E_i >= 0``: the
whole port stays passive.  It is sufficient, not necessary: one budget for the whole port would
let an axis spend what another axis' friction paid and so lower the force less; per axis each
drive's budget needs nothing but its own cycle, and an axis that stalls never borrows.

A run ends with torque zero and the drives disabled whatever ends it: the cycles done, the stop
flag, a drive error, an assumption broken, Ctrl-C; the summary says which (``exit_reason``;
the loop is :class:`~haptic_bus.control.cycle_loop.CycleLoop`'s).
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from collections.abc import Sequence
from typing import Any, Generic, Protocol

import numpy as np

from drives.base import AxesDrive, AxesDriveCycle, Drive, OneAxis
from haptic_bus.control.clock import CycleClock, VirtualClock
from haptic_bus.control.cycle_loop import CycleLoop, RunSummary
from haptic_bus.control.gate import PassivityGate
from haptic_bus.control.joints import PositionIntegrator
from haptic_bus.control.kinematics import Cartesian, Kinematics
from haptic_bus.control.passivity_layer import LayerPolicy, PassivityLayer
from haptic_bus.control.port_account import PortAccount
from haptic_bus.control.protocols import DecisionT, DecisionT_co, Gate, SceneT
from haptic_bus.control.record import EventLog, RunRecord
from haptic_bus.control.scene_switch import SceneSwitch
from haptic_bus.control.supervisor import Action, Alarm, Supervisor, SupervisorPolicy
from haptic_bus.errors import ParameterError
from haptic_bus.validation import some_names

logger = logging.getLogger(__name__)


class Derate(Protocol[SceneT, DecisionT_co]):
    """The supervisor's derate (:class:`haptic_bus.app.derate_table.DerateTable`)."""

    def __call__(self, running: SceneT, observed_delay: float) -> tuple[Gate[SceneT, DecisionT_co], SceneT, DecisionT_co] | None:
        """Given the running scene and the observed loop delay (samples): a gate for that loop, the
        scene scaled down so that it passes it, and the decision; None if none is prepared."""
        ...

    def shortfall(self, observed_delay: float) -> str:
        """Why there is none for ``observed_delay`` samples (beyond the table, not built yet, ...)."""
        ...


def _per_axis(name: str, value: float | Sequence[float], size: int) -> list[float]:
    """``value`` for each of ``size`` axes: a number for every axis, or one per axis; else ParameterError."""
    values = [float(value)] * size if isinstance(value, (int, float)) else [float(v) for v in value]
    if len(values) != size:
        raise ParameterError(name, list(values), f"one value per axis ({size})", "controller")
    return values


class WallController(CycleLoop, Generic[SceneT, DecisionT]):
    """Renders a gated scene on ``drive`` every period (module docstring).

    ``drive``: one :class:`~drives.base.Drive`, or several on one SYNC (:class:`~drives.base.AxesDrive`);
    ``gate``: the gate of their loops (its ``axes`` give each axis' ``b``, ``T`` and loop delay);
    ``scene`` must pass it.  ``force_limit`` (N, a number for every axis or one per axis)
    saturates each axis' force (its drive's clamp holds the torque target at it); ``names``: the
    axes' names (default: the drives'); ``clock`` is a :class:`VirtualClock` (default),
    :class:`RealClock` or :class:`ScheduledClock`; ``record_capacity`` bounds each axis' record, kept in
    shared memory with ``shared_records`` (a writer process streams it);
    ``origin`` (m, a number for one axis or one per axis) is each joint's position as read before
    enabling (:func:`encoder_origins`): the walls' energy there is what the ports start with (the
    joints themselves start at each axis' first 0x6064, where the enabling may have moved them);
    ``supervisor`` the policy (None: no supervision);
    ``ramp_time`` (s) scales the force from 0 to 1 over the first seconds (0: none; the caller
    proves every scaled wall passive: the gate's ``proves_ramp``); ``derate`` is what a "derate"
    alarm calls; ``passivity`` the layer's policy and ``hold`` (s) the longest a
    drive may hold a target before its watchdog faults it (the ``bound`` layer's budget per target;
    default one period); ``kinematics``: the device (default Cartesian).  Every axis' cyclic
    inputs must carry the position (0x6064): the port observer reads it.
    """

    def __init__(
        self,
        drive: Drive | AxesDrive,
        gate: Gate[SceneT, DecisionT],
        scene: SceneT,
        *,
        force_limit: float | Sequence[float],
        names: Sequence[str] | None = None,
        clock: CycleClock | None = None,
        record_capacity: int = 200_000,
        shared_records: bool = False,
        origin: float | Sequence[float] = 0.0,
        supervisor: SupervisorPolicy | None = None,
        ramp_time: float = 0.0,
        derate: Derate[SceneT, DecisionT] | None = None,
        passivity: LayerPolicy | None = None,
        hold: float | None = None,
        kinematics: Kinematics | None = None,
    ) -> None:
        if not (isinstance(ramp_time, (int, float)) and 0.0 <= ramp_time < math.inf):
            raise ParameterError("ramp_time", ramp_time, "a finite time >= 0 s", "controller")
        axes = OneAxis(drive) if isinstance(drive, Drive) else drive
        self.scalar = isinstance(gate, PassivityGate)  # the 1-D gate's scenes are 1-D: the scalar path, floats
        if self.scalar and not isinstance(drive, Drive):
            raise ParameterError("drive", axes.name, "one Drive for a 1-D scene (several drives render a scene in space, "
                                 "judged by the coupled gate)", "controller")
        loops = tuple(gate.axes)
        size = len(loops)
        scalings = axes.scalings
        names = tuple(names) if names is not None else tuple(d.name for d in axes.drives)
        if not len(scalings) == len(names) == size:
            raise ParameterError("axes", len(scalings), f"{size} drives and names (the gate's axes)", "controller")
        self.axes = axes
        self.names = names
        self.period = loops[0].T
        self.kinematics = kinematics if kinematics is not None else Cartesian(size)
        self.clock = clock if clock is not None else VirtualClock(self.period)
        self.events = EventLog()
        policy = passivity if passivity is not None else LayerPolicy()
        self.passivity = policy
        self.scenes: SceneSwitch[SceneT, DecisionT] = SceneSwitch(gate, scene, self.events, self.now,
                                                                   beyond_gate=policy.beyond_gate, step=self.entered_step)
        self.hold = hold if policy.layer == "bound" and hold is not None else self.period
        limits = _per_axis("force_limit", force_limit, size)
        origins = _per_axis("origin", origin, size)
        self._origins = origins
        self.torque_limits = [s.torque_limit(limit) for limit, s in zip(limits, scalings)]  # each drive's clamp
        self.integrators = tuple(PositionIntegrator(self.period, s.velocity_per_count) for s in scalings)
        softest = min((obj.stiffness for obj in scene.objects if obj.stiffness > 0), default=0.0)
        tolerance = supervisor.observer_limit if supervisor is not None else 0.0
        self.ports = tuple(
            PortAccount(f"axis {name}" if size > 1 else axes.name, friction=loop.b, count=s.position_per_count,
                        newton_per_permille=s.newton_per_permille, delay=loop.delay, clock=self.clock, policy=policy,
                        hold=self.hold, force_limit=min(limit, s.max_force), softest_spring=softest,
                        initial_energy=stored, tolerance=tolerance)
            for name, loop, s, limit, stored in zip(names, loops, scalings, limits, self._stored_energies(scene, origins)))
        self.supervisor = Supervisor(supervisor, self.period, max(loop.delay for loop in loops),
                                     tuple(d.name for d in axes.drives)) if supervisor is not None else None
        self.records = tuple(RunRecord(record_capacity, shared=shared_records) for _ in range(size))
        self.ramp_cycles = round(ramp_time / self.period)
        self._derate = derate
        self._scalings = scalings
        self.cycles = 0
        self.saturated_cycles = 0
        self.peak_force = 0.0
        # the whole port's E = sum E_i (J), kept by the path for several axes; from the energy stored in the walls the
        # run begins in contact with, as each axis' observer starts (the least so far too: not 0 J it never reached)
        self.energy = self.least_energy = sum(port.observer.energy for port in self.ports)
        self.observer_active_cycles = 0
        self.stopped_on_error = False
        self.error_cycle_s = 0.0
        self._q = [0.0] * size  # the joints' q (m) and q_dot (m/s) of the latest cycle, several axes: floats
        self._q_dot = [0.0] * size
        self._identity = type(self.kinematics) is Cartesian  # x = q, v = q_dot, J^T u = u: no matrix a cycle
        # what each axis' cycle reads of its port, joint and scaling, and writes its row with: one tuple per axis
        self._joints = tuple((port, integrator, s.position_per_count, s.velocity_per_count)
                             for port, integrator, s in zip(self.ports, self.integrators, scalings))
        self._rows = tuple((record.append, port.observer, port.layer) for record, port in zip(self.records, self.ports))
        self._cycle: AxesDriveCycle | None = None  # the drives' cyclic phase while run() runs

    def _stored_energies(self, scene: SceneT, origins: list[float]) -> list[float]:
        """The energy (J) the walls hold at the start, per axis: what each axis' port starts with.

        One axis holds it all.  Several share it as the wall force at rest does: axis ``i`` the
        part ``tau_i^2 / |tau|^2`` of it (``tau = J^T u``), exact for one plane wall (``K d^2 n_i^2 / 2``
        is what it releases along axis ``i``)."""
        if self.scalar:
            return [scene.stored_energy(origins[0])]
        x = self.kinematics.position(origins)
        stored = scene.stored_energy(x)
        efforts = self.kinematics.jacobian(np.array(origins)).T @ np.asarray(scene.force(x, np.zeros_like(x)), dtype=float)
        total = float(efforts @ efforts)
        if stored == 0.0 or total == 0.0:
            return [0.0] * len(origins)
        return [stored * float(e * e) / total for e in efforts]

    # ------------------------------------------------------------------ what the run reads

    @property
    def record(self) -> RunRecord:
        """The first axis' record (the one axis')."""
        return self.records[0]

    @property
    def layer(self) -> PassivityLayer:
        """The first axis' passivity layer (the one axis')."""
        return self.ports[0].layer

    # ------------------------------------------------------------------ gated changes

    def now(self) -> float:
        """The run's clock: virtual time of the current cycle, s."""
        return self.cycles * self.period

    @property
    def gate(self) -> Gate[SceneT, DecisionT]:
        """The gate every change passes (a derate's, after a derate)."""
        return self.scenes.gate

    @property
    def decision(self) -> DecisionT:
        """The gate's decision on the scene running now."""
        return self.scenes.running.decision

    @property
    def scene(self) -> SceneT:
        """The scene the loop renders now."""
        return self.scenes.running.scene

    @property
    def latest_scene(self) -> SceneT:
        """The scene of the last accepted upload (running, or staged for the next cycle)."""
        return self.scenes.latest.scene

    @property
    def applied_scenes(self) -> int:
        """Scenes adopted after the first."""
        return self.scenes.applied

    def handle_position(self) -> Any:
        """Where the handle is after the latest cycle (before the first: where it was before
        enabling): m, one axis; the point in space (m) for several."""
        q = [integrator.position for integrator in self.integrators] if self.cycles else self._origins
        return q[0] if self.scalar else self.kinematics.position(q)

    def entered_step(self, running: SceneT, new: SceneT) -> str | None:
        """Why ``new`` may not replace ``running`` where the handle is now, or None: the handle would
        be inside an object of ``new`` that it is not inside now (a wall moved or added onto it, or
        one whose ``K`` was 0), and feel its force at once -- the start's rule for a handle inside an
        object, for an upload.  A wall it already presses, stiffened or softened, is the operator's
        own change under the hand, judged by the gate as every upload is."""
        x = self.handle_position()
        entered = sorted(set(new.touching(x)) - set(running.touching(x)))
        if not entered:
            return None
        rest = 0.0 if self.scalar else np.zeros(len(x))

        def felt(scene: SceneT) -> float:
            return float(np.linalg.norm(np.atleast_1d(np.asarray(scene.force(x, rest), dtype=float))))

        names = some_names(entered)
        return (f"the handle would be inside {names} at once (its force would step from {felt(running):.3g} N to "
                f"{felt(new):.3g} N, {new.stored_energy(x) * 1e3:.3g} mJ in the new walls' springs); move it out of "
                f"{names}, then upload again")

    def upload_scene(self, scene: SceneT) -> DecisionT:
        """Gate ``scene`` and stage it for the next cycle boundary; raise Refusal if refused."""
        return self.scenes.upload(scene)

    def set_wall(self, name: str, stiffness: float, damping: float) -> DecisionT:
        """Change one object's ``K`` (N/m) and ``B`` (N s/m) together, through the gate."""
        return self.scenes.set_walls({name: (stiffness, damping)})

    def set_walls(self, changes: dict[str, tuple[float, float]]) -> DecisionT:
        """Change several objects' ``(K, B)`` as one upload: all pass the gate, or none applies."""
        return self.scenes.set_walls(changes)

    # ------------------------------------------------------------------ the cycle

    def step(self, lateness: float = 0.0) -> None:
        """One cycle of every axis (module docstring); ``lateness`` (s): how late it started after its
        deadline (the clock's).  An alarm the supervisor raises acts after the cycle is recorded."""
        if self._cycle is None:
            with self._cyclic():
                self.step(lateness)
            return
        if self.scalar:
            self._scalar_step(lateness)
        else:
            self._axes_step(lateness)

    def _scalar_step(self, lateness: float) -> None:
        """One axis, a 1-D scene: the cycle in floats, on the drive's own phase."""
        cycle = self._cycle.one if self._cycle is not None else None
        assert cycle is not None, "the scalar path runs in one drive's phase"
        entry = self.scenes.adopt()  # one read: the whole accepted scene, never half of one
        inputs = cycle.read()
        started = time.perf_counter()
        wall_clock = time.time()
        scaling = self._scalings[0]
        port = self.ports[0]
        energy = port.account(inputs, scaling.position_per_count)
        v = inputs.velocity * scaling.velocity_per_count
        integrator = self.integrators[0]
        x = integrator.add(inputs.velocity) if self.cycles else \
            integrator.start((inputs.position or 0) * scaling.position_per_count, inputs.velocity)
        scale = 1.0 if self.cycles >= self.ramp_cycles else (self.cycles + 1) / self.ramp_cycles
        force = entry.scene.force(x, v) * scale
        target = scaling.torque_permille(-force)  # the motor pushes against the wall
        torque = cycle.saturate(target)
        saturated = torque != target
        if saturated:
            force = -torque * scaling.newton_per_permille  # the force asked of the drive
        torque = port.limit(torque)
        cycle.write(torque)
        compute = time.perf_counter() - started
        supervisor = self.supervisor
        late, alarm = supervisor.cycle(lateness, energy, inputs.age) if supervisor is not None else (False, None)
        self.saturated_cycles += saturated
        if abs(force) > self.peak_force:
            self.peak_force = abs(force)
        self.records[0].append(self.cycles * self.period, wall_clock, started, lateness, inputs.statusword,
                               inputs.velocity, inputs.age, x, v, force, torque, energy, entry.scene_id, scale, late,
                               compute, port.layer.removed)
        self.cycles += 1
        if alarm is not None:
            self._act(alarm)

    def _axes_step(self, lateness: float) -> None:
        """Several axes (or a scene in space): joints, kinematics, the scene's force, joint efforts.  The
        joints are floats; a Cartesian device (``J = I``) passes them to the scene as they are and takes
        its force as the joint efforts -- exactly what ``J q_dot`` and ``J^T u`` give for a finite ``u``
        (each entry one product by 1.0 plus products by 0.0) -- without a matrix or an array a cycle."""
        cycle = self._cycle
        assert cycle is not None
        entry = self.scenes.adopt()
        inputs = cycle.read()
        started = time.perf_counter()
        wall_clock = time.time()
        q, q_dot = self._q, self._q_dot
        energy = 0.0
        age = oldest = 0
        first = not self.cycles
        for i, (found, (port, integrator, position_per_count, velocity_per_count)) in enumerate(zip(inputs, self._joints)):
            energy += port.account(found, position_per_count)
            velocity = found.velocity
            q[i] = integrator.start((found.position or 0) * position_per_count, velocity) if first \
                else integrator.add(velocity)
            q_dot[i] = velocity * velocity_per_count
            if found.age > age:  # the whole cycle is as late as its oldest input
                age, oldest = found.age, i
        scale = 1.0 if self.cycles >= self.ramp_cycles else (self.cycles + 1) / self.ramp_cycles
        scene = entry.scene
        if not self._identity:
            kinematics = self.kinematics
            joints = np.array(q)
            jacobian = kinematics.jacobian(joints)
            wall = (jacobian.T @ scene.force(kinematics.position(joints), jacobian @ np.array(q_dot))).tolist()
        else:
            wall = scene.force_floats(q, q_dot)  # joint efforts of u: u itself, floats from floats
        forces: list[float] = wall if scale == 1.0 else [force * scale for force in wall]
        scalings = self._scalings
        targets = [scaling.torque_permille(-force) for scaling, force in zip(scalings, forces)]  # against the wall
        torques = []
        saturated = False
        for i, (target, clamp, port) in enumerate(zip(targets, cycle.clamps, self.ports)):  # AxesDriveCycle.saturate's clamps
            torque = clamp(target)
            if torque != target:
                saturated = True
                forces[i] = -torque * scalings[i].newton_per_permille  # the force asked of the drive
            torques.append(port.limit(torque))
        cycle.write(torques)
        compute = time.perf_counter() - started
        late, alarm = self.supervisor.cycle(lateness, energy, age, oldest) if self.supervisor is not None else (False, None)
        self._account(energy, forces, saturated)
        t = self.cycles * self.period
        scene_id = entry.scene_id
        for (append, observer, layer), found, qi, vi, force, torque in zip(self._rows, inputs, q, q_dot, forces, torques):
            append(t, wall_clock, started, lateness, found.statusword, found.velocity, found.age, qi, vi,
                   force, torque, observer.energy, scene_id, scale, late, compute, layer.removed)
        self.cycles += 1
        if alarm is not None:
            self._act(alarm)

    def _account(self, energy: float, forces: list[float], saturated: bool) -> None:
        """The whole port's energy (J, the least, the cycles below the tolerance), saturation and peak force (N)."""
        self.energy = energy
        if energy < self.least_energy:
            self.least_energy = energy
        if energy < -(self.supervisor.policy.observer_limit if self.supervisor is not None else 0.0):
            self.observer_active_cycles += 1
        self.saturated_cycles += saturated
        magnitude = math.hypot(*forces)
        if magnitude > self.peak_force:
            self.peak_force = magnitude

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
            raise alarm.broken(assumed, self._derate.shortfall(alarm.observed_delay))
        raise alarm.broken(assumed)

    def _phase(self) -> contextlib.AbstractContextManager[AxesDriveCycle]:
        """The drives' cyclic phase, each clamp at its axis' torque limit."""
        return self.axes.cyclic(self.torque_limits)

    def _disable(self) -> None:
        self.axes.disable()

    def summary(self, exit_reason: str = "completed", error: str | None = None) -> RunSummary:
        """The summary of everything run so far: the whole port's energy is the sum over axes (each
        axis' in :meth:`axis_summaries`)."""
        if self.scalar:
            observer = self.ports[0].observer
            energy, least, active = observer.energy, observer.least, observer.active_cycles
        else:
            energy, least, active = self.energy, self.least_energy, self.observer_active_cycles
        return self._summary(exit_reason, error, energy=energy, least_energy=least,
                             rounding_bound=sum(port.observer.rounding for port in self.ports),
                             observer_active_cycles=active, layer=self.passivity.layer,
                             layer_interventions=sum(port.layer.interventions for port in self.ports),
                             compute=self.records[0].column("compute_s"),
                             warnings=self.scenes.history[0].decision.warnings)

    def axis_summaries(self) -> list[dict[str, Any]]:
        """Per axis: its name, its port energy ``E_i`` (J, the last and the least), its counts rounding
        bound (J), how often its layer lowered a target, and its budget's cap (J)."""
        return [{"axis": name, "energy_j": port.observer.energy, "least_energy_j": port.observer.least,
                 "rounding_bound_j": port.observer.rounding, "layer_interventions": port.layer.interventions,
                 "budget_cap_j": port.observer.cap}
                for name, port in zip(self.names, self.ports)]
