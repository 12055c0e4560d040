"""``haptic-bus demo``: the default profile's wall, simulated drive and controller, one process.

The simulated CiA-402 drive and the controller talk CANopen on the lock-step bus
(:mod:`drives.lockstep_bus`: one thread, deterministic) in virtual time; an operator pushes
into the wall.  The demo prints a short summary and records as a run does
(:mod:`~haptic_bus.app.run_recorder`: ``record.csv`` streamed, ``run.json``, the same pictures
:mod:`~haptic_bus.app.run_plots` draws for a run), without a bus log (its bus is in-process).
"""

from __future__ import annotations

import bisect
import functools
import pathlib
from contextlib import ExitStack
from dataclasses import dataclass
from typing import Any

import numpy as np

from haptic_bus.app.profiles import Profile, default_profile
from haptic_bus.app.rig import simulated_canopen
from haptic_bus.app.run_folder import RECORD_CSV, RunJournal, gate_loop, prepare_run_folder, run_document, scene_dicts
from haptic_bus.app.run_recorder import RunRecorder
from haptic_bus.control.controller import RunSummary, WallController, encoder_origin
from haptic_bus.control.gate import GateDecision
from haptic_bus.control.record import RunRecord


@dataclass
class DemoResult:
    """The demo's numbers (SI) and the files it wrote."""

    profile: Profile
    decision: GateDecision
    summary: RunSummary
    penetration: float | None
    expected_penetration: float | None
    operator_energy: float
    port_energy: float
    files: list[pathlib.Path]


def run_demo(out_dir: str | pathlib.Path, profile: Profile | None = None, seconds: float = 2.0,
             plots: bool = True) -> DemoResult:
    """Run ``profile`` (default: the shipped default) for ``seconds`` of virtual time; write
    ``record.csv``, ``run.json`` and (if ``plots``) the pictures to ``out_dir``, whatever ends the
    run (Ctrl-C too)."""
    profile = profile or default_profile()
    out = prepare_run_folder(out_dir, profile.name)
    cycles = max(1, round(seconds / profile.loop.period))
    link = {"kind": "canopen", "bus": {"interface": "lockstep"}, "simulated": True}
    extra: dict[str, Any] = {"loop": {"period": profile.loop.period, "timing": profile.loop.timing,
                                      "delay_assumed": profile.loop.delay}}
    journal = RunJournal(out, profile, link, extra, run_document)
    journal.write()
    recorder = RunRecorder(out, journal)
    with ExitStack() as stack:
        writer = recorder.start(stack, bus_log=False)  # before the drive is enabled: Ctrl-C from then on is recorded
        sim, drive = stack.enter_context(simulated_canopen(profile))
        origin = encoder_origin(drive)
        scene = profile.compiled_scene()
        gate = profile.gate()
        controller = WallController(drive, gate, scene, force_limit=profile.force_limit, origin=origin,
                                    supervisor=profile.supervisor, passivity=profile.passivity, shared_records=True)
        extra["gate_loop"] = gate_loop(gate.device)
        journal.controller = controller
        recorder.stream(writer, [(RECORD_CSV, "", controller.record)], controller.events,
                        functools.partial(scene_dicts, controller), controller.period)
        summary = controller.run(cycles)
        operator_energy = sim.drive.operator_energy
        # the port's energy as the simulated drive's exact ledger has it: b int v^2 dt minus the motor's work
        port_energy = scene.stored_energy(origin) + sim.drive.viscous_energy + sim.drive.wall_energy
    record = controller.record
    model = profile.operator_model
    push = model.get("level") if model.get("model") == "constant" else None
    surfaces = [obj.position for obj in profile.scene if hasattr(obj, "position")]
    penetration = expected = None
    contact = _contact_stiffness(controller, record) if record.total else None
    if isinstance(push, (int, float)) and contact is not None and surfaces:
        final_x = float(np.mean(record.column("position_m")[-max(1, cycles // 20):]))
        surface = min(surfaces, key=lambda s: abs(s - final_x))
        penetration, expected = abs(final_x - surface), abs(push) / contact
    extra.update(exit_reason=summary.exit_reason, error=summary.error, operator_energy_exact=operator_energy,
                 port_energy_exact=port_energy)
    files = recorder.finish(summary, pictures=plots)
    return DemoResult(profile, controller.decision, summary, penetration, expected, operator_energy, port_energy, files)


def _contact_stiffness(controller: WallController, record: RunRecord) -> float | None:
    """The summed K acting where the handle ended (N/m), or None if nothing acts there."""
    x = float(record.column("position_m")[-1])
    scene = controller.scene
    k = scene.stiffness[bisect.bisect_right(scene.breaks, x)]
    return k if k > 0 else None


def format_demo(result: DemoResult) -> str:
    """The demo's short summary, one fact a line."""
    s = result.summary
    profile = result.profile
    walls = ", ".join(f"{'+'.join(w.objects)} margin {w.verdict.margin:.3g} N s/m" for w in result.decision.walls)
    lines = [
        f"profile: {profile.name} ({profile.loop.timing} timing, delay {profile.loop.delay} sample(s), "
        f"T = {profile.loop.period * 1e3:g} ms)",
        f"gate: passed ({walls})" + (f"; warnings: {'; '.join(s.warnings)}" if s.warnings else ""),
        f"cycles: {s.cycles} in virtual time ({s.clock}); force saturated in {s.saturated_cycles}",
        f"peak force: {s.peak_force:.4g} N",
    ]
    if result.penetration is not None and result.expected_penetration is not None:
        error = (result.penetration - result.expected_penetration) / result.expected_penetration
        lines.append(f"steady penetration: {result.penetration * 1e3:.4f} mm vs F/K = "
                     f"{result.expected_penetration * 1e3:.4f} mm ({error:+.2%})")
    lines.append(f"energy: operator put in {result.operator_energy * 1e3:.4g} mJ (exact, simulated drive); port: "
                 f"observer {s.energy * 1e3:.4g} mJ from positions (least {s.least_energy * 1e3:.4g} mJ, counts "
                 f"rounding within {s.rounding_bound * 1e3:.2g} mJ) vs {result.port_energy * 1e3:.4g} mJ exact "
                 f"({(s.energy - result.port_energy) / result.port_energy:+.2%})")
    lines.append(f"passivity layer: {s.layer}, lowered {s.layer_interventions} of {s.cycles} targets")
    p = s.compute_percentiles
    if p:
        lines.append(f"cycle compute, TPDO in to RPDO sent (position, scene, conversion, encode, send): "
                     f"p50 {p['p50'] * 1e6:.1f} us, p99 {p['p99'] * 1e6:.1f} us, max {p['max'] * 1e6:.1f} us")
    if s.error:
        lines.append(f"run ended early ({s.exit_reason}): {s.error}")
    lines.append("wrote: " + ", ".join(str(f) for f in result.files))
    return "\n".join(lines)
