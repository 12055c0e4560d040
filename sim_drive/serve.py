"""``haptic-bus sim`` serving: the simulated drive(s) a parsed command line describes, until SIGINT/SIGTERM.

CANopen: one slave (:class:`~sim_drive.canopen.slave.CanopenSimDrive`) or one per node of a multi-axis
device (:class:`~sim_drive.canopen.multi_axis.MultiAxisSim`), the main thread waiting for a stop
signal.  Modbus: one TCP server, or the units of a multi-axis device on one server or a server per
axis, in an asyncio loop that a stop signal ends.  A refusal of the arguments or the profile is one
line on stderr and exit 2, before the bus or the socket is opened; a bus or socket that fails, or a CANopen
node id another node already sends with (heard before the boot-up, :func:`node_heard`), exit 1.
"""

from __future__ import annotations

import argparse
import asyncio
import datetime as dt
import logging
import os
import signal
import socket
import sys
import time
from collections.abc import Awaitable, Callable, Mapping, Sequence
from typing import Any

from drives.os_threads import show_names
from haptic_bus.analysis.can_timing import checked_bitrate
from haptic_bus.console import log_to_stderr
from haptic_bus.errors import DriveError, ParameterError
from sim_drive.eds import eds_path
from sim_drive.scheduling import answer_in_real_time
from sim_drive.setups import axes_setup, bus_config, drive_setup, modbus_axes_setup, node_id, profile_axes, unit_id
from sim_drive.sync_clock import sync_clock

logger = logging.getLogger("sim_drive")

PROG = "haptic-bus sim"
NODE_LISTEN_S = 0.25  # s: how long the simulator listens for a node of its id before its boot-up: 2.5 periods of a
# simulated drive's heartbeat (0x1017 = 100 ms), whose next one comes within a period; a master cycling it is heard at once
NMT_RESETS = (0x81, 0x82)  # NMT reset node, reset communication: the node boots up again
SENT_BY_A_NODE = (0x080, 0x180, 0x280, 0x380, 0x480, 0x580, 0x700)  # EMCY, TPDO1-4, SDO answer, heartbeat: + node id


class StopSignals:
    """Records SIGINT/SIGTERM from ``__enter__`` to ``__exit__``; :meth:`wait` blocks for the first.

    The handler only appends to a list (a handler that took a lock could deadlock on one the
    interrupted main thread holds), and Python's C-level handler writes a byte to the wake-up
    socket, so the blocking ``recv`` returns even for a signal that came just before it.
    Signal masks are no help: numpy's BLAS threads, started at import time, would take a
    masked signal with its default action.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __enter__(self) -> StopSignals:
        self.received: list[signal.Signals] = []
        self._reader, self._writer = socket.socketpair()
        self._writer.setblocking(False)
        self._previous_fd = signal.set_wakeup_fd(self._writer.fileno(), warn_on_full_buffer=False)
        self._previous = {sig: signal.signal(sig, self._record) for sig in self.SIGNALS}
        return self

    def _record(self, number: int, frame: object) -> None:
        self.received.append(signal.Signals(number))

    def wait(self) -> signal.Signals:
        """The first stop signal received (blocks until there is one)."""
        while not self.received:
            self._reader.recv(64)
        return self.received[0]

    def __exit__(self, *exc: object) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        signal.set_wakeup_fd(self._previous_fd)
        self._reader.close()
        self._writer.close()


def set_up_process(wall_clock: bool, library: str, level: int) -> str:
    """Log lines on stderr (stamped with the wall clock with ``wall_clock``; the bus ``library`` only
    from ``level``), then real-time scheduling for every thread to come (:mod:`sim_drive.scheduling`):
    what it got, in words for the serving line (a refusal before it logs nothing)."""
    fmt = "%(asctime)s %(message)s" if wall_clock else "%(message)s"
    log_to_stderr(logging.INFO, fmt)
    logging.getLogger(library).setLevel(level)
    return answer_in_real_time()


def utc_now() -> str:
    """Now as ISO 8601 UTC to the millisecond (``2026-12-07T21:04:05.123Z``): when a server started, in
    its serving line (it was a raw Unix time, ``started 1796674766.908``)."""
    return dt.datetime.now(dt.UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


SIM_BUS_ALLOWED = ("--interface NAME --channel CHANNEL and --node-id N (--node-ids for several axes), "
                   "or --modbus URL")


def missing_flag(args: argparse.Namespace, names: tuple[str, ...]) -> ParameterError | None:
    """The first of ``names`` not given, as every command says a missing flag (``--channel is missing;
    allowed: ...``, :class:`ParameterError`'s rule), or None when all are given."""
    for name in names:
        if getattr(args, name) is None:
            return ParameterError("--" + name.replace("_", "-"), None, SIM_BUS_ALLOWED)
    return None


def run_canopen(args: argparse.Namespace) -> int:
    """The CANopen slave until SIGINT/SIGTERM."""

    from sim_drive.bus_timing import BusLoadMeter
    from sim_drive.canopen.slave import CanopenSimDrive

    if args.eds_path:
        print(eds_path())
        return 0
    if args.node_ids is not None:
        return run_axes(args)
    missing = missing_flag(args, ("interface", "channel", "node_id"))
    if missing is not None:
        print(f"{PROG}: error: {missing}", file=sys.stderr)
        return 2
    scheduling = set_up_process(args.log_wall_clock, "canopen", logging.WARNING)
    try:
        node = node_id(args)
        parameters, operator, timing = drive_setup(args)
        meter = BusLoadMeter(args.bitrate, parameters.period) if args.bitrate else None
        config = bus_config(args)
        sim = CanopenSimDrive(config, node, timing=timing, parameters=parameters, operator=operator, bus_meter=meter,
                              od=args.od or "haptic", eds=args.eds, sync_clock=sync_clock(args.clock),
                              hand_needs_power=True)  # the hand takes a powered handle (sim_drive.device.SimulatedDrive)
    except ParameterError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    with StopSignals() as stop_signals:  # from before the boot-up: an early signal still stops cleanly
        if not started(sim, config, [args.node_id]):
            return 1
        try:
            dictionary = "standard objects only" if args.od == "standard" else f"EDS {args.eds or eds_path()}"
            if args.eds:
                log_eds_gaps(args.node_id, sim.object_dictionary)
            logger.info("node %d: serving on %s %s (timing %s); %s; %s",
                        args.node_id, args.interface, args.channel, timing, dictionary, scheduling)
            received = stop_signals.wait()
            logger.info("node %d: %s received, stopping", args.node_id, received.name)
        finally:
            sim.stop()
    drive = sim.drive
    logger.info("node %d: stopped after %d SYNCs, virtual time %.6f s, operator energy %.6g J, wall energy %.6g J",
                args.node_id, drive.sync_count, drive.time, drive.operator_energy, drive.wall_energy)
    if meter is not None and meter.cycle_bit_counts:
        logger.info("node %d: bus load %.1f %% at %d bit/s, worst cycle %.1f us",
                    args.node_id, 100 * meter.load(), args.bitrate, 1e6 * meter.worst_latency())
    return 0


def run_axes(args: argparse.Namespace) -> int:
    """The simulated multi-axis device (``--node-ids``) until SIGINT/SIGTERM: one CANopen slave per node."""

    from sim_drive.canopen.multi_axis import MultiAxisSim

    missing = missing_flag(args, ("interface", "channel"))
    if missing is not None:
        print(f"{PROG}: error: {missing}", file=sys.stderr)
        return 2
    try:  # the bus as one axis' (--bus-kwargs were dropped here: the slaves served python-can's default port)
        if args.bitrate is not None:
            checked_bitrate(args.bitrate)
        config = bus_config(args)
        axes, hand, coordinates = axes_setup(args)
        sim = MultiAxisSim(config, axes, hand, coordinates=coordinates, clock=args.clock, od=args.od or "haptic")
    except ParameterError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    scheduling = set_up_process(args.log_wall_clock, "canopen", logging.WARNING)  # once the arguments hold
    with StopSignals() as stop_signals:
        if not started(sim, config, [node.node_id for node in sim.nodes]):
            return 1
        try:
            logger.info("node%s %s: serving on %s %s (one simulated drive per axis, the hand: %s); %s",
                        "s" if len(sim.nodes) > 1 else "", ", ".join(str(node.node_id) for node in sim.nodes),
                        args.interface, args.channel, type(hand).__name__, scheduling)
            received = stop_signals.wait()
            logger.info("nodes: %s received, stopping", received.name)
        finally:
            sim.stop()
    for node in sim.nodes:
        drive = node.drive
        logger.info("node %d: stopped after %d SYNCs, virtual time %.6f s, operator energy %.6g J, wall energy %.6g J",
                    node.node_id, drive.sync_count, drive.time, drive.operator_energy, drive.wall_energy)
    return 0


def node_heard(listener: Any, node_ids: Sequence[int], seconds: float) -> int | None:
    """The first of ``node_ids`` that sends a frame (:data:`SENT_BY_A_NODE`) that ``listener`` (an open bus)
    hears within ``seconds`` (s), or None: a drive, or another simulator, already has that id."""
    sent = {base + node: node for node in node_ids for base in SENT_BY_A_NODE}
    deadline = time.monotonic() + seconds
    while (left := deadline - time.monotonic()) > 0:
        message = listener.recv(left)
        if message is not None and not message.is_extended_id and message.arbitration_id in sent:
            return sent[message.arbitration_id]
    return None


def booted_twice(listener: Any, node_ids: Sequence[int], seconds: float) -> int | None:
    """The first of ``node_ids`` whose boot-up (``0x700 + id``, one byte 0) ``listener`` (an open bus, opened before
    this simulator's own boot-up, which it hears too) hears twice within ``seconds`` (s), or None: another simulator
    of that id listened (:func:`node_heard`) at the same instant, heard nothing either, and booted beside it."""
    heard = dict.fromkeys(node_ids, 0)
    deadline = time.monotonic() + seconds
    while (left := deadline - time.monotonic()) > 0:
        message = listener.recv(left)
        if message is None or message.is_extended_id:
            continue
        data = bytes(message.data)
        if message.arbitration_id == 0 and len(data) == 2 and data[0] in NMT_RESETS:  # a master that found it resets it:
            for reset in node_ids if data[1] == 0 else [data[1]]:  # its boot-up comes again, no twin's
                heard.pop(reset, None)
            continue
        node = message.arbitration_id - 0x700
        if node in heard and data == b"\x00":
            heard[node] += 1
            if heard[node] > 1:
                return node
    return None


def started(sim: Any, bus: Mapping[str, Any], node_ids: Sequence[int]) -> bool:
    """Start ``sim`` (a slave or the multi-axis device on ``bus``, its nodes ``node_ids``), its threads named for
    the OS; False after one line on stderr if its bus cannot be opened, a node of one of its ids is heard there
    first, or one boots beside it (two node 5 on one bus answer each SDO twice: every master's session fails).
    One listener from before the listening to after the boot-up: two simulators of one id started at one instant
    (their listening within 2 ms) heard nothing of each other and both served (break18b); each now hears both
    boot-ups, and neither serves."""
    import can

    from drives.bus_config import open_bus

    try:
        with open_bus(**bus) as listener:
            taken = node_heard(listener, node_ids, NODE_LISTEN_S)
            if taken is not None:
                print(f"{PROG}: error: node {taken} is already on this bus (a frame of it heard: a drive or another "
                      "simulator with that id); stop it or give another node id", file=sys.stderr)
                return False
            sim.start()
            twice = booted_twice(listener, node_ids, NODE_LISTEN_S)
        if twice is not None:
            sim.stop()
            print(f"{PROG}: error: node {twice} booted twice on this bus at once (another simulator with that id "
                  "started at the same instant); stop it or give another node id", file=sys.stderr)
            return False
    except DriveError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return False
    except (can.CanError, OSError, ValueError) as exc:
        print(f"{PROG}: error: cannot open the bus: {exc}", file=sys.stderr)
        return False
    show_names()  # sim-drive-5, sim-bridge, ...: top -H and /proc/PID/task/*/comm say which thread is which
    return True


def log_eds_gaps(node_id: int, dictionary: Any) -> None:
    """One line naming what a user's EDS lacks of what a CiA-402 master in CST mode relies on."""
    from sim_drive.canopen.vendor_od import core_gaps

    gaps = core_gaps(dictionary)
    if gaps:
        logger.info("node %d: the EDS lacks %s: absent here too", node_id, "; ".join(gaps))


def run_modbus(args: argparse.Namespace) -> int:
    """The Modbus TCP server until SIGINT/SIGTERM (several axes: :func:`run_modbus_axes`)."""
    from sim_drive.modbus import ModbusSimServer, parse_modbus_url

    try:
        several = args.unit_ids is not None or len(args.modbus) > 1 or profile_axes(args) is not None
    except ParameterError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    if several:
        return run_modbus_axes(args)
    try:
        unit = unit_id(args)
    except ParameterError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    scheduling = set_up_process(args.log_wall_clock, "pymodbus", logging.CRITICAL)
    word_order = args.word_order or "big"
    try:
        host, port = parse_modbus_url(args.modbus[0])
        parameters, operator, timing = drive_setup(args)
        sim = ModbusSimServer(host, port, unit_id=unit, timing=timing, parameters=parameters, operator=operator,
                              word_order=word_order, sync_clock=sync_clock(args.clock),
                              hand_needs_power=True)  # the hand takes a powered handle (sim_drive.device.SimulatedDrive)
    except ParameterError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2

    def bound() -> None:
        logger.info("unit %d: serving Modbus TCP on %s (timing %s, word order %s, started %s); %s",
                    unit, sim.url, timing, word_order, utc_now(), scheduling)

    if not serve_until_stopped(args, lambda stop: sim.serve(stop, on_bound=bound)):
        return 1
    drive = sim.drive
    logger.info("unit %d: stopped after %d cycles, virtual time %.6f s, operator energy %.6g J, wall energy %.6g J",
                unit, sim.bank.cycles, drive.time, drive.operator_energy, drive.wall_energy)
    return 0


def serve_until_stopped(args: argparse.Namespace, serve: Callable[[asyncio.Event], Awaitable[None]]) -> bool:
    """Run ``serve(stop)`` in an event loop until SIGINT/SIGTERM sets ``stop``; False after one line
    on stderr if the socket cannot be served."""

    async def run() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        await serve(stop)

    try:
        asyncio.run(run())
    except (OSError, RuntimeError) as exc:  # pymodbus says "Could not start listen, please check address." alone
        print(f"{PROG}: error: cannot serve on {', '.join(args.modbus)}: {refused_address(args.modbus) or exc}",
              file=sys.stderr)
        return False
    return True


def refused_address(urls: Sequence[str]) -> str | None:
    """Why the system refuses to listen at the first of ``urls`` it refuses (``Address already in use``; with
    several, the address first), found by binding it for an instant; None if it refuses none of them."""
    from sim_drive.modbus import parse_modbus_url

    for url in urls:
        host, port = parse_modbus_url(url)
        try:
            socket.create_server((host, port)).close()
        except OSError as exc:
            why = os.strerror(exc.errno) if exc.errno else str(exc)
            return f"{url}: {why}" if len(urls) > 1 else why
    return None


def run_modbus_axes(args: argparse.Namespace) -> int:
    """The simulated multi-axis device over Modbus TCP until SIGINT/SIGTERM: one unit per axis, on one
    server or a server per axis."""
    from sim_drive.modbus import parse_modbus_url
    from sim_drive.modbus.multi_axis import MultiAxisModbusSim

    scheduling = set_up_process(args.log_wall_clock, "pymodbus", logging.CRITICAL)
    try:
        addresses = [parse_modbus_url(url) for url in args.modbus]
        axes, hand = modbus_axes_setup(args)
        sim = MultiAxisModbusSim(addresses, axes, hand, clock=args.clock, word_order=args.word_order or "big")
    except ParameterError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    units = ", ".join(str(unit) for unit in sim.unit_ids)

    def bound() -> None:
        logger.info("units %s: serving Modbus TCP on %s (one simulated drive per axis, the hand: %s, started %s); %s",
                    units, ", ".join(dict.fromkeys(sim.urls)), type(hand).__name__, utc_now(), scheduling)

    if not serve_until_stopped(args, lambda stop: sim.serve(stop, bound)):
        return 1
    for unit, url in zip(sim.units, sim.urls):
        drive = unit.drive
        logger.info("unit %d at %s: stopped after %d cycles, virtual time %.6f s, operator energy %.6g J, wall energy "
                    "%.6g J", unit.unit_id, url, unit.bank.cycles, drive.time, drive.operator_energy, drive.wall_energy)
    return 0
