"""``haptic-bus run <multi-axis profile>``: a scene in space through several CANopen drives on one SYNC.

The drives may be the simulated device in another process (``haptic-bus sim --node-ids 5,6,7
--profile gantry-3d`` on ``udp_multicast``), or real ones.  One run, in order:

1. the profile's axes must map 0x6064 (``mapping = "with-position"``: the port observer and the
   passivity layer read it every cycle; exit 2 otherwise) and the controller's node id must be
   none of theirs -- checked before anything is touched; the run's folder is created and shown
   writable (:mod:`~haptic_bus.app.run_folder`);
2. **the bus load** (:func:`haptic_bus.control.bus_load.axes_bus_load`): one SYNC and every axis'
   PDOs at the bus' bitrate (``--bitrate``, python-can's configuration, else the profile's
   ``[bus] bitrate``) and ``T``; above 70 % the run is refused, naming the load and the smallest
   ``T`` that fits (exit 1, no bus opened, nothing enabled);
3. every drive is reached and commissioned (:class:`drives.canopen.axes.CanopenAxes`: each its own
   safety chain; one heartbeat of this controller's node for all; in virtual time the master's own
   patience is :data:`drives.safety.VIRTUAL_TIME_CANOPEN_PATIENCE`);
4. real time only: pre-flight timing (:mod:`~haptic_bus.app.preflight`) with the coupled gate at
   the measured delay;
5. **safe start**: every axis' position is read right before enabling (after pre-flight, whose
   SYNCs a real handle lives through); a handle inside an object is refused (exit 1, nothing
   enabled), or with ``--start-in-contact ramp`` the force ramps in along each contact normal
   once the coupled gate has proven every scaled wall passive; then the controller's node joins the
   axes' network (gated uploads of every object's K and B, judged by the coupled gate in the judge
   process, :mod:`~haptic_bus.node.controller_node`), every drive is enabled in the same cycle and
   the controller cycles (:class:`~haptic_bus.control.controller.WallController`) under the
   supervisor, the control thread alone on the bus handle;
6. from the first cycle the run's writer process (started before commissioning, with the bus
   log on the drives' one handle) streams every axis' record and keeps ``run.json`` current, as
   for one axis (:class:`~haptic_bus.app.run_recorder.RunRecorder`, :mod:`~haptic_bus.app.axes_records`):
   a killed run keeps them; whatever else ends it (the time, SIGTERM, Ctrl-C, any axis' fault --
   which zeroes every axis' torque in the same cycle -- an assumption broken), the drives are left
   disabled, ``run.json`` completed and the plot drawn.
"""

from __future__ import annotations

import dataclasses
import functools
import pathlib
from collections.abc import Mapping
from contextlib import ExitStack
from typing import Any

from drives.bus_config import resolve_bus_config
from drives.canopen.axes import CanopenAxes
from drives.canopen.drive import DEFAULT_TPDO_WITH_POSITION
from drives.os_threads import show_names
from drives.safety import VIRTUAL_TIME_CANOPEN_PATIENCE, patient
from haptic_bus.app import preflight
from haptic_bus.app.axes_profile import AxesProfile
from haptic_bus.app.axes_records import axes_run_document, record_files, space_scene_dicts
from haptic_bus.app.profile_policies import StartPolicy
from haptic_bus.app.run_folder import RunJournal, prepare_run_folder
from haptic_bus.app.run_recorder import RunRecorder
from haptic_bus.app.runner import (
    DEFAULT_CONTROLLER_NODE_ID,
    PROFILE_SCALING_SOURCE,
    RunOptions,
    canopen_watchdog,
    control_thread_scheduling,
    longest_hold,
)
from haptic_bus.control.bus_load import axes_bus_load
from haptic_bus.control.clock import RealClock, VirtualClock
from haptic_bus.control.controller import WallController, encoder_origins
from haptic_bus.control.cycle_loop import RunSummary
from haptic_bus.control.space_gate import SpaceDecision, SpaceGate
from haptic_bus.control.space_scene import SpaceScene
from haptic_bus.errors import DriveError, ParameterError, Refusal
from haptic_bus.node.controller_node import ControllerNode

RUN_MAPPING = "with-position"


@dataclasses.dataclass
class AxesRunResult:
    """How a multi-axis run ended (``exit_reason``, ``error``), what it did, and where it wrote."""

    exit_reason: str
    error: str | None
    summary: RunSummary | None
    controller: WallController[SpaceScene, SpaceDecision] | None
    folder: pathlib.Path
    files: list[pathlib.Path]


def check_run(profile: AxesProfile, controller_node_id: int) -> list[int]:
    """The axes' node ids, once the profile can be run as the controller node ``controller_node_id``;
    ParameterError (exit 2) naming the field otherwise."""
    nodes = [axis.node_id for axis in profile.axes]
    if any(node is None for node in nodes):
        raise ParameterError("axes[0].unit_id", profile.axes[0].unit_id,
                             "a node_id per axis: a multi-axis run drives CANopen axes (Modbus axes are not built)",
                             f"profile {profile.path or profile.name}")
    for i, axis in enumerate(profile.axes):
        if axis.mapping != RUN_MAPPING:
            raise ParameterError(f"axes[{i}].mapping", axis.mapping, f'"{RUN_MAPPING}" for a run: the port observer and '
                                 "the passivity layer read 0x6064 every cycle", f"profile {profile.path or profile.name}")
    if controller_node_id in nodes:
        raise ParameterError("--controller-node-id", controller_node_id, f"a node id none of the axes has ({nodes})")
    return [node for node in nodes if node is not None]


def run_axes_canopen(profile: AxesProfile, bus: Mapping[str, Any], options: RunOptions,
                     controller_node_id: int = DEFAULT_CONTROLLER_NODE_ID) -> AxesRunResult:
    """Run ``profile`` against its axes' drives on ``bus`` (python-can keyword arguments) as CANopen
    node ``controller_node_id`` (module docstring)."""
    nodes = check_run(profile, controller_node_id)
    config = resolve_bus_config(**bus)  # before any file: an unknown interface is exit 2
    folder = prepare_run_folder(options.out_dir, profile.name)
    period = profile.period
    safety = dataclasses.replace(profile.safety, master_node_id=controller_node_id)
    bitrate = float(config.get("bitrate") or profile.bitrate)
    link: dict[str, Any] = {"kind": "canopen", "bus": {k: str(v) for k, v in config.items()}, "node_ids": nodes,
                            "controller_node_id": controller_node_id, "upload_server": True, "bitrate_checked": bitrate}
    extra: dict[str, Any] = {"loop": {"period": period, "delays": [axis.delay for axis in profile.axes]}}
    journal = RunJournal(folder, profile, link, extra, axes_run_document)
    journal.write()  # "running", before any bus is touched: a run killed from here on says so
    recorder = RunRecorder(folder, journal)
    controller: WallController[SpaceScene, SpaceDecision] | None = None
    summary: RunSummary | None = None
    reason, error = "completed", None
    try:
        try:
            load = axes_bus_load([axis.mapping for axis in profile.axes], bitrate, period)
        except ParameterError as refusal:
            raise Refusal(f"the bus cannot carry this cycle; allowed: {refusal.allowed}") from None
        link["bus_load"] = dataclasses.asdict(load)
        with ExitStack() as stack:
            writer = recorder.start(stack, options.bus_log)  # before the drives: commissioning logged
            axes = CanopenAxes(nodes, scalings=[axis.device.scaling() for axis in profile.axes],
                               interface=config["interface"], channel=config.get("channel"), bitrate=config.get("bitrate"),
                               bus_kwargs={k: v for k, v in config.items() if k not in ("interface", "channel", "bitrate")},
                               period=period, tpdo_objects=DEFAULT_TPDO_WITH_POSITION, scaling_source=PROFILE_SCALING_SOURCE,
                               safety=safety if options.wall_paced else safety.for_virtual_time(period),
                               **patient(options.wall_paced, VIRTUAL_TIME_CANOPEN_PATIENCE))
            stack.callback(axes.close)
            axes.link.tap = writer.tap
            axes.connect()
            _describe(axes, options, link)
            scene = profile.space_scene()
            gate = profile.gate()
            with control_thread_scheduling(options) as scheduling:
                extra["realtime"] = scheduling.to_dict() if scheduling is not None else None
                if options.wall_paced:
                    _preflight(axes, gate, scene, profile, options, extra)
                origin, ramp_time = _safe_start(axes, profile, gate, scene, options)  # after pre-flight: where it is now
                extra["start"] = {"positions_m": origin, "ramp_time_s": ramp_time}
                clock = RealClock(period, spin=options.scheduling.spin) if options.wall_paced else VirtualClock(period)
                hold = longest_hold(period, options.wall_paced, safety.rpdo_deadline_ms(period), safety.consumer_ms)
                controller = WallController(axes, gate, scene, names=[axis.name for axis in profile.axes],
                                            force_limit=[axis.force_limit for axis in profile.axes], clock=clock,
                                            origin=origin, supervisor=profile.supervisor, ramp_time=ramp_time,
                                            passivity=profile.passivity, hold=hold, shared_records=True)
                extra["passivity"] = {"layer": profile.passivity.layer, "hold_s": controller.hold, "per_axis": True}
                journal.controller = controller
                recorder.stream(writer, record_files(controller), controller.events,
                                functools.partial(space_scene_dicts, controller), period,
                                f"haptic-bus run {profile.name}" if options.live else None, options.duration)
                node = _serve(stack, controller, axes, controller_node_id, safety.heartbeat_ms)
                show_names()  # every helper thread by its name in top -H and /proc/PID/task/*/comm
                axes.enable()  # every drive in the same cycle, right before the first: their RPDO deadlines run from here
                with node.cycling():  # its verdicts answered by the cycle
                    summary = controller.run(max(1, round(options.duration / period)), options.stop.event,
                                             on_cycle=node.poll)
            reason, error = summary.exit_reason, summary.error
            if reason == "stopped" and options.stop.interrupted:
                reason, error = "interrupted", "interrupted (Ctrl-C)"
            if reason in ("completed", "stopped", "interrupted"):
                axes.disable()
    except Refusal as exc:
        reason, error = "refused", str(exc)
    except DriveError as exc:
        reason, error = "drive error", str(exc)
    except KeyboardInterrupt:
        reason, error = "interrupted", "interrupted (Ctrl-C)"
    finally:
        extra["exit_reason"], extra["error"] = reason, error
        files = recorder.finish(summary, pictures=options.plots)
    return AxesRunResult(reason, error, summary, controller, folder, files)


def _serve(stack: ExitStack, controller: WallController[SpaceScene, SpaceDecision], axes: CanopenAxes, node_id: int,
           heartbeat_ms: int) -> ControllerNode:
    """The controller as CANopen node ``node_id`` on the axes' own network (one handle, read by the
    control thread): gated uploads of the scene's walls, judged by the coupled gate in the judge process."""
    if axes.link.network is None:
        raise DriveError(axes.name, "the CAN network has no bus after connecting")
    node = ControllerNode(controller, node_id, heartbeat_ms)
    node.attach(axes.link.network)
    stack.callback(node.detach)
    return node


def _describe(axes: CanopenAxes, options: RunOptions, link: dict[str, Any]) -> None:
    """Each axis' scaling sources, safety warnings and PDO mapping notes: printed (unless quiet) and in ``link``."""
    link["safety_warnings"] = {drive.name: list(drive.safety_warnings) for drive in axes.drives}
    link["pdo_mapping_notes"] = {drive.name: list(drive.commissioned.mapping_notes) if drive.commissioned else []
                                 for drive in axes.drives}
    if options.live:
        for drive in axes.drives:
            report = drive.scaling_report
            lines = report.lines() if report is not None else []
            print("\n".join(f"scaling of {drive.name}: {line}" for line in lines), flush=True)


def _safe_start(axes: CanopenAxes, profile: AxesProfile, gate: SpaceGate, scene: SpaceScene,
                options: RunOptions) -> tuple[list[float], float]:
    """Every axis' position (m) before enabling, and the start ramp's time (s, 0 = none).

    Inside an object: :class:`Refusal`, or under ``--start-in-contact ramp`` the ramp time once
    the coupled gate has proven every wall scaled by a factor in [0, 1] passive along its normals.
    """
    q = encoder_origins(axes)
    x = profile.kinematics().position(q)
    inside = scene.contacts(x)
    if not inside:
        return q, 0.0
    force = float(sum(value * value for value in scene.force(x, [0.0] * len(q))) ** 0.5)
    where = (f"handle is inside {'+'.join(inside)} at ({', '.join(f'{c * 1e3:.3g}' for c in x)}) mm (at rest "
             f"it would feel {force:.3g} N)")
    if options.start_in_contact != "ramp":
        raise Refusal(f"{where}; move it out first or use --start-in-contact ramp")
    proof = gate.proves_ramp(scene)
    if not proof.proven:
        raise Refusal(f"{where}; and the start ramp is refused: {proof.reason}")
    return q, StartPolicy().ramp_time


def _preflight(axes: CanopenAxes, gate: SpaceGate, scene: SpaceScene, profile: AxesProfile, options: RunOptions,
               extra: dict[str, Any]) -> None:
    """Pre-flight timing with every drive not enabled; the coupled gate judged at the measured delay."""
    assumed = max(loop.delay for loop in gate.axes)

    def passes_at(delay: float) -> bool:
        later = tuple(dataclasses.replace(loop, delay=loop.delay + delay - assumed) for loop in gate.axes)
        return SpaceGate(later, gate.policy).judge(scene).accepted

    watchdog = canopen_watchdog(axes.drives[0].safety, profile.period)
    zeros = [0] * len(gate.axes)
    with axes.cyclic() as cycle:  # the run's own path, every target zero
        timing = preflight.measure(lambda: (cycle.read(), cycle.saturate_and_write(zeros)), profile.period,
                                   spin=options.scheduling.spin)
    preflight.settle(preflight.judge_delay(timing, assumed, passes_at, profile.passivity.layer, watchdog.stall,
                                           watchdog.periods), options.live, extra)
