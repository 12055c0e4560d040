"""``haptic-bus demo``: a profile's scene, simulated drive(s) and controller, one process, one axis or several.

The simulated drive(s) and the controller talk CANopen on the lock-step bus
(:mod:`drives.lockstep_bus`: one thread, deterministic) in virtual time; an operator (one axis) or
a hand in space (several) pushes into the walls.  The demo prints a short summary and records as
a run does (:mod:`~haptic_bus.app.run_recorder`: every axis' record streamed, ``run.json``, the
same pictures :mod:`~haptic_bus.app.run_pictures` draws for a run), without a bus log (its bus is
in-process).  What differs by kind -- the simulator, what is read against its truth, the summary's
lines -- is in :mod:`~haptic_bus.app.demo_kinds`; the scene, gate and controller come from the
run's own kinds (:mod:`~haptic_bus.app.run_kinds`).
"""

from __future__ import annotations

import pathlib
from contextlib import ExitStack
from dataclasses import dataclass
from typing import Any

from haptic_bus.app.demo_kinds import Findings, demo_kind
from haptic_bus.app.profiles import AxesProfile, Profile, default_profile
from haptic_bus.app.run_folder import RunJournal, own_run_folder
from haptic_bus.app.run_kinds import run_kind
from haptic_bus.app.run_options import StopRequest
from haptic_bus.app.run_recorder import RunRecorder
from haptic_bus.control.controller import RunSummary, WallController


@dataclass
class DemoResult:
    """The demo's numbers (SI), what it read against the simulated truth (``findings``: the exact
    energies, the steady penetration or states), and the files it wrote."""

    profile: Profile | AxesProfile
    controller: WallController[Any, Any]
    summary: RunSummary
    findings: Findings
    lines: list[str]  # the summary's lines of this kind (:func:`format_demo` adds how it ended and the files)
    files: list[pathlib.Path]


def run_demo(out_dir: str | pathlib.Path, profile: Profile | AxesProfile | None = None, seconds: float | None = None,
             plots: bool = True, stop: StopRequest | None = None) -> DemoResult:
    """Run ``profile`` (default: the shipped default) for ``seconds`` of virtual time (None: 2 s for one
    axis, the hand's whole tour for several); write every axis' record, ``run.json`` and (if
    ``plots``) the pictures to ``out_dir``, whatever ends the run (Ctrl-C too).  ``stop`` (the command
    installs it for SIGINT and SIGTERM) ends the cycles at the next boundary, "stopped" or "interrupted"."""
    profile = profile or default_profile()
    kind, demo = run_kind(profile), demo_kind(profile)
    out, lock = own_run_folder(out_dir, profile.name)  # held until the demo has written everything (or its process ends)
    seconds = demo.seconds() if seconds is None else seconds
    cycles = max(1, round(seconds / kind.period))
    link = {"kind": "canopen", "bus": {"interface": "lockstep"}, "simulated": True, **demo.link()}
    extra: dict[str, Any] = {"loop": kind.loop_extra()}
    journal = RunJournal(out, kind, link, extra)
    journal.begin()
    recorder = RunRecorder(out, journal)
    with ExitStack() as stack:
        writer = recorder.start(stack, bus_log=False)  # before the drive is enabled: Ctrl-C from then on is recorded
        sim, drive = stack.enter_context(demo.simulated())
        journal.safety = getattr(drive, "drives", (drive,))[0].safety  # settings.safety: what its drives were given
        origin = kind.origin(drive)
        gate = profile.gate()
        scene = kind.scene(gate)
        kind.describe_gate(gate, extra)
        controller = kind.controller(drive, gate, scene, clock=None, origin=origin)
        journal.controller = controller
        extra["scaling"] = kind.scaling(controller.axes.drives)
        recorder.stream(writer, kind.records(controller), controller.events, kind.scene_dicts(controller), kind.period)
        demo.enable(drive)
        summary = controller.run(cycles, stop.event if stop is not None else None,
                                 on_cycle=demo.on_cycle(sim, cycles, seconds))
        found = demo.findings(sim, controller, origin, cycles)
        if summary.exit_reason in ("completed", "stopped"):
            drive.disable()
        if stop is not None:
            stop.said(summary)
    _say_write_failure(recorder, summary)
    extra.update(exit_reason=summary.exit_reason, error=summary.error, operator_energy_exact=found.operator_energy,
                 port_energy_exact=found.port_energy)
    if found.steady is not None:
        extra["steady_states"] = [dict(vars(s)) for s in found.steady]
    files = recorder.finish(summary, pictures=plots)
    lock.release()
    _say_write_failure(recorder, summary)  # run.json's own completion too
    return DemoResult(profile, controller, summary, found, list(demo.lines(controller, summary, found)), files)


def _say_write_failure(recorder: RunRecorder, summary: RunSummary) -> None:
    """A folder the demo could not write (a full disk, deleted): its summary ends "write error" (exit 1), saying why."""
    if recorder.failure is not None:
        summary.exit_reason, summary.error = "write error", recorder.failure


def format_demo(result: DemoResult) -> str:
    """The demo's short summary, one fact a line."""
    lines = list(result.lines)
    reason, error = result.summary.exit_reason, result.summary.error
    if reason != "completed":
        lines.append(f"run ended early ({reason})" + (f": {error}" if error else ""))
    lines.append("wrote: " + ", ".join(str(f) for f in result.files))
    return "\n".join(lines)
