"""``haptic-bus run``: a profile's controller against a drive on a CAN bus or over Modbus.

The drive may be the simulated one in another process (``udp_multicast``, ``vcan0``, Modbus
TCP on loopback) or real hardware (``can0``, a Modbus TCP/RTU drive).  One run, in order:

1. the run's folder is created and shown writable (:mod:`~haptic_bus.app.run_folder`) before any
   bus is touched, and ``run.json`` written there ("running"); the run's writer process starts
   (:mod:`~haptic_bus.app.run_writer`), and on CANopen ``bus.asc`` with it, before the drive is
   reached (the drive link's tap copies every frame into its ring); with ``reset_fault`` a drive
   in FAULT is reset first, as ``haptic-bus fault-reset`` does (the first of run.json's events);
   without it a faulted drive is refused at enabling, with the command that clears it;
2. the drive is reached and commissioned (CANopen: the safety chain of ``[safety]``; Modbus: the
   gate judges with the loop delay the poll measured, :func:`drives.modbus.timing.loop_delay`);
3. **safe start**: the handle's position is read before enabling; inside an object the run is
   refused (:class:`Refusal`, the drive never enabled), or with ``in_contact = "ramp"`` the
   force rises from 0 over ``ramp_time`` once the gate has proven every scaled wall passive;
4. the record streamed by the writer process (and its live view), the upload server (CANopen:
   the controller's node on the drive's own network, its commits judged in a worker process
   started here, :mod:`~haptic_bus.node.controller_node`) and the real-time session are set up;
   then the drive is enabled, right before the first cycle (its RPDO deadline runs from there),
   and the controller cycles under the supervisor (``[supervisor]``), the control thread alone on
   the bus handle: it sends SYNC, RPDO and the controller's heartbeat, reads every frame, and
   answers the upload server's SDO requests;
5. ``record.csv`` is streamed from the first cycle and ``run.json`` kept current by the writer
   process (:mod:`~haptic_bus.app.run_recorder`), so a killed run keeps its cycles; whatever else
   ends it (the time, SIGTERM, Ctrl-C, a drive error, an assumption broken), the drive is left
   disabled, ``run.json`` completed and the pictures drawn.

:func:`exit_status` maps how a run ended to the command's exit status.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import pathlib
import signal
import threading
from collections.abc import Callable, Iterator, Mapping
from contextlib import ExitStack, contextmanager, nullcontext
from typing import TYPE_CHECKING, Any

from drives.base import Drive
from drives.bus_config import resolve_bus_config
from drives.cia402 import State
from drives.cia402_master import Cia402Master
from drives.drive_status import DEFAULT_ANSWER_TIMEOUT
from drives.fault_reset import DEFAULT_WAIT
from drives.os_threads import show_names
from drives.safety import VIRTUAL_TIME_CANOPEN_PATIENCE, VIRTUAL_TIME_MODBUS_PATIENCE, SafetySettings, patient
from haptic_bus.app import preflight
from haptic_bus.app.drive_address import DriveAddress
from haptic_bus.app.profile_policies import START_POLICIES
from haptic_bus.app.profiles import Profile
from haptic_bus.app.realtime import RealtimeReport, RealtimeSettings, realtime_session
from haptic_bus.app.run_folder import RECORD_CSV, RunJournal, gate_loop, prepare_run_folder, run_document, scene_dicts
from haptic_bus.app.run_recorder import RunRecorder
from haptic_bus.control.clock import RealClock, VirtualClock
from haptic_bus.control.controller import Derate, RunSummary, WallController, encoder_origin
from haptic_bus.control.gate import GateDecision, PassivityGate
from haptic_bus.control.record import Event
from haptic_bus.control.scene import CompiledScene
from haptic_bus.control.supervisor import Action
from haptic_bus.errors import DriveError, DriveFault, ParameterError, Refusal
from haptic_bus.validation import real_in_range

if TYPE_CHECKING:
    import can

    from drives.canopen.link import Tap
    from drives.modbus.drive import ModbusDrive
    from haptic_bus.node.controller_node import ControllerNode

logger = logging.getLogger(__name__)

DEFAULT_CONTROLLER_NODE_ID = 127
PROFILE_SCALING_SOURCE = "profile [device]"  # how the profile's scaling values are named in the report
DERATE_SCALE_STEPS = 40  # bisection steps of the derate's margin search inside a passive interval: 2^-40
DERATE_EXTRA_DELAYS = (0.25, 0.5, 1.0, 2.0, 3.0)  # samples beyond the assumed delay a derated scene is prepared for
WALL, VIRTUAL = "wall", "virtual"
PACINGS = (WALL, VIRTUAL)  # what paces a run's cycles: the wall clock, or the simulated drive (lock-step)
EXIT_STATUS = {"completed": 0, "stopped": 0, "refused": 1, "drive error": 1, "assumption broken": 3, "interrupted": 130}


class StopRequest:
    """How a run is asked to end: SIGTERM stops it (exit 0), SIGINT interrupts it (exit 130)."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self.interrupted = False

    def install(self) -> None:
        """SIGINT and SIGTERM set the event (the loop ends at the next cycle boundary)."""
        def on_signal(signum: int, frame: object) -> None:
            self.interrupted = self.interrupted or signum == signal.SIGINT
            self.event.set()

        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, on_signal)


@dataclasses.dataclass(frozen=True)
class RunOptions:
    """One run: ``duration`` (s), its ``pacing`` (:data:`PACINGS`: "wall", each cycle at its
    deadline on the wall clock, or "virtual", lock-step with a simulated drive, a cycle as soon
    as the last one ends), the output folder (None: ``runs/...``), the start-in-contact policy
    (None: the profile's), the live view, the stop request, what a wall-paced run asks of the OS
    for its control thread (``scheduling``, :mod:`~haptic_bus.app.realtime`: ``--realtime``),
    whether a drive found in FAULT is reset before commissioning, whether a CANopen run logs
    every frame (``bus.asc``, :mod:`~haptic_bus.app.bus_log`), and whether the pictures are drawn
    (seconds of matplotlib and of the region's boundary: ``--no-plots``, the benchmark, which runs
    the session many times, and the pytest plugin's runs leave them out)."""

    duration: float
    pacing: str = WALL
    out_dir: pathlib.Path | None = None
    start_in_contact: str | None = None
    live: bool = True
    stop: StopRequest = dataclasses.field(default_factory=StopRequest)
    scheduling: RealtimeSettings = dataclasses.field(default_factory=RealtimeSettings)
    reset_fault: bool = False
    bus_log: bool = True
    plots: bool = True

    def __post_init__(self) -> None:
        real_in_range("duration", self.duration, 0.0, 1e9, low_inclusive=False, unit="s", context="run options")
        check_pacing(self.pacing)
        if self.start_in_contact not in (None, *START_POLICIES):
            raise ParameterError("start_in_contact", self.start_in_contact,
                                 "None (the profile's) or " + " or ".join(repr(p) for p in START_POLICIES), "run options")
        if not isinstance(self.scheduling, RealtimeSettings):
            raise ParameterError("scheduling", self.scheduling, "a RealtimeSettings", "run options")

    @property
    def wall_paced(self) -> bool:
        """Whether the cycles keep the wall clock (``pacing == "wall"``)."""
        return self.pacing == WALL


def check_pacing(pacing: str) -> None:
    """ParameterError unless ``pacing`` is one of :data:`PACINGS`."""
    if pacing not in PACINGS:
        raise ParameterError("pacing", pacing, " or ".join(repr(p) for p in PACINGS), "run options")


@dataclasses.dataclass
class RunResult:
    """How a run ended (``exit_reason``, ``error``), what it did, and where it wrote."""

    exit_reason: str
    error: str | None
    summary: RunSummary | None
    controller: WallController | None
    folder: pathlib.Path
    files: list[pathlib.Path]


def exit_status(reason: str) -> int:
    """0 completed or stopped, 1 refused or a drive error, 3 an assumption broken, 130 interrupted."""
    return EXIT_STATUS[reason]


# --------------------------------------------------------------------------- the two links

def run_canopen(profile: Profile, bus: can.BusABC | Mapping[str, Any], node_id: int, options: RunOptions,
                controller_node_id: int = DEFAULT_CONTROLLER_NODE_ID) -> RunResult:
    """Run against CANopen drive ``node_id`` on ``bus`` and return how it ended (:class:`RunResult`).

    ``bus``: a configuration (python-can keyword arguments, ``{"interface": ..., "channel":
    ...}``; python-can's configuration chain fills what it leaves out), or an open
    :class:`can.BusABC` that the caller owns (the run neither closes it nor sets its receive
    filters).  Either way the controller is also CANopen node ``controller_node_id`` serving
    gated wall uploads over SDO, on the drive's own network and bus handle (its requests read
    and answered by the control thread while it cycles, :mod:`~haptic_bus.node.controller_node`),
    and ``bus.asc`` logs every frame of that handle (its tap); with an open bus ``reset_fault`` is
    refused (:class:`ParameterError`).
    The heartbeat the drive watches (``[safety]``) is sent as node ``controller_node_id`` either way.
    """
    import can

    from drives.canopen.drive import DEFAULT_TPDO_WITH_POSITION, CanopenDrive
    from haptic_bus.node.controller_node import ControllerNode

    if not isinstance(bus, (Mapping, can.BusABC)):
        raise ParameterError("bus", bus, "python-can keyword arguments (a mapping) or an open can.BusABC", "run_canopen")
    for name, value in (("node_id", node_id), ("controller_node_id", controller_node_id)):
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 127:
            raise ParameterError(name, value, "a CANopen node id, an integer 1..127", "run_canopen")
    given = None if isinstance(bus, Mapping) else bus
    if given is not None and options.reset_fault:
        raise ParameterError("reset_fault", True, "False with an open bus (the reset needs a bus configuration)",
                             "run_canopen")
    config = resolve_bus_config(**bus) if isinstance(bus, Mapping) else \
        {"interface": type(bus).__name__, "channel": bus.channel_info}  # before any file: an unknown interface is exit 2
    folder = prepare_run_folder(options.out_dir, profile.name)
    period = profile.loop.period
    safety = dataclasses.replace(profile.safety, master_node_id=controller_node_id)
    link = {"kind": "canopen", "bus": {k: str(v) for k, v in config.items()}, "node_id": node_id,
            "controller_node_id": controller_node_id, "upload_server": True, "bus_log": options.bus_log}
    where = ({"bus": given} if given is not None else
             {"interface": config["interface"], "channel": config.get("channel"), "bitrate": config.get("bitrate"),
              "bus_kwargs": {k: v for k, v in config.items() if k not in ("interface", "channel", "bitrate")}})

    def open_drive(stack: ExitStack, tap: Tap | None) -> tuple[Drive, PassivityGate, Serve]:
        drive = CanopenDrive(node_id, **where, period=period,
                             tpdo_objects=DEFAULT_TPDO_WITH_POSITION, scaling=profile.scaling(),
                             scaling_source=PROFILE_SCALING_SOURCE,
                             safety=safety if options.wall_paced else safety.for_virtual_time(period),
                             **patient(options.wall_paced, VIRTUAL_TIME_CANOPEN_PATIENCE))
        stack.callback(drive.close)
        drive.link.tap = tap  # before commissioning: its frames are logged too
        drive.connect()
        _show_scaling(drive, options)
        link["safety_warnings"] = list(drive.safety_warnings)
        link["pdo_mapping_notes"] = list(drive.commissioned.mapping_notes) if drive.commissioned is not None else []

        def serve(controller: WallController) -> ControllerNode:
            node = ControllerNode(controller, controller_node_id, safety.heartbeat_ms)
            if drive.link.network is None:
                raise DriveError(drive.name, "the CAN network has no bus after connecting")
            node.attach(drive.link.network)  # the drive's own network: one handle, read by the control thread
            stack.callback(node.detach)
            return node

        return drive, profile.gate(), serve

    hold = longest_hold(period, options.wall_paced, safety.rpdo_deadline_ms(period), safety.consumer_ms)
    address = DriveAddress(bus=dict(bus) if isinstance(bus, Mapping) else {}, node_id=node_id)
    return _session(profile, options, folder, link, open_drive,
                    DriveSide(hold, canopen_watchdog(safety, period), address, frames=True))


def run_modbus(profile: Profile, url: str, unit_id: int, options: RunOptions) -> RunResult:
    """Run against the Modbus drive at ``url`` (``tcp://HOST:PORT`` or ``rtu:/dev/...``)."""
    from drives.modbus.drive import ModbusDrive
    from drives.modbus.timing import loop_delay, measure_poll

    folder = prepare_run_folder(options.out_dir, profile.name)
    period = profile.loop.period
    safety = profile.safety if options.wall_paced else profile.safety.for_virtual_time(period)
    link: dict[str, Any] = {"kind": "modbus", "url": url, "unit_id": unit_id}

    def open_drive(stack: ExitStack, tap: Tap | None) -> tuple[Drive, PassivityGate, Serve]:
        drive = ModbusDrive.from_url(url, unit_id=unit_id, scaling=profile.scaling(), safety=safety, with_position=True,
                                     **patient(options.wall_paced, VIRTUAL_TIME_MODBUS_PATIENCE))
        stack.callback(drive.close)
        drive.connect()  # reads only: identity, scaling, timing
        _refuse_another_master(drive)  # before the poll measurement, which writes
        _show_scaling(drive, options)
        poll = None if drive.simulated_delay is not None else measure_poll(drive, 500)
        delay = loop_delay(drive, period, poll)
        link["poll"] = None if poll is None else dataclasses.asdict(poll)
        logger.info("Modbus poll: the gate assumes a loop delay of %.4g sample(s)", delay)
        gate = PassivityGate(dataclasses.replace(profile.device_loop(), delay=delay), profile.gate_policy)
        if not profile.passivity.beyond_gate:  # the profile was judged at its own timing's delay
            gate.admit(profile.compiled_scene())
        return drive, gate, lambda controller: None  # no upload server over Modbus

    hold = longest_hold(period, options.wall_paced, safety.modbus_watchdog_ms, 0)
    watchdog = Watchdog(safety.modbus_watchdog_ms / 1000.0 if safety.modbus_watchdog_ms else math.inf, None)
    return _session(profile, options, folder, link, open_drive, DriveSide(hold, watchdog, DriveAddress(url=url, unit_id=unit_id)))


def longest_hold(period: float, wall_paced: bool, deadline_ms: int, fallback_ms: int) -> float:
    """How long (s) the drive may hold one torque target before its watchdog removes it: the
    ``bound`` layer's budget per target.  In virtual time the simulated plant advances one
    period per SYNC, so a target acts exactly ``period``; wall-paced (``wall_paced``) up to the drive's receive
    deadline (RPDO deadline, Modbus watchdog; else ``fallback_ms``, the heartbeat consumer) plus
    the period it was latched for.  With no watchdog at all nothing bounds it: ``inf``."""
    if not wall_paced:
        return period
    watchdog = deadline_ms or fallback_ms
    return watchdog / 1000.0 + period if watchdog else math.inf


def canopen_watchdog(safety: SafetySettings, period: float) -> Watchdog:
    """The shortest stall that faults a CANopen drive with these settings at period ``period`` s:
    its RPDO deadline, or the slack its heartbeat consumer leaves over the controller's heartbeat."""
    deadline = safety.rpdo_deadline_ms(period) / 1000.0 if safety.rpdo_deadline_periods else math.inf
    slack = (safety.consumer_ms - safety.heartbeat_ms) / 1000.0 if safety.master_node_id is not None else math.inf
    return Watchdog(min(deadline, slack), safety.rpdo_deadline_periods if deadline <= slack else None)


def _refuse_another_master(drive: ModbusDrive) -> None:
    """A drive already OPERATION ENABLED when we arrive is driven by another master (every run
    leaves it disabled, and its watchdog faults it when a master dies): refuse before writing
    anything, rather than disable it under that master.  (The CANopen master does the same,
    and also listens for another SYNC, at commissioning.)"""
    if drive.state() is State.OPERATION_ENABLED:
        drive.link.drop()  # leave without a write: closing a live link writes the safe outputs, disabling it
        raise DriveError(drive.name, "the drive is in OPERATION ENABLED before this master enabled it: another master "
                                     "drives it; stop that master, or disable the drive, before starting this one")


def _show_scaling(drive: Cia402Master, options: RunOptions) -> None:
    """Say where each scaling factor came from (run.json records it too), unless the run is quiet."""
    if options.live and drive.scaling_report is not None:
        print("\n".join(f"scaling: {line}" for line in drive.scaling_report.lines()), flush=True)


# --------------------------------------------------------------------------- one session

Serve = Callable[[WallController], "ControllerNode | None"]  # the upload server, set up for a controller (None: none)
OpenDrive = Callable[[ExitStack, "Tap | None"], "tuple[Drive, PassivityGate, Serve]"]


@dataclasses.dataclass(frozen=True)
class Watchdog:
    """The shortest stall (s) that faults the drive (inf: none), and the RPDO deadline in periods
    when that is the binding one (a longer ``T`` lengthens it), else None."""

    stall: float
    periods: int | None


@dataclasses.dataclass(frozen=True)
class DriveSide:
    """What a session knows of the drive beside opening it: ``hold``, the longest it may hold a
    torque target (s, the ``bound`` layer's budget per target); its ``watchdog`` (pre-flight);
    its ``address`` (a fault reset before commissioning); ``frames``: whether it has CAN frames to
    log (a CAN bus)."""

    hold: float
    watchdog: Watchdog
    address: DriveAddress
    frames: bool = False


def _session(profile: Profile, options: RunOptions, folder: pathlib.Path, link: dict[str, Any],
             open_drive: OpenDrive, side: DriveSide) -> RunResult:
    """One run (module docstring)."""
    controller: WallController | None = None
    summary: RunSummary | None = None
    extra: dict[str, Any] = {"loop": {"period": profile.loop.period, "timing": profile.loop.timing}}
    journal = RunJournal(folder, profile, link, extra, run_document)
    journal.write()  # "running", before any bus is touched: a run killed from here on says so
    recorder = RunRecorder(folder, journal)
    reason, error = "completed", None
    before: list[Event] = []  # what happened before the controller (and its event log) existed
    try:
        with ExitStack() as stack:
            writer = recorder.start(stack, side.frames and options.bus_log)  # before the drive: commissioning logged
            if options.reset_fault:
                before += _reset_fault_first(side.address, options, extra)
            drive, gate, serve = open_drive(stack, writer.tap)
            extra["loop"]["delay_assumed"] = gate.device.delay
            extra["gate_loop"] = gate_loop(gate.device)
            scene = profile.compiled_scene()
            origin, ramp_time = _safe_start(profile, drive, gate, scene, options)
            extra["start"] = {"position_m": origin, "ramp_time_s": ramp_time}
            period = profile.loop.period
            clock = RealClock(period, spin=options.scheduling.spin) if options.wall_paced else VirtualClock(period)
            derate = prepare_derate(gate, scene) if Action.DERATE.value in (profile.supervisor.on_late,
                                                                            profile.supervisor.on_observer) else None
            controller = WallController(drive, gate, scene, force_limit=profile.force_limit, clock=clock, origin=origin,
                                        supervisor=profile.supervisor, ramp_time=ramp_time, derate=derate,
                                        passivity=profile.passivity, hold=side.hold, shared_records=True)
            extra["passivity"] = {"layer": profile.passivity.layer, "hold_s": controller.hold,
                                  "budget_cap_j": controller.ports[0].observer.cap, "friction_min": gate.device.b,
                                  "beyond_gate": profile.passivity.beyond_gate}
            for event in before:
                controller.events.add(event.time_s, event.kind, event.message, **event.data)
            journal.controller = controller
            recorder.stream(writer, [(RECORD_CSV, "", controller.record)], controller.events,
                            functools.partial(scene_dicts, controller), period,
                            f"haptic-bus run {profile.name}" if options.live else None, options.duration)
            node = serve(controller)
            with control_thread_scheduling(options) as scheduling:
                extra["realtime"] = scheduling.to_dict() if scheduling is not None else None
                if options.wall_paced:
                    _preflight(drive, gate, scene, profile, options, side.watchdog, extra)
                recorder.publish()  # run.json as it stands before the cycles (pre-flight's verdict in it)
                # last before the first cycle: the drive's RPDO deadline runs from here, and the
                # set-up above (the upload server, the real-time session) can take longer
                show_names()  # every helper thread by its name in top -H and /proc/PID/task/*/comm
                drive.enable()
                with node.cycling() if node is not None else nullcontext():  # its verdicts answered by the cycle
                    summary = controller.run(max(1, round(options.duration / period)), options.stop.event,
                                             on_cycle=node.poll if node is not None else None)
            reason, error = summary.exit_reason, summary.error
            if reason == "stopped" and options.stop.interrupted:
                reason, error = "interrupted", "interrupted (Ctrl-C)"  # the command's one line on stderr
            if reason in ("completed", "stopped", "interrupted"):
                drive.disable()
    except Refusal as exc:  # refused before the drive is enabled
        reason, error = "refused", str(exc)
    except DriveError as exc:
        reason, error = "drive error", str(exc)
        if isinstance(exc, DriveFault) and exc.state is State.FAULT:
            error += f"; {side.address.fault_reset_hint()} (or run with --reset-fault)"
    except KeyboardInterrupt:
        reason, error = "interrupted", "interrupted (Ctrl-C)"
    finally:
        extra["exit_reason"], extra["error"] = reason, error
        files = recorder.finish(summary, pictures=options.plots)
    return RunResult(reason, error, summary, controller, folder, files)


def _preflight(drive: Drive, gate: PassivityGate, scene: CompiledScene, profile: Profile, options: RunOptions,
               watchdog: Watchdog, extra: dict[str, Any]) -> None:
    """Measure this machine's lateness on this bus with the drive not enabled, print it and record it
    in ``extra``, and refuse (:class:`Refusal`) a run the drive's watchdogs, or the gate without
    a layer, cannot hold."""
    with drive.cyclic() as cycle:  # the run's own path, every target zero
        timing = preflight.measure(lambda: (cycle.read(), cycle.saturate_and_write(0)), profile.loop.period,
                                   spin=options.scheduling.spin)
    preflight.settle(preflight.judge(timing, gate, scene, profile.passivity.layer, watchdog.stall, watchdog.periods),
                     options.live, extra)


def _reset_fault_first(address: DriveAddress, options: RunOptions, extra: dict[str, Any]) -> list[Event]:
    """``--reset-fault``: reset a drive found in FAULT before commissioning; the reset as an event
    (run.json's ``events``, also when the run ends before it cycles), or none if the drive was
    not in FAULT.  DriveFault if the cause persists."""
    outcome = address.reset_fault(DEFAULT_WAIT, DEFAULT_ANSWER_TIMEOUT)
    if not outcome.reset_sent and outcome.cleared:
        logger.info("%s", outcome.message())
        return []
    event = Event(0.0, "fault reset", f"before commissioning: {outcome.message()}", outcome.to_dict())
    extra["events"] = [event.to_dict()]
    if not outcome.cleared:
        raise DriveFault(outcome.drive, f"--reset-fault: {outcome.detail()}", outcome.error_code_after)
    if options.live:
        print(f"fault reset: {outcome.message()}", flush=True)
    return [event]


@contextmanager
def control_thread_scheduling(options: RunOptions) -> Iterator[RealtimeReport | None]:
    """A wall-paced run's control thread set up for the cycles (entered last: helper threads keep theirs)."""
    if not options.wall_paced:
        yield None
        return
    with realtime_session(options.scheduling) as report:
        yield report


def _safe_start(profile: Profile, drive: Drive, gate: PassivityGate, scene: CompiledScene,
                options: RunOptions) -> tuple[float, float]:
    """The handle's position (m) before enabling, and the start ramp's time (s, 0 = none).

    Inside an object: :class:`Refusal` under "refuse"; under "ramp" the ramp time, once the
    gate has proven every wall scaled by a factor in (0, 1] passive.
    """
    origin = encoder_origin(drive)
    names, force, stiffness = scene.contact(origin)
    if force == 0.0:
        return origin, 0.0
    depth = abs(force) / stiffness if stiffness > 0 else math.nan
    where = f"handle is {depth * 1e3:.1f} mm inside {'+'.join(names)} (at rest it would feel {abs(force):.3g} N)"
    policy = options.start_in_contact or profile.start.in_contact
    if policy != "ramp":
        raise Refusal(f"{where}; move it out or use --start-in-contact ramp")
    proof = gate.proves_ramp(scene)
    if not proof.proven:
        raise Refusal(f"{where}; and the start ramp is refused: {proof.reason}")
    logger.info("%s: ramping the force in over %g s", where, profile.start.ramp_time)
    return origin, profile.start.ramp_time


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
