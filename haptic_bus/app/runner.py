"""``haptic-bus run``: a profile's controller against its drive(s), one axis or several, on a CAN bus or over Modbus.

The drives may be the simulated ones in another process (``haptic-bus sim``, ``haptic-bus sim
--node-ids 5,6,7 --profile gantry-3d`` on ``udp_multicast``, ``vcan0``, Modbus TCP on loopback) or
real hardware (``can0``, a Modbus TCP/RTU drive).  One code path for any axis count: what differs
by link sits in a :class:`~haptic_bus.app.run_links.Rig` (one CANopen drive, several on one SYNC,
one Modbus drive or several polled in one cycle -- ``haptic-bus sim --modbus tcp://127.0.0.1:0
--unit-ids 1,2,3 --profile gantry-3d``), what differs by profile kind in a
:mod:`~haptic_bus.app.run_kinds` kind (a 1-D scene or a scene in space).  One run, in order:

1. the link is checked before anything is touched (node ids 1..127, none twice, each axis' 0x6064
   mapped, the controller's node id none of theirs: exit 2); the run's folder is
   created and shown writable (:mod:`~haptic_bus.app.run_folder`), locked for this run (another
   run's folder: exit 2, :mod:`~haptic_bus.app.folder_lock`) and ``run.json`` written there
   ("running");
2. CANopen: **the bus load** (:func:`haptic_bus.control.bus_load.axes_bus_load`), one SYNC and
   every axis' PDOs at the bus' bitrate and ``T``; above 70 % the run is refused, naming the load
   and the smallest ``T`` that fits (exit 1, no bus opened, nothing enabled);
3. the run's writer process starts (:mod:`~haptic_bus.app.run_writer`), and on CANopen ``bus.asc``
   with it, before the drives are reached (the link's tap copies every frame into its ring); with
   ``reset_fault`` every drive found in FAULT is reset first, axis by axis, as ``haptic-bus
   fault-reset`` does (each reset one of run.json's events); without it a drive found in FAULT
   once reached (step 4) is refused there, before pre-flight, naming its error code and the
   command that clears that axis' drive;
4. the drive(s) are reached and commissioned (CANopen: each the safety chain of ``[safety]``, one
   heartbeat of this controller's node for all; Modbus: each unit's 0x6007 and watchdog, a unit
   nobody answers for named, and the gate -- 1-D or coupled -- judges with each axis' loop delay
   from the poll, :func:`drives.modbus.timing.loop_delay`); the supervisor's derate table, where
   the profile asks for one, is started (:mod:`~haptic_bus.app.derate_table`);
5. real time only: **pre-flight** (:mod:`~haptic_bus.app.preflight`) runs the cyclic path at zero
   torque, drives not enabled, and judges the gate at the delay it measured (a stop, SIGTERM or
   Ctrl-C, ends the run there, never enabled: :attr:`RunResult.preflight_stopped` and ``run.json``'s
   ``preflight_stopped`` name the cycles it had measured);
6. **safe start** (with step 7 before pre-flight, which then measures the cycle after that start-up
   work, and leaves no gap in the RPDOs it started before the drives are enabled): the handle's
   position (every joint's) is read; inside an object the run is refused (:class:`Refusal`, the
   drives never enabled), or with ``in_contact = "ramp"`` the force rises from 0 over the ramp
   time (along each contact normal for several axes) once the gate has proven every scaled wall
   passive; without a ramp it is read again after pre-flight, whose cycles a real handle lives
   through, right before enabling;
7. the controller is built, its records streamed by the writer process (and its live view), the
   upload server set up (CANopen: the controller's node on the drives' own network, its commits
   judged by the gate -- 1-D or coupled -- in a worker process, :mod:`~haptic_bus.node.controller_node`);
   then every drive is enabled in the same cycle, right before the first (their RPDO deadlines run
   from there), and the controller cycles under the supervisor (``[supervisor]``), the control
   thread alone on the bus handle: it sends SYNC, RPDOs and the controller's heartbeat, reads every
   frame, and answers the upload server's SDO requests;
8. every axis' record is streamed from the first cycle and ``run.json`` kept current by the writer
   process (:mod:`~haptic_bus.app.run_recorder`), so a killed run keeps its cycles; whatever else
   ends it (the time, SIGTERM, Ctrl-C, a drive error -- any axis' fault zeroes every axis' torque
   in the same cycle -- an assumption broken), the drives are left disabled, ``run.json``
   completed and the pictures drawn (none for a run Ctrl-C or SIGTERM stopped before its first
   cycle: it ends at once, ``haptic-bus plot`` draws them).  A folder the writer can no longer write (a full disk, the
   folder deleted) stops the run at the next cycle boundary: the drives disabled, "write error"
   (exit 1), what was written before kept, nothing more attempted.
   An exception none of these is (a bug, a judge worker that could not start) is raised, ``run.json``
   saying "crashed" and the exception, not "completed".

:func:`~haptic_bus.app.run_options.exit_status` maps how a run ended to the command's exit status.
"""

from __future__ import annotations

import dataclasses
import logging
import pathlib
from collections.abc import Iterator, Mapping, Sequence
from contextlib import ExitStack, contextmanager, nullcontext
from typing import TYPE_CHECKING, Any

from drives.base import Drive, OneAxis
from drives.cia402 import State
from drives.cia402_master import Cia402Master
from drives.drive_status import DEFAULT_ANSWER_TIMEOUT
from drives.fault_reset import DEFAULT_WAIT
from drives.modbus.register_map import UNIT_IDS
from drives.os_threads import show_names
from haptic_bus.app import preflight
from haptic_bus.app.drive_address import DEFAULT_UNIT_ID, DriveAddress
from haptic_bus.app.profiles import AxesProfile, Profile
from haptic_bus.app.realtime import RealtimeReport, realtime_session
from haptic_bus.app.run_folder import RunJournal, own_run_folder
from haptic_bus.app.run_kinds import RunKind, run_kind
from haptic_bus.app.run_links import DEFAULT_CONTROLLER_NODE_ID, Rig, canopen_rig, modbus_rig, modbus_units
from haptic_bus.app.run_options import RunOptions
from haptic_bus.app.run_recorder import RunRecorder
from haptic_bus.control.clock import RealClock, VirtualClock
from haptic_bus.control.controller import RunSummary, WallController
from haptic_bus.control.record import Event
from haptic_bus.errors import DriveError, DriveFault, DriveTimeout, HapticBusError, ParameterError, Refusal
from haptic_bus.profile.scene import check_force_limit

if TYPE_CHECKING:
    import can

    from haptic_bus.node.controller_node import ControllerNode

logger = logging.getLogger(__name__)


@dataclasses.dataclass
class RunResult:
    """How a run ended (``exit_reason``, ``error``), what it did, and where it wrote;
    ``preflight_stopped``: the cycles pre-flight had measured when a stop (SIGTERM, Ctrl-C) ended the
    run there, before enabling (``run.json``'s ``preflight_stopped``), else None."""

    exit_reason: str
    error: str | None
    summary: RunSummary | None
    controller: WallController[Any, Any] | None
    folder: pathlib.Path
    files: list[pathlib.Path]
    preflight_stopped: int | None = None


def run(profile: Profile | AxesProfile, bus: can.BusABC | Mapping[str, Any] | str | Sequence[str], options: RunOptions,
        *, node_id: int | None = None, unit_id: int | None = None, unit_ids: Sequence[int] | None = None,
        controller_node_id: int = DEFAULT_CONTROLLER_NODE_ID, kind: RunKind[Any, Any, Any] | None = None) -> RunResult:
    """Run ``profile`` -- one axis, or several (``[[axes]]``) -- and return how it ended (:class:`RunResult`).

    ``bus``: python-can keyword arguments (``{"interface": ..., "channel": ...}``; python-can's
    configuration chain fills what it leaves out) or an open :class:`can.BusABC` the caller owns
    (the run neither closes it nor sets its receive filters, and ``reset_fault`` is refused) for
    CANopen; or a Modbus URL (``tcp://HOST:PORT``, ``rtu:/dev/...``), or a list of
    them, one per axis.  One CANopen axis is drive ``node_id``; several take theirs from
    ``[[axes]]``.  One Modbus axis is unit ``unit_id``; several are units ``unit_ids`` (one per
    axis, in axis order; default: the profile's ``[[axes]]`` unit ids, else unit 1 on each server
    of a URL per axis), every unit polled in one cycle.  On CANopen the controller is also node
    ``controller_node_id``, serving gated wall uploads over SDO on the drives' own network and bus
    handle, sending the heartbeat the drives watch, and ``bus.asc`` logs every frame of that
    handle.  ParameterError (nothing touched) for a combination that names no drive.  ``kind``:
    what the run renders and how (default :func:`~haptic_bus.app.run_kinds.run_kind` of ``profile``:
    its own scene; ``haptic-bus validate`` passes its probe,
    :class:`~haptic_bus.app.validate_run.ValidateRun`).
    """
    _refuse_a_spawned_start()
    rig = _rig(profile, bus, options, node_id, unit_id, unit_ids, controller_node_id)
    return _session(kind or run_kind(profile), rig, options)


def _refuse_a_spawned_start() -> None:
    """HapticBusError, before any folder or bus, when ``run`` is called from a script's top level that a
    process started by ``spawn`` (a run's writer or judge) is running again: the script lacks
    ``if __name__ == "__main__":``.  Where its top level caught the error the worker started, and that
    second ``run`` wrote a run folder of its own saying "crashed" (multiprocessing's RuntimeError) beside
    the real run; the check is the one multiprocessing makes before it starts a process."""
    import multiprocessing

    if getattr(multiprocessing.current_process(), "_inheriting", False):
        raise HapticBusError("hb.run was called while a process of a run started (spawn runs the calling script's "
                             "top level again in it): keep the run under if __name__ == '__main__': (Python's rule "
                             "for spawned processes)")


def run_canopen(profile: Profile, bus: can.BusABC | Mapping[str, Any], node_id: int, options: RunOptions,
                controller_node_id: int = DEFAULT_CONTROLLER_NODE_ID) -> RunResult:
    """:func:`run` against one CANopen drive ``node_id``."""
    return run(profile, bus, options, node_id=node_id, controller_node_id=controller_node_id)


def run_modbus(profile: Profile, url: str, unit_id: int, options: RunOptions) -> RunResult:
    """:func:`run` against the Modbus drive at ``url``, unit ``unit_id`` (required: None is refused as
    missing, not taken as :func:`run`'s default unit 1)."""
    if not isinstance(url, str):  # None went on as a CANopen bus and was refused as 'unit_id = 1 is invalid'
        raise ParameterError("url", url, "a Modbus URL, tcp://HOST:PORT or rtu:/dev/SERIAL", "run_modbus")
    if unit_id is None:  # run() reads None as its default, unit 1: the drive a caller left out was quietly unit 1
        raise ParameterError("unit_id", None, UNIT_IDS, "run_modbus")
    return run(profile, url, options, unit_id=unit_id)


def _rig(profile: Profile | AxesProfile, bus: can.BusABC | Mapping[str, Any] | str | Sequence[str], options: RunOptions,
         node_id: int | None, unit_id: int | None, unit_ids: Sequence[int] | None, controller_node_id: int) -> Rig:
    """The link ``profile`` and ``bus`` name (:mod:`~haptic_bus.app.run_links`); ParameterError if none."""
    if not isinstance(profile, (Profile, AxesProfile)):  # a name or a path: what hb.load_profile takes
        raise ParameterError("profile", profile, "a Profile or an AxesProfile, as hb.load_profile(name_or_path) "
                             "returns it", "run")
    if not isinstance(options, RunOptions):
        raise ParameterError("options", options, "a RunOptions, e.g. hb.RunOptions(duration=1.0)", "run")
    several = isinstance(profile, AxesProfile)
    _refuse_unread_limits(profile)
    _refuse_misplaced_ids(several, isinstance(bus, (str, Sequence)), node_id, unit_id, unit_ids)
    if isinstance(bus, (str, Sequence)):
        urls = [bus] if isinstance(bus, str) else list(bus)
        one = DEFAULT_UNIT_ID if unit_id is None else unit_id
        units = modbus_units(profile, urls, unit_ids if several else [one])
        return modbus_rig(profile, urls, units, options)
    return canopen_rig(profile, bus, options, node_id, controller_node_id)


def _refuse_unread_limits(profile: Profile | AxesProfile) -> None:
    """ParameterError, before any folder or bus, for a force limit outside what its drive allows: a profile a
    program built (``dataclasses.replace(profile, force_limit=-5.0)``) skipped the reader's check, and was
    refused only after commissioning (``torque_limit = -312``), its run.json saying "crashed"."""
    if isinstance(profile, Profile):
        check_force_limit("limits.force_limit", profile.force_limit, profile.device, "run")
        return
    for i, axis in enumerate(profile.axes):
        check_force_limit(f"axes[{i}].force_limit", axis.force_limit, axis.device, "run")


def _refuse_faulted_at_the_end(drives: Sequence[Any]) -> None:
    """DriveFault for the first drive that sits in FAULT after the run's disable walk (which accepts
    FAULT as an end), read acyclically: a drive that faulted as the run ended (its RPDO deadline, a
    stall between the last cycle and the disable) makes the run a drive error, not "completed"."""
    for each in drives:
        try:
            each.refuse_fault()
        except DriveFault as fault:
            raise DriveFault(fault.node, f"in FAULT after the run's last cycle: {fault.message}", fault.code,
                             fault.state) from fault


def _refuse_misplaced_ids(several: bool, modbus: bool, node_id: int | None, unit_id: int | None,
                          unit_ids: Sequence[int] | None) -> None:
    """ParameterError naming the first of run()'s drive ids given where it names nothing: ``node_id``
    (one CANopen drive) for several axes or over Modbus, ``unit_id`` (one Modbus unit) for several or
    on CANopen, ``unit_ids`` (several Modbus units) for one axis or on CANopen."""
    for name, value, wrong, allowed in (
            ("node_id", node_id, several or modbus, "none: it names one CANopen drive; several take theirs from "
                                                    "[[axes]], a Modbus drive is unit_id"),
            ("unit_id", unit_id, several or not modbus, "none: it names one Modbus unit (several: unit_ids); a "
                                                        "CANopen drive is node_id"),
            ("unit_ids", unit_ids, not several or not modbus, "none: they name several axes' Modbus units (one axis: "
                                                              "unit_id; CANopen: [[axes]] node_id)")):
        if value is not None and wrong:
            raise ParameterError(name, value, allowed, "run")


def _session(kind: RunKind[Any, Any, Any], rig: Rig, options: RunOptions) -> RunResult:
    """One run (module docstring)."""
    folder, lock = own_run_folder(options.out_dir, kind.profile.name)  # before its bus or files
    controller: WallController[Any, Any] | None = None
    summary: RunSummary | None = None
    extra: dict[str, Any] = {"loop": kind.loop_extra()}
    journal = RunJournal(folder, kind, rig.link, extra, rig.safety)
    journal.begin()  # "running", before any bus is touched: a run killed from here on says so
    recorder = RunRecorder(folder, journal)
    reason, error = "completed", None
    before: list[Event] = []  # what happened before the controller (and its event log) existed
    names: list[str] = []  # the drives' names, in axis order, once reached
    drives: Sequence[Drive] = ()
    period = kind.period
    try:
        rig.check()
        with ExitStack() as stack:
            writer = recorder.start(stack, rig.frames and options.bus_log,  # before the drive: commissioning logged
                                    on_failure=options.stop.event.set)  # a folder that cannot be written stops the run
            if options.reset_fault:
                before += _reset_faults_first(rig.addresses, options, extra)
            drive, gate, serve = rig.open(stack, writer.tap)
            drives = (OneAxis(drive) if isinstance(drive, Drive) else drive).drives
            names = [axis.name for axis in drives]
            extra["scaling"] = kind.scaling(drives)  # in run.json from here, a run refused at pre-flight too
            kind.describe_gate(gate, extra)
            scene = kind.scene(gate)
            for each in getattr(drive, "drives", (drive,)):  # a drive in FAULT: said now, not after pre-flight
                each.refuse_fault()
            derate = kind.derate(gate, scene)  # before the control thread's real-time session (a worker may build it)
            if derate is not None:
                stack.callback(derate.abandon)  # the run's end waits for no entry still being built

            def ready() -> tuple[WallController[Any, Any], ControllerNode | None]:
                """Safe start, the controller, its records streamed, the upload server: all but enabling."""
                nonlocal controller
                origin, ramp_time = _safe_start(kind, drive, gate, scene, options)
                extra["start"] = kind.start_extra(origin, ramp_time)
                clock = RealClock(period, spin=options.scheduling.spin) if options.wall_paced else VirtualClock(period)
                controller = kind.controller(drive, gate, scene, clock=clock, origin=origin, ramp_time=ramp_time,
                                             hold=rig.hold, derate=derate)
                extra["passivity"] = kind.passivity_extra(controller, gate)
                for event in before:
                    controller.events.add(event.time_s, event.kind, event.message, **event.data)
                journal.controller = controller
                recorder.stream(writer, kind.records(controller), controller.events, kind.scene_dicts(controller),
                                period, f"haptic-bus run {kind.profile.name}" if options.live else None,
                                options.duration)
                return controller, serve(controller)

            with control_thread_scheduling(options) as scheduling:
                extra["realtime"] = scheduling.to_dict() if scheduling is not None else None
                running, node = ready()  # before pre-flight, which then measures the cycle after it
                show_names()  # every thread by its name in top -H and /proc/PID/task/*/comm, through pre-flight too
                for each in drives:
                    each.select_mode()  # its SDO round trips now, not between pre-flight and the enable
                if options.wall_paced:
                    _preflight(kind, rig, drive, gate, scene, options, extra)
                    recorder.publish()  # run.json as it stands before the cycles (pre-flight's verdict in it)
                    if running.ramp_cycles == 0:
                        _still_outside(kind, drive, scene)
                show_names()  # again: threads started since (a judge names itself)
                _stop_if_asked(options)  # Ctrl-C or SIGTERM during set-up or pre-flight: never enabled
                # last before the first cycle: every drive in the same cycle, their RPDO deadlines run from here
                drive.enable()
                with node.cycling() if node is not None else nullcontext():  # its verdicts answered by the cycle
                    summary = running.run(max(1, round(options.duration / period)), options.stop.event,
                                          on_cycle=node.poll if node is not None else None)
                # still in the control thread's real-time session: undoing it (SCHED_FIFO, mlockall, the frozen
                # gc) took 11 ms idle, and 75 ms beside CPU-bound work outlasted gantry-3d's 60 ms RPDO deadline
                # while the drives still held their last torque: every drive of a completed run in FAULT
                if summary.exit_reason in ("completed", "stopped", "interrupted"):
                    drive.disable()
                if summary.exit_reason in ("completed", "stopped"):
                    _refuse_faulted_at_the_end(drives)
            options.stop.said(summary)  # run.json's summary says it as its status does
            reason, error = summary.exit_reason, summary.error
            if reason == "drive error" and error is not None:  # a drive that faulted in the cycles: was it a stall of ours?
                error = summary.error = error + _stall_before(controller, rig.watchdog.stall, _answers_wait(rig))
    except Refusal as exc:  # refused before the drive is enabled
        reason, error = "refused", str(exc)
    except DriveError as exc:
        reason, error = "drive error", str(exc) + _stall_before(controller, rig.watchdog.stall, _answers_wait(rig))
        hint = rig.fault_hint(names.index(exc.node) if exc.node in names else None)
        if isinstance(exc, DriveFault) and exc.state is State.FAULT and hint is not None:
            error += f"; {hint} (or run with --reset-fault)"
    except KeyboardInterrupt:
        reason, error = "interrupted", "interrupted (Ctrl-C)"
    except _StopBeforeEnabling:
        reason, error = "stopped", None
    except BaseException as exc:  # anything else (a bug, a judge worker that could not start): not "completed"
        reason, error = "crashed", f"{type(exc).__name__}: {exc}"
        raise
    finally:
        reason, error = _write_failure(reason, error, recorder, summary, period)
        extra["exit_reason"], extra["error"] = reason, error
        extra["drive_counts"] = {each.name: dataclasses.asdict(each.stats) for each in drives if isinstance(each, Cia402Master)}
        # a run asked to stop (Ctrl-C, SIGTERM) before its first cycle ends now: no pictures of a run that
        # never moved (region.png alone took 3-8 s on a loaded machine); haptic-bus plot draws them later
        asked_to_stop = summary is None and reason in ("interrupted", "stopped")
        files = recorder.finish(summary, pictures=options.plots and not asked_to_stop)
        lock.release()
        options.stop.spent()  # a stop that ended this run does not end the next run given these options
    reason, error = _write_failure(reason, error, recorder, summary, period)  # run.json itself, at the end
    return RunResult(reason, error, summary, controller, folder, files, extra.get("preflight_stopped", {}).get("cycles"))


STALL_LOOKBACK = 3  # cycles: the stalled one, and the exchanges of the cycles after it that found the drive faulted


def _answers_wait(rig: Rig) -> bool:
    """Whether a cycle of ``rig``'s link can wait for an answer as long as the drive's watchdog allows: a
    Modbus request waits for its answer up to its timeout, beyond the 60 ms watchdog; a CANopen cycle waits
    for the TPDOs at most half the shortest stall that faults a drive (``longest_tpdo_wait``)."""
    return rig.link.get("kind") == "modbus"


def _stall_before(controller: WallController[Any, Any] | None, stall: float, answers_wait: bool = False) -> str:
    """What the one line of a drive error adds when one of the last cycles started ``stall`` s late or more
    (the shortest stall that faults the drive), or the cycle that met the error had run that long (a stop in
    the middle of its exchange): this process did not run (a SIGSTOP, a debugger, starved of CPU), and the
    drive's watchdog did what it is for; "" otherwise, and for a virtual-time run.  ``answers_wait`` (Modbus):
    the cycle may as well have waited that long for an answer (a server stopped with SIGSTOP held a cycle
    402 ms, and the line blamed this process alone), so the line names both."""
    clock = controller.clock if controller is not None else None
    if controller is None or not isinstance(clock, RealClock):
        return ""
    late = clock.lateness(STALL_LOOKBACK)
    held = max(float(late.max()) if late.size else 0.0, controller.error_cycle_s)
    if held < stall:
        return ""
    either = ", or it waited that long for a drive's answer (a drive or server that stalled)" if answers_wait else ""
    return (f" (a cycle just before was held {held * 1e3:.4g} ms late, past the {stall * 1e3:.4g} ms the drive's "
            f"watchdog allows: this process did not run for that long, stopped or starved of CPU{either})")


def _write_failure(reason: str, error: str | None, recorder: RunRecorder, summary: RunSummary | None,
                   period: float) -> tuple[str, str | None]:
    """A run that stopped, or completed, while its folder could not be written (a full disk, the
    folder deleted: :attr:`RunRecorder.failure`) ends "write error" (exit 1): the failure, when the
    run stopped (cycles and s of ``T = period``), and what was kept; any other end stays as it is."""
    failure = recorder.failure
    if failure is None or reason not in ("completed", "stopped"):
        return reason, error
    when = "before its first cycle, nothing enabled" if summary is None else \
        f"after {summary.cycles} cycles ({summary.cycles * period:.3f} s), every drive disabled"
    error = f"{failure}; the run stopped {when}; the folder keeps what was written before"
    if summary is not None:
        summary.exit_reason, summary.error = "write error", error
    return "write error", error


class _StopBeforeEnabling(BaseException):  # control flow, not an error: no caller ever sees it
    """SIGTERM asked the run to stop before its drives were enabled: it ends "stopped", nothing enabled."""


def _stop_if_asked(options: RunOptions) -> None:
    """End a run not yet enabled that SIGTERM (:class:`_StopBeforeEnabling`) or Ctrl-C asked to stop."""
    if options.stop.event.is_set():
        raise KeyboardInterrupt if options.stop.interrupted else _StopBeforeEnabling


def _preflight(kind: RunKind[Any, Any, Any], rig: Rig, drive: Any, gate: Any, scene: Any, options: RunOptions,
               extra: dict[str, Any]) -> None:
    """Measure this machine's lateness on this bus with the drive(s) not enabled, print it and record
    it in ``extra``, and refuse (:class:`Refusal`) a run the drives' watchdogs, or the gate
    without a layer, cannot hold.  A stop (SIGTERM, Ctrl-C) ends it, the cycles measured by then
    recorded (``extra["preflight_stopped"]``: ``{"cycles": N}``; no ``preflight``, no verdict taken)."""
    zeros = kind.zero_targets
    measured = 0
    with drive.cyclic() as cycle:  # the run's own path, every target zero

        def exchange() -> object:
            # a stop asked during pre-flight ends it at this cycle's start: during the measurement (up to 8000
            # cycles), or while the gate judges (the run stops now, not once it has judged)
            _stop_if_asked(options)
            return cycle.read(), cycle.saturate_and_write(zeros)

        def measured_exchange() -> object:
            nonlocal measured
            done = exchange()
            measured += 1
            return done

        def exchange_while_judged() -> object:
            try:
                return exchange()
            except DriveTimeout as silent:
                raise DriveTimeout(silent.node, f"{silent.message}, while pre-flight's verdict was judged after its "
                                                "cycles (nothing enabled)") from silent

        spin = options.scheduling.spin
        cycles = preflight.PREFLIGHT_CYCLES if options.preflight_cycles is None else options.preflight_cycles
        try:
            timing = preflight.measure(measured_exchange, kind.period, preflight.looks_for(cycles), spin=spin)
            _stop_if_asked(options)  # asked after the last cycle measured: the run stops, whatever its verdict would be
            report = preflight.while_cycling(exchange_while_judged, kind.period, spin=spin, work=lambda: (
                preflight.judge_delay(timing, kind.assumed_delay(gate), kind.passes_at(gate, scene),
                                      kind.profile.passivity.layer, rig.watchdog.stall, rig.watchdog.periods,
                                      rig.link.get("bus_load", {}).get("smallest_period", 0.0), kind.on_arrival,
                                      rig.watchdog.at)))
        except (KeyboardInterrupt, _StopBeforeEnabling):
            extra["preflight_stopped"] = {"cycles": measured}
            raise
    preflight.settle(preflight.without_realtime(report, extra.get("realtime")), options.live, extra)


def _safe_start(kind: RunKind[Any, Any, Any], drive: Any, gate: Any, scene: Any, options: RunOptions) -> tuple[Any, float]:
    """The handle's position before enabling (m; one per joint for several axes), and the start
    ramp's time (s, 0 = none).

    Inside an object: :class:`Refusal` under "refuse"; under "ramp" the ramp time, once the
    gate has proven every wall scaled by a factor in [0, 1] passive (along each contact normal).
    """
    origin = kind.origin(drive)
    where = kind.inside(scene, origin)
    if where is None:
        return origin, 0.0
    policy = options.start_in_contact or kind.start.in_contact
    if policy != "ramp":
        raise Refusal(f"{where}; move it out or use --start-in-contact ramp")
    proof = gate.proves_ramp(scene)
    if not proof.proven:
        raise Refusal(f"{where}; and the start ramp is refused: {proof.reason}")
    if kind.profile.passivity.layer == "off" and kind.profile.supervisor.on_observer != "stop":
        # the gate proves each scaled wall; the rising scale is held by energy: the layer, or the observer's stop
        raise Refusal(f"{where}; and the start ramp is refused with [passivity] layer = \"off\" and [supervisor] "
                      f"on_observer = \"{kind.profile.supervisor.on_observer}\": a wall whose force rises under the "
                      "handle is time-varying, which the gate's verdict on each scaled wall does not cover; the "
                      "passivity layer, or the observer stopping the run, bounds the energy it can give")
    logger.info("%s: ramping the force in over %g s", where, kind.start.ramp_time)
    return origin, kind.start.ramp_time


def _still_outside(kind: RunKind[Any, Any, Any], drive: Any, scene: Any) -> None:
    """The start judged outside every object before pre-flight, judged again right before enabling
    (:class:`Refusal`, nothing enabled, if the handle is inside one now): an operator pushing the
    unpowered handle, or a hand moving it, during pre-flight's cycles would otherwise have it
    enabled deep inside a wall, the passivity layer lowering every target from its first."""
    where = kind.inside(scene, kind.origin(drive, sampled=True))  # pre-flight's last sample, no SDO: the enable is due
    if where is not None:
        raise Refusal(f"{where}: it moved there during pre-flight, after the start was judged outside every object; "
                      "move it out or use --start-in-contact ramp")


def _reset_faults_first(addresses: Sequence[DriveAddress], options: RunOptions, extra: dict[str, Any]) -> list[Event]:
    """``--reset-fault``: reset every drive found in FAULT before commissioning, one per axis in axis
    order (:attr:`Rig.addresses <haptic_bus.app.run_links.Rig.addresses>`); each reset an event
    (run.json's ``events``, also when the run ends before it cycles); a drive not in FAULT none.
    DriveFault (nothing enabled) at the first drive whose cause persists."""
    events: list[Event] = []
    for address in addresses:
        outcome = address.reset_fault(DEFAULT_WAIT, DEFAULT_ANSWER_TIMEOUT)
        if not outcome.reset_sent and outcome.cleared:
            logger.info("%s", outcome.message())
            continue
        events.append(Event(0.0, "fault reset", f"before commissioning: {outcome.message()}", outcome.to_dict()))
        extra["events"] = [event.to_dict() for event in events]
        if not outcome.cleared:
            raise DriveFault(outcome.drive, f"--reset-fault: {outcome.detail()}", outcome.error_code_after)
        if options.live:
            print(f"fault reset: {outcome.message()}", flush=True)
    return events


@contextmanager
def control_thread_scheduling(options: RunOptions) -> Iterator[RealtimeReport | None]:
    """A wall-paced run's control thread set up for the cycles (entered last: helper threads keep theirs)."""
    if not options.wall_paced:
        yield None
        return
    with realtime_session(options.scheduling) as report:
        yield report
