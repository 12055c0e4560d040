"""``haptic-bus demo --profile gantry-3d``: a multi-axis profile's scene, simulated device and controller, one process.

The simulated device (one CANopen slave per axis and the profile's hand in space,
:class:`sim_drive.canopen.multi_axis.MultiAxisSim`) and the multi-axis master
(:class:`drives.canopen.axes.CanopenAxes`) talk CANopen on the lock-step bus in virtual time,
as the one-axis demo does.  The hand pushes towards its targets; just before the end of each
target's dwell (:data:`STEADY_LEAD`) and at the end the demo reads the steady state
(:class:`SteadyState`): the force the controller asks along the contact's normal against ``K``
times the penetration it measures, the force the drives apply (their torques, whole per mille)
against the hand's push, and ``K`` times the true penetration (the simulated drives' exact
positions).  It writes every axis' record, ``run.json`` and ``trajectory.png``.
"""

from __future__ import annotations

import functools
import math
import pathlib
from contextlib import ExitStack
from dataclasses import dataclass
from typing import Any

import numpy as np

from haptic_bus.app.axes_profile import AxesProfile
from haptic_bus.app.axes_records import axes_run_document, record_files, space_scene_dicts
from haptic_bus.app.rig import MultiAxisSim, simulated_axes
from haptic_bus.app.run_folder import RunJournal, prepare_run_folder
from haptic_bus.app.run_recorder import RunRecorder
from haptic_bus.control.controller import WallController, encoder_origins
from haptic_bus.control.cycle_loop import RunSummary
from haptic_bus.control.space_gate import SpaceDecision
from haptic_bus.control.space_scene import SpaceScene

STEADY_LEAD = 0.05  # s: a steady state is read this long before the hand turns to its next target
STILL_TOUR = 8.0  # s: the demo of a hand that stays on one target (or pushes nothing)


@dataclass(frozen=True)
class SteadyState:
    """One steady state (SI): at ``time_s``, in contact with ``obj`` of stiffness ``stiffness``.

    ``penetration``: the depth at the controller's measured position (0x606C summed, m);
    ``normal_force``: the force the controller asked along the outward normal (N); ``applied``:
    the drives' applied force along it (their torques x the per-mille unit, N) and ``torques``
    (per mille); ``push``: the hand's force into the object along it (N); ``true_penetration``:
    the depth at the simulated drives' exact positions (m); ``quantum``: the largest force
    rounding the per-mille torques allow along the normal (N, ``sqrt(sum (n_i u_i / 2)^2)``,
    ``u_i`` an axis' newton per per mille)."""

    time_s: float
    obj: str
    stiffness: float
    penetration: float
    normal_force: float
    applied: float
    torques: tuple[int, ...]
    push: float
    true_penetration: float
    quantum: float

    @property
    def relative_error(self) -> float:
        """``|normal_force - K penetration| / (K penetration)``: the controller's own chain."""
        expected = self.stiffness * self.penetration
        return abs(self.normal_force - expected) / expected


def contact(scene: SpaceScene, x: np.ndarray) -> tuple[str, float, float, np.ndarray] | None:
    """The one object penetrated at ``x`` (m): its name, stiffness (N/m), depth (m) and outward
    normal; None for none (or for several at once, which a single steady state does not name)."""
    hits = [(obj, obj.penetration(x.tolist())) for obj in scene.objects]
    found = [(obj, hit) for obj, hit in hits if hit is not None]
    if len(found) != 1:
        return None
    obj, (depth, normal) = found[0]
    return obj.name, obj.stiffness, depth, np.array(normal)


def steady_state(controller: WallController[SpaceScene, SpaceDecision], sim: MultiAxisSim) -> SteadyState | None:
    """The steady state of the latest cycle (:class:`SteadyState`), None out of contact."""
    rows = [record.latest() for record in controller.records]
    if any(row is None for row in rows):
        return None
    q = np.array([row["position_m"] for row in rows if row is not None])
    x = controller.kinematics.position(q)
    touching = contact(controller.scene, x)
    if touching is None:
        return None
    name, stiffness, depth, normal = touching
    wall = np.array([row["force_n"] for row in rows if row is not None])
    units = np.array([s.newton_per_permille for s in controller.axes.scalings])
    torques = tuple(int(node.drive.torque_actual) for node in sim.nodes)
    applied = float(np.dot(np.array(torques) * units, normal))  # the motor force on the handle, outward
    push = -float(np.dot(sim.hand.vector(sim.nodes[0].drive.time, sim.positions), normal))
    true = contact(controller.scene, controller.kinematics.position(np.array(sim.positions)))
    return SteadyState(controller.now(), name, stiffness, depth, -float(np.dot(wall, normal)), applied, torques, push,
                       true[2] if true is not None else 0.0, float(np.linalg.norm(normal * units / 2.0)))


@dataclass
class AxesDemoResult:
    """The demo's numbers (SI), its steady states, and the files it wrote."""

    profile: AxesProfile
    controller: WallController[SpaceScene, SpaceDecision]
    summary: RunSummary
    steady: list[SteadyState]
    operator_energy: float
    port_energy: float
    files: list[pathlib.Path]


def tour_seconds(profile: AxesProfile) -> float:
    """How long (s) the profile's hand takes to visit every target (``dwell`` each), once it has taken
    the handle; :data:`STILL_TOUR` where it has a single target or none."""
    dwell = profile.operator_model.get("dwell", math.inf)
    targets = len(profile.operator_model.get("toward", ()))
    return dwell * targets if math.isfinite(dwell) and targets > 1 else STILL_TOUR


def run_axes_demo(out_dir: str | pathlib.Path, profile: AxesProfile, seconds: float | None = None,
                  plots: bool = True) -> AxesDemoResult:
    """Run ``profile`` for ``seconds`` of virtual time (None: the hand's whole tour, :func:`tour_seconds`);
    the steady state read at the end of each target's dwell (and at the end); every axis' record,
    ``run.json`` and (if ``plots``) the plot written."""
    out = prepare_run_folder(out_dir, profile.name)
    period = profile.period
    seconds = tour_seconds(profile) if seconds is None else seconds
    cycles = max(1, round(seconds / period))
    dwell = profile.operator_model.get("dwell", math.inf)
    lead = round(STEADY_LEAD / period)
    ends = {round(j * dwell / period) - lead for j in range(1, len(profile.operator_model.get("toward", ())) + 1)
            if j * dwell < seconds} if math.isfinite(dwell) else set()
    ends.add(cycles - 1)
    steady: list[SteadyState] = []
    link = {"kind": "canopen", "bus": {"interface": "lockstep"}, "simulated": True,
            "node_ids": [a.node_id for a in profile.axes]}
    extra: dict[str, Any] = {"loop": {"period": period}}
    journal = RunJournal(out, profile, link, extra, axes_run_document)
    journal.write()
    recorder = RunRecorder(out, journal)
    with ExitStack() as stack:
        writer = recorder.start(stack, bus_log=False)  # before the drives are enabled
        sim, axes = stack.enter_context(simulated_axes(profile))
        controller = WallController(axes, profile.gate(), profile.space_scene(), names=[a.name for a in profile.axes],
                                    force_limit=[a.force_limit for a in profile.axes], origin=encoder_origins(axes),
                                    supervisor=profile.supervisor, passivity=profile.passivity, shared_records=True)
        journal.controller = controller
        recorder.stream(writer, record_files(controller), controller.events,
                        functools.partial(space_scene_dicts, controller), period)
        axes.enable()

        def read_steady(running: Any) -> None:
            if running.cycles - 1 in ends and (state := steady_state(running, sim)) is not None:
                steady.append(state)

        summary = controller.run(cycles, on_cycle=read_steady)
        operator_energy = sim.hand.energy_balance()
        port_energy = math.fsum(node.drive.viscous_energy + node.drive.wall_energy for node in sim.nodes)
        if summary.exit_reason == "completed":
            axes.disable()
    extra.update(exit_reason=summary.exit_reason, error=summary.error, operator_energy_exact=operator_energy,
                 port_energy_exact=port_energy, steady_states=[dict(vars(s)) for s in steady])
    files = recorder.finish(summary, pictures=plots)
    return AxesDemoResult(profile, controller, summary, steady, operator_energy, port_energy, files)


def format_axes_demo(result: AxesDemoResult) -> str:
    """The demo's short summary, one fact a line."""
    s, profile = result.summary, result.profile
    decision = result.controller.decision
    lines = [
        f"profile: {profile.name} ({len(profile.axes)} axes, nodes {', '.join(str(a.node_id) for a in profile.axes)}, "
        f"one SYNC every {profile.period * 1e3:g} ms)",
        f"gate (coupled): passed, least margin {decision.worst_margin:.3g} N s/m over "
        + ", ".join("+".join(w.objects) for w in decision.walls),
        f"cycles: {s.cycles} in virtual time; force saturated in {s.saturated_cycles}; peak |F| {s.peak_force:.4g} N",
    ]
    for state in result.steady:
        lines.append(
            f"steady at t = {state.time_s:.3f} s on {state.obj}: K d = {state.stiffness * state.penetration:.9g} N "
            f"(d = {state.penetration * 1e3:.6f} mm measured), asked along the normal {state.normal_force:.9g} N "
            f"(relative difference {state.relative_error:.1e}); the drives apply {state.applied:.9g} N "
            f"({'/'.join(map(str, state.torques))} per mille), the hand pushes {state.push:.9g} N; "
            f"K x true depth {state.stiffness * state.true_penetration:.6g} N (per-mille rounding "
            f"<= {state.quantum * 1e3:.3g} mN)")
    exact = result.port_energy
    lines.append(f"energy: the hand put in {result.operator_energy * 1e3:.4g} mJ (exact); port E = sum E_i "
                 f"{s.energy * 1e3:.4g} mJ from positions (least {s.least_energy * 1e3:.4g} mJ) vs {exact * 1e3:.4g} mJ "
                 f"exact")
    lines.append(f"passivity layer: {s.layer} per axis, lowered {s.layer_interventions} targets")
    if s.error:
        lines.append(f"run ended early ({s.exit_reason}): {s.error}")
    lines.append("wrote: " + ", ".join(str(f) for f in result.files))
    return "\n".join(lines)
