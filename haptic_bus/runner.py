"""``haptic-bus run``: a profile's controller against a drive on any python-can bus.

The drive may be the simulated one in another process (``udp_multicast``, ``vcan0``) or real
hardware (``can0``).  The controller also serves its wall parameters as a CANopen node
(:mod:`haptic_bus.controller_node`) so that ``haptic-bus upload`` can change them, gated,
while it runs.  SIGINT/SIGTERM end the run cleanly: torque zero, drive disabled, record kept.
"""

from __future__ import annotations

import logging
import pathlib
import signal
import threading
from contextlib import ExitStack
from typing import Any, Mapping

from drives.bus_config import resolve_bus_config
from drives.canopen_drive import CanopenDrive
from haptic_bus.clock import RealClock, VirtualClock
from haptic_bus.controller import RunSummary, WallController
from haptic_bus.controller_node import ControllerNode
from haptic_bus.profiles import Profile
from haptic_bus.session import encoder_origin

logger = logging.getLogger(__name__)


def run_profile(
    profile: Profile,
    bus: Mapping[str, Any],
    node_id: int,
    *,
    duration: float,
    realtime: bool,
    controller_node_id: int | None = None,
    out_dir: pathlib.Path | None = None,
    stop: threading.Event | None = None,
) -> tuple[RunSummary, WallController]:
    """Connect to drive ``node_id`` on ``bus`` (python-can keyword arguments), run ``duration`` s."""
    stop = stop or threading.Event()
    period = profile.loop.period
    config = resolve_bus_config(**bus)  # python-can's config chain fills what ``bus`` leaves out
    extra = {k: v for k, v in config.items() if k not in ("interface", "channel", "bitrate")}
    drive = CanopenDrive(node_id, interface=config["interface"], channel=config.get("channel"),
                         bitrate=config.get("bitrate"), bus_kwargs=extra, period=period, scaling=profile.scaling())
    with ExitStack() as stack:
        drive.connect()
        stack.callback(drive.close)
        drive.enable()
        clock = RealClock(period) if realtime else VirtualClock(period)
        controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit,
                                    clock=clock, origin=encoder_origin(drive))
        if controller_node_id is not None:
            node = stack.enter_context(ControllerNode(controller, controller_node_id, config))
            logger.info("controller node %d serves wall uploads", node.node_id)
        summary = controller.run(max(1, round(duration / period)), stop)
        if summary.error is None:
            drive.disable()
    if out_dir is not None:
        controller.record.write_csv(pathlib.Path(out_dir) / "record.csv")
    return summary, controller


def install_stop_signals(stop: threading.Event) -> None:
    """SIGINT and SIGTERM set ``stop`` (the loop ends at the next cycle boundary)."""
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
