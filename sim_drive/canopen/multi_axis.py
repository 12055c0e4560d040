"""A simulated multi-axis device: one simulated drive per axis, each a real CANopen slave on one bus.

Every axis is a :class:`~sim_drive.canopen.slave.CanopenSimDrive` (its own node id, its own
handle on a lock-step channel that :class:`~sim_drive.canopen.bridge.BusBridge` joins to the bus
through the process's one bus handle, its own exact plant with its hidden truth, its own safety chain:
heartbeat consumer, RPDO deadline, 0x6007); the axes of a Cartesian device are independent
plants, and what couples them is the hand (:mod:`sim_drive.space_operator`), whose force in
space each axis takes its component of.  A master sees as many CiA-402 drives on the bus as
there are axes: ``haptic-bus scan`` lists them, ``haptic-bus identify --node-id N`` drives one
while the others stay where they are.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from sim_drive.canopen.bridge import BusBridge
from sim_drive.canopen.slave import CanopenSimDrive
from sim_drive.parameters import DeviceParameters, Timing
from sim_drive.parts import Part, start_all, stop_all
from sim_drive.space_operator import SpaceHand
from sim_drive.sync_clock import sync_clock

AxisSetup = tuple[int, DeviceParameters, Timing | str]  # node id, plant and scaling, timing


class MultiAxisSim:
    """The axes ``axes`` (node id, parameters, timing; in coordinate order) on the bus ``bus`` (the
    keyword arguments of ``can.Bus``, opened once for all nodes), pushed by ``hand`` (None:
    nobody).  ``coordinates``: the hand's coordinate of each axis simulated here (default: all of
    them, in order; a hand over more axes than this process simulates sees the others at 0 m).
    ``clock``: "virtual" or "wall" (:mod:`sim_drive.sync_clock`, one clock per node); ``od``: the
    dictionary kind of every node."""

    def __init__(self, bus: Mapping[str, Any], axes: Sequence[AxisSetup], hand: SpaceHand | None = None, *,
                 coordinates: Sequence[int] | None = None, clock: str = "virtual", od: str = "haptic") -> None:
        hand = hand if hand is not None else SpaceHand(len(axes))
        places = list(coordinates) if coordinates is not None else list(range(len(axes)))
        self.hand = hand
        self._bridge = None if bus.get("interface") == "lockstep" else BusBridge(bus, self._lose_bus)
        node_bus = dict(bus) if self._bridge is None else self._bridge.node_bus
        self.nodes = tuple(CanopenSimDrive(dict(node_bus), node, timing=timing, parameters=parameters,
                                           operator=hand.axis(place), od=od, sync_clock=sync_clock(clock))
                           for (node, parameters, timing), place in zip(axes, places, strict=True))
        hand.bind_places(places, [node.drive for node in self.nodes])
        self._parts: list[Part] = [*([] if self._bridge is None else [self._bridge]), *self.nodes]  # the bus first

    def node(self, node_id: int) -> CanopenSimDrive:
        """The simulated drive with ``node_id``."""
        return next(node for node in self.nodes if node.node_id == node_id)

    @property
    def positions(self) -> tuple[float, ...]:
        """Every simulated axis' true handle position (m), in axis order."""
        return tuple(node.drive.handle.position for node in self.nodes)

    def start(self) -> MultiAxisSim:
        """Open the bus once (:class:`~sim_drive.canopen.bridge.BusBridge`), boot every node (boot-up
        message, PRE-OPERATIONAL) and serve."""
        start_all(self._parts)
        return self

    def stop(self) -> None:
        """Stop every node (their heartbeats stop with them), then close the bus."""
        stop_all(self._parts)

    def _lose_bus(self, exc: BaseException) -> None:
        for node in self.nodes:
            node.lose_bus(exc)

    def __enter__(self) -> MultiAxisSim:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
