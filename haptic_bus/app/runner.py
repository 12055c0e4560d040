"""``haptic-bus run``: a profile's controller against a drive on a CAN bus or over Modbus.

The drive may be the simulated one in another process (``udp_multicast``, ``vcan0``, Modbus
TCP on loopback) or real hardware (``can0``, a Modbus TCP/RTU drive).  On CANopen the
controller also serves its wall parameters as a CANopen node
(:mod:`haptic_bus.control.node`) so that ``haptic-bus upload`` can change them, gated,
while it runs.  Over Modbus the gate judges the profile with the loop delay the poll
actually has (:func:`drives.modbus.timing.loop_delay`), not the profile's CiA-402 timing.
SIGINT/SIGTERM end the run cleanly: torque zero, drive disabled, record kept.
"""

from __future__ import annotations

import dataclasses
import logging
import pathlib
import signal
import threading
from contextlib import ExitStack
from typing import Any, Mapping

from drives.base import Drive
from drives.bus_config import resolve_bus_config
from drives.canopen.drive import CanopenDrive
from haptic_bus.app.profiles import Profile
from haptic_bus.control.clock import RealClock, VirtualClock
from haptic_bus.control.controller import RunSummary, WallController, encoder_origin
from haptic_bus.control.gate import PassivityGate
from haptic_bus.control.node import ControllerNode

logger = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class RunOptions:
    """How long (s), which clock, where the record goes, and the stop flag of one run."""

    duration: float
    realtime: bool
    out_dir: pathlib.Path | None = None
    stop: threading.Event = dataclasses.field(default_factory=threading.Event)


DEFAULT_CONTROLLER_NODE_ID = 127


def run_canopen(profile: Profile, bus: Mapping[str, Any], node_id: int, options: RunOptions,
                controller_node_id: int = DEFAULT_CONTROLLER_NODE_ID) -> tuple[RunSummary, WallController]:
    """Run against CANopen drive ``node_id`` on ``bus`` (python-can keyword arguments).

    The controller is CANopen node ``controller_node_id``: its heartbeat (the profile's
    ``[safety]``) is what the drive watches, and it serves gated wall uploads over SDO.
    """
    config = resolve_bus_config(**bus)  # python-can's config chain fills what ``bus`` leaves out
    extra = {k: v for k, v in config.items() if k not in ("interface", "channel", "bitrate")}
    period = profile.loop.period
    safety = dataclasses.replace(profile.safety, master_node_id=controller_node_id)
    drive = CanopenDrive(node_id, interface=config["interface"], channel=config.get("channel"),
                         bitrate=config.get("bitrate"), bus_kwargs=extra, period=period,
                         scaling=profile.scaling(), safety=safety if options.realtime else safety.for_virtual_time(period))
    with ExitStack() as stack:
        drive.connect()
        stack.callback(drive.close)

        def serve(controller: WallController) -> None:
            stack.enter_context(ControllerNode(controller, controller_node_id, config, safety.heartbeat_ms))

        return _run(profile, drive, profile.gate(), options, serve)


def run_modbus(profile: Profile, url: str, unit_id: int, options: RunOptions) -> tuple[RunSummary, WallController]:
    """Run against the Modbus drive at ``url`` (``tcp://HOST:PORT`` or ``rtu:/dev/...``)."""
    from drives.modbus.drive import ModbusDrive
    from drives.modbus.timing import loop_delay, measure_poll

    safety = profile.safety if options.realtime else profile.safety.for_virtual_time(profile.loop.period)
    drive = ModbusDrive.from_url(url, unit_id=unit_id, scaling=profile.scaling(), safety=safety)
    with ExitStack() as stack:
        drive.connect()
        stack.callback(drive.close)
        poll = None if drive.simulated_timing is not None else measure_poll(drive, 500)
        delay = loop_delay(drive, profile.loop.period, poll)
        logger.info("Modbus poll: the gate assumes a loop delay of %d sample(s)", delay)
        device = dataclasses.replace(profile.device_loop(), delay=delay)
        return _run(profile, drive, PassivityGate(device, profile.gate_policy), options, None)


def _run(profile: Profile, drive: Drive, gate: PassivityGate, options: RunOptions, serve) -> tuple[RunSummary, WallController]:
    drive.enable()
    period = profile.loop.period
    clock = RealClock(period) if options.realtime else VirtualClock(period)
    origin = encoder_origin(drive)
    controller = WallController(drive, gate, profile.compiled_scene(), force_limit=profile.force_limit,
                                clock=clock, origin=origin)
    if serve is not None:
        serve(controller)
    summary = controller.run(max(1, round(options.duration / period)), options.stop)
    if summary.error is None:
        drive.disable()
    if options.out_dir is not None:
        controller.record.write_csv(pathlib.Path(options.out_dir) / "record.csv")
    return summary, controller


def install_stop_signals(stop: threading.Event) -> None:
    """SIGINT and SIGTERM set ``stop`` (the loop ends at the next cycle boundary)."""
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
