"""A simulated multi-axis device over Modbus TCP: one simulated drive per axis, each a Modbus unit.

The Modbus twin of :mod:`sim_drive.canopen.multi_axis`: every axis is a
:class:`~sim_drive.device.SimulatedDrive` with its own exact plant, hidden truth, state machine and
watchdogs, served as a unit of a :class:`~sim_drive.modbus.server.ModbusSimServer` -- all axes as
units of one server (one address), or each axis on a server of its own (one address per axis).
The axes of a Cartesian device are independent plants; what couples them is the hand
(:mod:`sim_drive.space_operator`), which pushes only once every axis is enabled.  Modbus has no
SYNC: a unit's plant advances by one period when its output block is written, so in one poll of
every axis the hand's force of that period is computed by the first axis written, every axis
then still at the period's start (:class:`~sim_drive.space_operator.SpaceHand`).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Sequence

from haptic_bus.validation import one_or_one_each
from sim_drive.device import SimulatedDrive
from sim_drive.modbus.server import ModbusSimServer, ServedUnit
from sim_drive.parameters import DeviceParameters, Timing
from sim_drive.parts import start_all, stop_all
from sim_drive.space_operator import SpaceHand
from sim_drive.sync_clock import sync_clock

AxisSetup = tuple[int, DeviceParameters, Timing | str]  # unit id, plant and scaling, timing


class MultiAxisModbusSim:
    """The axes ``axes`` (unit id, parameters, timing; in coordinate order) served over Modbus TCP at
    ``addresses`` ((host, port); port 0 picks a free one): one address for every axis (one server,
    several units), or one per axis (a server each).  ``hand`` pushes them (None: nobody);
    ``coordinates``, ``clock`` as :class:`sim_drive.canopen.multi_axis.MultiAxisSim` takes them;
    ``word_order`` of every server.  ``servers``: the servers; ``units``: every axis' served unit (its
    simulated drive and register bank), in axis order."""

    def __init__(self, addresses: Sequence[tuple[str, int]], axes: Sequence[AxisSetup], hand: SpaceHand | None = None,
                 *, coordinates: Sequence[int] | None = None, clock: str = "virtual", word_order: str = "big") -> None:
        one_or_one_each("addresses", addresses, len(axes), "axis")
        hand = hand if hand is not None else SpaceHand(len(axes))
        places = list(coordinates) if coordinates is not None else list(range(len(axes)))
        self.hand = hand
        self.servers: list[ModbusSimServer] = []
        self._server_of: list[ModbusSimServer] = []
        for i, ((unit, parameters, timing), place) in enumerate(zip(axes, places, strict=True)):
            operator, clock_of = hand.axis(place), sync_clock(clock)
            if i == 0 or len(addresses) > 1:
                host, port = addresses[i]
                server = ModbusSimServer(host, port, unit_id=unit, timing=timing, parameters=parameters,
                                         operator=operator, word_order=word_order, sync_clock=clock_of)
                self.servers.append(server)
            else:
                server = self.servers[0]
                server.add_unit(unit, timing, parameters, operator, clock_of)
            self._server_of.append(server)
        self.units: tuple[ServedUnit, ...] = tuple(server.units[unit] for server, (unit, _, _) in zip(self._server_of, axes))
        hand.bind_places(places, self.drives)

    @property
    def unit_ids(self) -> tuple[int, ...]:
        """Every axis' unit id, in axis order."""
        return tuple(unit.unit_id for unit in self.units)

    @property
    def drives(self) -> tuple[SimulatedDrive, ...]:
        """Every axis' simulated drive, in axis order."""
        return tuple(unit.drive for unit in self.units)

    @property
    def urls(self) -> tuple[str, ...]:
        """Every axis' server address, ``tcp://HOST:PORT`` (once bound)."""
        return tuple(server.url for server in self._server_of)

    @property
    def positions(self) -> tuple[float, ...]:
        """Every simulated axis' true handle position (m), in axis order."""
        return tuple(drive.handle.position for drive in self.drives)

    def start(self) -> MultiAxisModbusSim:
        """Serve every server in a thread of its own (each bound when this returns)."""
        start_all(self.servers)
        return self

    def stop(self) -> None:
        """Stop every server's thread."""
        stop_all(self.servers)

    async def serve(self, stop: asyncio.Event, on_bound: Callable[[], None]) -> None:
        """Serve every server in the running event loop until ``stop`` is set; ``on_bound`` once all are bound."""
        unbound = len(self.servers)

        def one_bound() -> None:
            nonlocal unbound
            unbound -= 1
            if not unbound:
                on_bound()

        await asyncio.gather(*(server.serve(stop, on_bound=one_bound) for server in self.servers))

    def __enter__(self) -> MultiAxisModbusSim:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
