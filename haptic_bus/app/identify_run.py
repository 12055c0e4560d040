"""``haptic-bus identify``'s run: open the drive as ``run`` does, probe, excite, always disable, then fit.

One run, in order:

1. the plan is checked against the profile (travel against the encoder's resolution, duration)
   before any bus is touched;
2. the drive is reached and commissioned with the profile's scaling and ``[safety]`` settings
   (CANopen: heartbeat, 0x6007 and the RPDO deadline, so the drive stops on its own if this
   process dies; Modbus: its watchdog register), with 0x6064 in the cyclic data, then enabled
   in cyclic synchronous torque;
3. :class:`~haptic_bus.identify.session.Session` runs cycle by cycle (real time, or lock-step in
   virtual time against a simulated drive): the probe (a handle that is not free to move ends
   the run here, :attr:`IdentifyOutcome.exit_reason` "refused"), the excitation, the settling;
4. whatever ends it (done, a refusal, a drive error, SIGTERM, Ctrl-C), the drive is disabled
   and closed; then the record is fitted (:func:`haptic_bus.identify.identify`).

:func:`run_cycles` is the cycle loop alone, over anything with the :class:`~drives.base.Drive`
cyclic phase (``cyclic``/``scaling``): each force's torque saturated there, once, at the plan's
force limit (counted in the record), and recorded as sent.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
from collections.abc import Callable, Mapping
from contextlib import AbstractContextManager, ExitStack
from typing import Any, Protocol

from drives.base import Drive, DriveCycle, DriveScaling
from drives.bus_config import resolve_bus_config
from drives.safety import VIRTUAL_TIME_CANOPEN_PATIENCE, VIRTUAL_TIME_MODBUS_PATIENCE, patient
from haptic_bus.app.profiles import Profile
from haptic_bus.app.run_options import EXIT_STATUS, WALL, StopRequest, check_pacing
from haptic_bus.control.clock import RealClock, VirtualClock
from haptic_bus.errors import DriveError, DriveProtocolError
from haptic_bus.identify import Identification, Plan, Record, Recorder, Scale, Session, identify
from haptic_bus.identify.bounds import DEFAULT_DURATION, DEFAULT_TRAVEL, MAX_DELAY

logger = logging.getLogger(__name__)



PERIOD_TOLERANCE = 0.25  # of T: a period longer than this is a stall the fit leaves out


class CycleDrive(Protocol):
    """What the cycle loop needs of a drive (a :class:`~drives.base.Drive` has it)."""

    scaling: DriveScaling

    def cyclic(self, torque_limit: int | None = None) -> AbstractContextManager[DriveCycle]:
        """The cyclic phase, targets saturated at ``torque_limit`` (per mille; None: the drive's own)."""


class Clock(Protocol):
    """A cycle clock (:mod:`haptic_bus.control.clock`)."""

    def wait_next(self, cycle: int) -> float:
        """Block until cycle ``cycle`` is due; how late it started, s."""

    def period_bound(self, sampled_by_ns: int) -> float:
        """How long (s, at most) the period the latest sample closed lasted."""


@dataclasses.dataclass(frozen=True)
class IdentifyOptions:
    """One identification: ``duration`` s of excitation, ``travel`` m either side of the start,
    its ``pacing`` ("wall" or "virtual", as :class:`~haptic_bus.app.runner.RunOptions`), the whole
    delays searched (``max_delay``), and the stop request."""

    duration: float = DEFAULT_DURATION
    travel: float = DEFAULT_TRAVEL
    pacing: str = WALL
    max_delay: int = MAX_DELAY
    stop: StopRequest = dataclasses.field(default_factory=StopRequest)

    def __post_init__(self) -> None:
        check_pacing(self.pacing)


@dataclasses.dataclass
class IdentifyOutcome:
    """How the run ended (``exit_reason`` as ``run``'s: completed, refused, drive error, stopped,
    interrupted), the ``error`` if any, the ``identification`` (None when nothing was recorded),
    and the ``link`` it used."""

    exit_reason: str
    error: str | None
    identification: Identification | None
    link: dict[str, Any]

    @property
    def exit_status(self) -> int:
        """0 when the data support the estimate; 1 refused, unsupported or a drive error; 130 interrupted."""
        status = EXIT_STATUS[self.exit_reason]
        if status == 0 and (self.identification is None or not self.identification.supported):
            return 1
        return status


def plan_for(profile: Profile, scaling: DriveScaling, options: IdentifyOptions) -> Plan:
    """The run's plan from the profile and the drive's ``scaling`` (ParameterError if they do not fit)."""
    force_limit = min(profile.force_limit, scaling.max_force)
    return Plan(profile.loop.period, force_limit, options.travel, options.duration, profile.device.mass,
                scaling.position_per_count)


def run_cycles(drive: CycleDrive, session: Session, recorder: Recorder, clock: Clock,
               stop: threading.Event | None = None) -> bool:
    """Cycle until the session is done (True) or ``stop`` is set (False); every cycle recorded.

    A cycle is recorded as not fresh, and the fit leaves out every equation that touches it, when
    its inputs repeat the last ones (a TPDO that missed its timeout: ``age`` > 0) or when the
    period its sample closes was longer than ``T`` by more than :data:`PERIOD_TOLERANCE` (a stall
    of the machine: a real handle moved under the held torque for that long, which the
    fixed-period model does not describe).  The torque recorded is the one sent, per mille: the
    drive's clamp holds it at the plan's force limit (such cycles counted in the record).
    """
    scaling = drive.scaling
    per_count = scaling.position_per_count
    longest = (1.0 + PERIOD_TOLERANCE) * session.plan.period
    cycle = 0
    with drive.cyclic(scaling.torque_limit(session.plan.force_limit)) as phase:
        while stop is None or not stop.is_set():
            clock.wait_next(cycle)
            inputs = phase.read()
            if inputs.position is None:
                raise DriveProtocolError(getattr(drive, "name", "drive"),
                                         "the cyclic inputs carry no position (0x6064): identification needs it")
            force = session.step(inputs.position * per_count)
            if session.done:
                return True
            target = scaling.torque_permille(force)
            torque = phase.saturate_and_write(target)
            recorder.append(inputs.position, inputs.velocity, torque,
                            not inputs.age and clock.period_bound(inputs.sampled_by_ns) <= longest, torque != target)
            cycle += 1
    return False


def identify_canopen(profile: Profile, bus: Mapping[str, Any], node_id: int, options: IdentifyOptions,
                     controller_node_id: int = 127) -> IdentifyOutcome:
    """Identify the handle on CANopen drive ``node_id`` on ``bus`` (python-can keyword arguments)."""
    from drives.canopen.drive import DEFAULT_TPDO_WITH_POSITION, CanopenDrive
    from haptic_bus.app.run_links import PROFILE_SCALING_SOURCE

    plan_for(profile, profile.scaling(), options)  # invalid input fails here, before the bus
    config = resolve_bus_config(**bus)
    extra = {k: v for k, v in config.items() if k not in ("interface", "channel", "bitrate")}
    period = profile.loop.period
    safety = dataclasses.replace(profile.safety, master_node_id=controller_node_id)
    link = {"kind": "canopen", "bus": {k: str(v) for k, v in config.items()}, "node_id": node_id}

    def open_drive() -> Drive:
        return CanopenDrive(node_id, interface=config["interface"], channel=config.get("channel"),
                            bitrate=config.get("bitrate"), bus_kwargs=extra, period=period, scaling=profile.scaling(),
                            scaling_source=PROFILE_SCALING_SOURCE,
                            tpdo_objects=DEFAULT_TPDO_WITH_POSITION,
                            safety=safety if options.pacing == WALL else safety.for_virtual_time(period),
                            **patient(options.pacing == WALL, VIRTUAL_TIME_CANOPEN_PATIENCE))

    return _identify(profile, options, link, open_drive)


def identify_modbus(profile: Profile, url: str, unit_id: int, options: IdentifyOptions) -> IdentifyOutcome:
    """Identify the handle on the Modbus drive at ``url`` (``tcp://HOST:PORT`` or ``rtu:/dev/...``)."""
    from drives.modbus.drive import ModbusDrive
    from haptic_bus.app.run_links import PROFILE_SCALING_SOURCE

    plan_for(profile, profile.scaling(), options)
    period = profile.loop.period
    safety = profile.safety if options.pacing == WALL else profile.safety.for_virtual_time(period)
    link: dict[str, Any] = {"kind": "modbus", "url": url, "unit_id": unit_id}

    def open_drive() -> Drive:
        return ModbusDrive.from_url(url, unit_id=unit_id, scaling=profile.scaling(), scaling_source=PROFILE_SCALING_SOURCE,
                                    safety=safety, with_position=True,
                                    **patient(options.pacing == WALL, VIRTUAL_TIME_MODBUS_PATIENCE))

    return _identify(profile, options, link, open_drive)


def _identify(profile: Profile, options: IdentifyOptions, link: dict[str, Any],
              open_drive: Callable[[], Drive]) -> IdentifyOutcome:
    reason, error = "completed", None
    record: Record | None = None
    session: Session | None = None
    with ExitStack() as stack:
        try:
            drive = open_drive()
            stack.callback(drive.close)
            drive.connect()
            link["safety_warnings"] = list(getattr(drive, "safety_warnings", ()))
            plan = plan_for(profile, drive.scaling, options)
            session = Session(plan)
            recorder = Recorder(plan.cycles)
            scaling = drive.scaling
            scale = Scale(scaling.position_per_count, scaling.velocity_per_count, scaling.newton_per_permille)
            stack.callback(lambda: _disable(drive))
            drive.enable()
            clock = RealClock(plan.period) if options.pacing == WALL else VirtualClock(plan.period)
            try:
                if not run_cycles(drive, session, recorder, clock, options.stop.event):
                    reason, error = ("interrupted", "interrupted (Ctrl-C)") if options.stop.interrupted else (
                        "stopped", "stopped (SIGTERM) before the run was done")
            finally:
                record = recorder.record(plan.period, scale, plan.force_limit, session.phases)
            if session.refused and session.probe is not None:
                reason, error = "refused", session.probe.message
        except DriveError as exc:
            reason, error = "drive error", str(exc)
        except KeyboardInterrupt:
            reason, error = "interrupted", "interrupted (Ctrl-C)"
    if record is None or session is None or session.probe is None or reason in ("interrupted", "stopped", "drive error"):
        return IdentifyOutcome(reason, error, None, link)
    found = identify(record, session.probe, session.left_envelope, profile.device.velocity, options.max_delay)
    return IdentifyOutcome(reason, error, found, link)


def _disable(drive: Drive) -> None:
    """Torque off and the drive disabled; a drive already gone has zeroed its torque itself."""
    try:
        drive.disable()
    except DriveError as exc:
        logger.info("could not disable the drive: %s", exc)
