"""``haptic-bus sim``: run the simulated drive as a CANopen slave or a Modbus TCP server until SIGINT/SIGTERM.

    haptic-bus sim --interface I --channel C --node-id N [--bitrate R] [--bus-option KEY=VALUE ...]
                   [--od haptic|standard | --eds FILE] [--timing cia402|ideal|reception] [--profile P] [--log-wall-clock]
    haptic-bus sim --interface I --channel C --node-ids 5,6,7 [--profile gantry-3d] [...]   (several axes)
    haptic-bus sim --modbus tcp://HOST:PORT [--unit-id N] [--word-order big|little]
                   [--timing cia402|ideal|reception] [--profile P] [--log-wall-clock]
    haptic-bus sim --modbus tcp://HOST:PORT --unit-ids 1,2,3 [--profile gantry-3d] [...]   (several axes, one server)
    haptic-bus sim --modbus URL1 --modbus URL2 --modbus URL3 [--unit-ids ...] [--profile gantry-3d]   (a server per axis)
    haptic-bus sim --eds-path
    haptic-bus sim --version
    python -m sim_drive ...   (the same)

The hidden truth and the operator (either server) override the profile's (or the defaults'):
``--mass KG``, ``--friction N_S_PER_M``, ``--coulomb N``, ``--velocity-noise COUNTS`` (0x606C
counts rms), ``--noise-seed N``, ``--operator none|constant:LEVEL|...`` (``none``: a free handle,
so that ``haptic-bus identify`` is not refused).  ``--bus-kwargs KEY=VALUE ...`` is python-can's
spelling of ``--bus-option``.

One parser: ``--modbus`` selects the Modbus server (:mod:`sim_drive.modbus`), otherwise the
CANopen slave runs; the options of the other server are refused.  Logs one line per CiA-402
state change through ``logging``, each with the drive's virtual time.  ``--log-wall-clock``
prefixes every line with the wall-clock time it was seen (the simulator paces nothing: the SYNC
producer, or the Modbus client, sets the pace).  With ``--bitrate`` the CANopen run ends with the bus load and
worst cycle latency of the worst-case bit-time model.
Exit status: 0 after a clean stop (or help), 2 for bad arguments or parameters (one line on
stderr), 1 if the bus or the socket fails.
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import logging
import signal
import socket
import sys
import time
from collections.abc import Awaitable, Callable, Sequence
from typing import Any, NoReturn

from drives.bus_config import BUS_KWARGS_HELP, BUS_OPTION_HELP, as_typed, merge_bus_options, parse_bus_option
from drives.cia301 import NODE_ID_RANGE
from haptic_bus._version import __version__
from haptic_bus.console import StderrHandler
from haptic_bus.errors import DriveError, ParameterError
from sim_drive.eds import OD_KINDS, eds_path
from sim_drive.operator import OperatorModel, operator_from_spec, operator_usage
from sim_drive.parameters import DeviceParameters, Timing
from sim_drive.profile import SimulatedDevice, read_simulated_device
from sim_drive.scheduling import answer_in_real_time, scheduling_restored
from sim_drive.sync_clock import SYNC_CLOCKS, sync_clock

logger = logging.getLogger("sim_drive")

_PROG = "haptic-bus sim"
_CANOPEN_ONLY = ("eds_path", "interface", "channel", "node_id", "bitrate", "bus_option", "bus_kwargs", "od", "eds",
                 "node_ids")
_MODBUS_ONLY = ("unit_id", "word_order", "unit_ids")
_HELP = frozenset({"-h", "--help"})


class _UsageError(Exception):
    """A command line the parser refuses; the message is one line."""


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors raise :class:`_UsageError` (one line) instead of printing usage."""

    def error(self, message: str) -> NoReturn:
        raise _UsageError(message)


class _StopSignals:
    """Records SIGINT/SIGTERM from ``__enter__`` to ``__exit__``; :meth:`wait` blocks for the first.

    The handler only appends to a list (a handler that took a lock could deadlock on one the
    interrupted main thread holds), and Python's C-level handler writes a byte to the wake-up
    socket, so the blocking ``recv`` returns even for a signal that came just before it.
    Signal masks are no help: numpy's BLAS threads, started at import time, would take a
    masked signal with its default action.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __enter__(self) -> _StopSignals:
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


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``haptic-bus sim`` (CANopen slave, or Modbus server with ``--modbus``)."""
    parser = _Parser(prog=_PROG, description="Simulated CiA-402 drive: a CANopen slave, or a Modbus TCP server with --modbus.")
    both = parser.add_argument_group("either server")
    both.add_argument("--timing", choices=[t.value for t in Timing],
                      help="cia402 (default), ideal or reception (a target acts the profile's [loop] delay, "
                           "default 0.25, of a period after the SYNC); default: the profile's [loop] timing")
    both.add_argument("--profile", help="operator profile (name or TOML path): [device], [loop], [operator_model]")
    both.add_argument("--log-wall-clock", action="store_true", help="timestamp log lines with the wall clock")
    both.add_argument("--clock", choices=SYNC_CLOCKS, default="virtual",
                      help="how far the handle moves per cycle: virtual (exactly T per SYNC or Modbus output "
                           "write, for a master in virtual time) or wall (the time between them, as a real "
                           "handle lives a late cycle; use it against a real-time run)")
    canopen = parser.add_argument_group("CANopen slave (the default)")
    canopen.add_argument("--interface", help="python-can interface (virtual, udp_multicast, socketcan, ...)")
    canopen.add_argument("--channel", help="python-can channel (e.g. vcan0, a multicast group)")
    canopen.add_argument("--node-id", type=int, help="CANopen node id 1..127")
    add_axes_arguments(canopen)
    canopen.add_argument("--bitrate", type=int, help="bit/s; also enables the bus-load report")
    canopen.add_argument("--bus-option", type=parse_bus_option, action="append", default=[], metavar="KEY=VALUE",
                         help=BUS_OPTION_HELP)
    canopen.add_argument("--eds-path", action="store_true", help="print the path of the shipped EDS and exit")
    canopen.add_argument("--od", choices=list(OD_KINDS),
                         help="object dictionary: haptic (default: the shipped EDS, manufacturer objects 0x2000.. "
                              "included) or standard (CiA-301/402 objects only, the scaling in 0x608F/0x6090/0x6091/"
                              "0x6092/0x60A8/0x60A9/0x6076, no object in 0x2000-0x5FFF)")
    canopen.add_argument("--eds", metavar="FILE",
                         help="serve the simulated CiA-402 core behind your own drive's EDS: objects it lacks are "
                              "absent (SDO abort 0x06020000/0x06090011), its PDOs and mapping limits as it declares "
                              "them; rehearse commissioning against your drive's dictionary")
    modbus = parser.add_argument_group("Modbus TCP server")
    modbus.add_argument("--modbus", metavar="tcp://HOST:PORT", action="append",
                        help="serve Modbus TCP on this address (PORT 0: any free port); several axes: once for all "
                             "(one server, a unit per axis) or once per axis (a server each)")
    modbus.add_argument("--unit-id", type=int, help="Modbus unit id 1..247, one a master can address (default 1)")
    modbus.add_argument("--unit-ids", metavar="IDS",
                        help="several axes (e.g. 1,2,3): one simulated drive per unit, in axis order; with a multi-axis "
                             "--profile ([[axes]]) each unit takes its axis' plant and hidden truth, and the profile's hand "
                             "in space pushes them all (default: the profile's unit_id, else unit 1 on each server)")
    modbus.add_argument("--word-order", choices=["big", "little"], help="32-bit word order (default big: high word first)")
    _add_overrides(parser, canopen)
    return parser


# --------------------------------------------------------------------------- the hidden truth, the operator, python-can's
# spelling of bus options, the version: the command line over the profile (issue 20)

_TRUTH_FLAGS = {"mass": "mass", "friction": "friction", "coulomb": "coulomb_friction", "velocity_noise": "velocity_noise",
                "noise_seed": "noise_seed", "transmission": "transmission",
                "extra_delay": "extra_delay"}  # argparse dest -> DeviceParameters field


def _add_overrides(parser: argparse.ArgumentParser, canopen: argparse._ArgumentGroup) -> None:
    """``--mass``, ``--friction``, ``--coulomb``, ``--velocity-noise``, ``--noise-seed``, ``--transmission``,
    ``--extra-delay``, ``--operator`` (either server), ``--bus-kwargs`` (CANopen) and ``--version``."""
    truth = parser.add_argument_group("the hidden truth and the operator (either server; over the profile's)")
    truth.add_argument("--mass", type=float, metavar="KG", help="handle mass m, kg")
    truth.add_argument("--friction", type=float, metavar="N_S_PER_M", help="viscous friction b, N s/m")
    truth.add_argument("--coulomb", type=float, metavar="N", help="Coulomb friction, N")
    truth.add_argument("--velocity-noise", type=float, metavar="COUNTS", help="rms of the noise on 0x606C, counts")
    truth.add_argument("--noise-seed", type=int, metavar="N", help="seed of that noise (default: fresh entropy)")
    truth.add_argument("--transmission", metavar="STIFFNESS:DAMPING:MOTOR_MASS",
                       help="a handle that is not rigid: a motor-side mass (kg), where the encoder and the torque act, "
                            "coupled to the handle (the profile's m and b) by a spring (N/m) and a damper (N s/m)")
    truth.add_argument("--extra-delay", type=_number_or_text, metavar="SAMPLES",
                       help="apply each target this many samples (fractional allowed) later than the timing says")
    truth.add_argument("--operator", metavar="MODEL",
                       help=f"what pushes the handle: {operator_usage()} (SI units; none: a free handle, nobody "
                            "touches it, as haptic-bus identify needs)")
    canopen.add_argument("--bus-kwargs", type=parse_bus_option, nargs="+", action="append", default=[],
                         metavar="KEY=VALUE", help=BUS_KWARGS_HELP)
    parser.add_argument("--version", action="version", version=f"{_PROG} {__version__}")


def _number_or_text(text: str) -> float | str:
    """``text`` as a float, or as it is: the truth's check then refuses it with its range in one line."""
    try:
        return float(text)
    except ValueError:
        return text


def _overridden(parameters: DeviceParameters, operator: OperatorModel | None,
                args: argparse.Namespace) -> tuple[DeviceParameters, OperatorModel | None]:
    """``parameters`` and ``operator`` with the command line's truth and operator; ParameterError names the flag."""
    given = {field: getattr(args, dest) for dest, field in _TRUTH_FLAGS.items() if getattr(args, dest) is not None}
    try:
        parameters = dataclasses.replace(parameters, **given)
    except ParameterError as exc:
        flag = next(dest for dest, field in _TRUTH_FLAGS.items() if field == exc.name)
        raise ParameterError("--" + flag.replace("_", "-"), exc.value, exc.allowed) from None
    return parameters, operator if args.operator is None else operator_from_spec(args.operator)


def _bus_config(args: argparse.Namespace) -> dict[str, Any]:
    """The CANopen slave's python-can arguments; ParameterError for a key given twice with different values."""
    named = [(key, getattr(args, key)) for key in ("interface", "channel", "bitrate") if getattr(args, key)]
    return merge_bus_options(named, args.bus_option, *args.bus_kwargs)


# --------------------------------------------------------------------------- running


def _flags(args: argparse.Namespace, parser: argparse.ArgumentParser, dests: Sequence[str]) -> str:
    """The options among ``dests`` given on the command line, each with the value given
    (``--node-id = 5, --bus-option = 'port=4'``; a switch by its name alone)."""
    return ", ".join(_given("--" + d.replace("_", "-"), getattr(args, d)) for d in dests
                     if getattr(args, d) != parser.get_default(d))


def _given(flag: str, value: object) -> str:
    return flag if isinstance(value, bool) else f"{flag} = {as_typed(value)!r}"


def _parse(parser: argparse.ArgumentParser, argv: list[str]) -> argparse.Namespace:
    """The arguments, or :class:`_UsageError` if they are malformed or mix the two servers' options."""
    args = parser.parse_args(argv)
    if args.modbus is not None and (given := _flags(args, parser, _CANOPEN_ONLY)):
        raise _UsageError(f"CANopen options cannot be combined with --modbus: {given}")
    if args.modbus is None and (given := _flags(args, parser, _MODBUS_ONLY)):
        raise _UsageError(f"Modbus options need --modbus: {given}")
    return args


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``haptic-bus sim``; return the exit status."""
    args_list = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    if _HELP.intersection(args_list):  # help wins wherever it stands, even after a bare --modbus
        parser.print_help()
        return 0
    try:
        args = _parse(parser, args_list)
    except _UsageError as exc:
        print(f"{_PROG}: error: {exc}", file=sys.stderr)
        return 2
    except SystemExit as exc:  # argparse's help through an abbreviation (--he): report, do not exit
        return int(exc.code or 0)
    with scheduling_restored():  # real time while serving (sim_drive.scheduling), not after
        return _run_modbus(args) if args.modbus is not None else _run_canopen(args)


def _set_up_process(wall_clock: bool, library: str, level: int) -> str:
    """Log lines on stderr (stamped with the wall clock with ``wall_clock``; the bus ``library`` only
    from ``level``), then real-time scheduling for every thread to come (:mod:`sim_drive.scheduling`):
    what it got, in words for the serving line (a refusal before it logs nothing)."""
    fmt = "%(asctime)s %(message)s" if wall_clock else "%(message)s"
    logging.basicConfig(level=logging.INFO, format=fmt, handlers=[StderrHandler()], force=True)
    logging.getLogger(library).setLevel(level)
    return answer_in_real_time()


def _drive_setup(args: argparse.Namespace) -> tuple[DeviceParameters, OperatorModel | None, str]:
    """Device parameters, operator model and timing of one axis from ``--profile`` (a one-axis profile)
    and ``--timing``; ParameterError if invalid."""
    axis, operator = read_simulated_device(args.profile).one_axis() if args.profile else (None, None)
    parameters, operator = _overridden(axis.parameters if axis else DeviceParameters(), operator, args)
    timing = args.timing or (axis.timing if axis else Timing.CIA402).value
    return parameters, operator, timing


def _profile_axes(args: argparse.Namespace) -> SimulatedDevice | None:
    """The device of a ``--profile`` with ``[[axes]]``, each axis its own plant and node or unit (None: no
    profile, or a one-axis profile, which every axis runs); ParameterError if the profile is invalid."""
    device = read_simulated_device(args.profile) if args.profile else None
    return device if device is not None and device.multi_axis else None


def _run_canopen(args: argparse.Namespace) -> int:
    """The CANopen slave until SIGINT/SIGTERM."""

    from sim_drive.bus_timing import BusLoadMeter
    from sim_drive.canopen.slave import CanopenSimDrive

    if args.eds_path:
        print(eds_path())
        return 0
    if args.node_ids is not None:
        return run_axes(args)
    missing = [name for name in ("interface", "channel", "node_id") if getattr(args, name) is None]
    if missing:
        print(f"{_PROG}: error: missing --{', --'.join(m.replace('_', '-') for m in missing)}", file=sys.stderr)
        return 2
    scheduling = _set_up_process(args.log_wall_clock, "canopen", logging.WARNING)
    try:
        parameters, operator, timing = _drive_setup(args)
        meter = BusLoadMeter(args.bitrate, parameters.period) if args.bitrate else None
        config = _bus_config(args)
        sim = CanopenSimDrive(config, args.node_id, timing=timing, parameters=parameters, operator=operator, bus_meter=meter,
                              od=args.od or "haptic", eds=args.eds, sync_clock=sync_clock(args.clock),
                              hand_needs_power=True)  # the hand takes a powered handle (sim_drive.device.SimulatedDrive)
    except ParameterError as exc:
        print(f"{_PROG}: error: {exc}", file=sys.stderr)
        return 2
    with _StopSignals() as stop_signals:  # from before the boot-up: an early signal still stops cleanly
        if not started(sim):
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


# ----------------------------------------------------------------------------- several axes (issue 22)

def add_axes_arguments(group: argparse._ArgumentGroup) -> None:
    """``--node-ids 5,6,7``: a simulated multi-axis device, one CANopen slave per node."""
    group.add_argument("--node-ids", metavar="IDS",
                       help="several axes in one process (e.g. 5,6,7): one simulated drive per node on the bus, each its "
                            "own exact plant; with a multi-axis --profile ([[axes]]) each node takes its axis' plant and "
                            "hidden truth, and the profile's hand in space ([space.operator]) pushes them all")


def id_list(flag: str, text: str, low: int, high: int, what: str) -> list[int]:
    """``5,6,7`` -> [5, 6, 7]: distinct whole numbers in [low, high]; ParameterError naming ``flag`` otherwise."""
    try:
        ids = [int(part) for part in text.split(",")]
    except ValueError:
        ids = []
    if not ids or len(set(ids)) != len(ids) or not all(low <= n <= high for n in ids):
        raise ParameterError(flag, text, f"distinct {what} {low}..{high} separated by commas, e.g. {low},{low + 1},{low + 2}")
    return ids


def _node_ids(text: str) -> list[int]:
    return id_list("--node-ids", text, *NODE_ID_RANGE, "CANopen node ids")


def _axes_setup(args: argparse.Namespace) -> tuple[list[Any], Any, list[int]]:
    """``(axes, hand, coordinates)`` for ``--node-ids``; ParameterError if the arguments or the profile are invalid."""
    from sim_drive.space_operator import SpaceHand

    nodes = _node_ids(args.node_ids)
    if args.node_id is not None or args.eds is not None:
        raise ParameterError("--node-ids", args.node_ids, "without --node-id and --eds (one dictionary kind: --od)")
    if args.transmission is not None:  # the hand in space pushes each axis' handle where its encoder is
        raise ParameterError("--transmission", args.transmission, "one axis only (--node-id): no hand in space on "
                             "the far side of a transmission")
    device = _profile_axes(args)
    if device is not None:
        known = [axis.node_id for axis in device.axes]
        unknown = [n for n in nodes if n not in known]
        if unknown:
            raise ParameterError("--node-ids", args.node_ids, f"node ids of the profile's [[axes]]: {known}")
        chosen = [known.index(n) for n in nodes]
        axes = [(n, device.axes[i].parameters, args.timing or device.axes[i].timing) for n, i in zip(nodes, chosen)]
        return axes, device.make_hand(), chosen
    parameters, _, timing = _drive_setup(args)
    return [(n, parameters, timing) for n in nodes], SpaceHand(len(nodes)), list(range(len(nodes)))


def run_axes(args: argparse.Namespace) -> int:
    """The simulated multi-axis device (``--node-ids``) until SIGINT/SIGTERM: one CANopen slave per node."""

    from sim_drive.canopen.multi_axis import MultiAxisSim

    missing = [name for name in ("interface", "channel") if getattr(args, name) is None]
    if missing:
        print(f"{_PROG}: error: missing --{', --'.join(missing)}", file=sys.stderr)
        return 2
    config: dict[str, Any] = {"interface": args.interface, "channel": args.channel, **dict(args.bus_option)}
    if args.bitrate:
        config["bitrate"] = args.bitrate
    try:
        axes, hand, coordinates = _axes_setup(args)
        sim = MultiAxisSim(config, axes, hand, coordinates=coordinates, clock=args.clock, od=args.od or "haptic")
    except ParameterError as exc:
        print(f"{_PROG}: error: {exc}", file=sys.stderr)
        return 2
    scheduling = _set_up_process(args.log_wall_clock, "canopen", logging.WARNING)  # once the arguments hold
    with _StopSignals() as stop_signals:
        if not started(sim):
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


def started(sim: Any) -> bool:
    """Start ``sim`` (a slave or the multi-axis device); False after one line on stderr if its bus cannot be opened."""
    import can

    try:
        sim.start()
    except DriveError as exc:
        print(f"{_PROG}: error: {exc}", file=sys.stderr)
        return False
    except (can.CanError, OSError, ValueError) as exc:
        print(f"{_PROG}: error: cannot open the bus: {exc}", file=sys.stderr)
        return False
    return True


def log_eds_gaps(node_id: int, dictionary: Any) -> None:
    """One line naming what a user's EDS lacks of what a CiA-402 master in CST mode relies on."""
    from sim_drive.canopen.vendor_od import core_gaps

    gaps = core_gaps(dictionary)
    if gaps:
        logger.info("node %d: the EDS lacks %s: absent here too", node_id, "; ".join(gaps))


def _run_modbus(args: argparse.Namespace) -> int:
    """The Modbus TCP server until SIGINT/SIGTERM (several axes: :func:`run_modbus_axes`)."""
    from sim_drive.modbus import ModbusSimServer, parse_modbus_url

    try:
        several = args.unit_ids is not None or len(args.modbus) > 1 or _profile_axes(args) is not None
    except ParameterError as exc:
        print(f"{_PROG}: error: {exc}", file=sys.stderr)
        return 2
    if several:
        return run_modbus_axes(args)
    from drives.modbus.register_map import UNIT_ID_RANGE

    unit_id = UNIT_ID_RANGE[0] if args.unit_id is None else args.unit_id
    if not UNIT_ID_RANGE[0] <= unit_id <= UNIT_ID_RANGE[1]:  # as --unit-ids: the units haptic-bus run can reach
        allowed = f"a Modbus unit id {UNIT_ID_RANGE[0]}..{UNIT_ID_RANGE[1]}"
        print(f"{_PROG}: error: {ParameterError('--unit-id', unit_id, allowed)}", file=sys.stderr)
        return 2
    scheduling = _set_up_process(args.log_wall_clock, "pymodbus", logging.CRITICAL)
    word_order = args.word_order or "big"
    try:
        host, port = parse_modbus_url(args.modbus[0])
        parameters, operator, timing = _drive_setup(args)
        sim = ModbusSimServer(host, port, unit_id=unit_id, timing=timing, parameters=parameters, operator=operator,
                              word_order=word_order, sync_clock=sync_clock(args.clock),
                              hand_needs_power=True)  # the hand takes a powered handle (sim_drive.device.SimulatedDrive)
    except ParameterError as exc:
        print(f"{_PROG}: error: {exc}", file=sys.stderr)
        return 2

    def bound() -> None:
        logger.info("unit %d: serving Modbus TCP on %s (timing %s, word order %s, started %.3f); %s",
                    unit_id, sim.url, timing, word_order, time.time(), scheduling)

    if not _serve_until_stopped(args, lambda stop: sim.serve(stop, on_bound=bound)):
        return 1
    drive = sim.drive
    logger.info("unit %d: stopped after %d cycles, virtual time %.6f s, operator energy %.6g J, wall energy %.6g J",
                unit_id, sim.bank.cycles, drive.time, drive.operator_energy, drive.wall_energy)
    return 0


def _serve_until_stopped(args: argparse.Namespace, serve: Callable[[asyncio.Event], Awaitable[None]]) -> bool:
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
    except (OSError, RuntimeError) as exc:
        print(f"{_PROG}: error: cannot serve on {', '.join(args.modbus)}: {exc}", file=sys.stderr)
        return False
    return True


def _modbus_axes_setup(args: argparse.Namespace) -> tuple[list[Any], Any]:
    """``(axes, hand)`` for several Modbus axes: each (unit id, parameters, timing) in axis order;
    ParameterError if the arguments or the profile are invalid (module docstring of the options)."""
    from drives.modbus.register_map import UNIT_ID_RANGE
    from sim_drive.space_operator import SpaceHand

    given = id_list("--unit-ids", args.unit_ids, *UNIT_ID_RANGE, "Modbus unit ids") if args.unit_ids else None
    if args.unit_id is not None:
        raise ParameterError("--unit-id", args.unit_id, "--unit-ids for several axes (one unit id per axis)")
    device = _profile_axes(args)
    if device is not None:
        stated = [axis.unit_id for axis in device.axes]
        units = given or (stated if None not in stated else [UNIT_ID_RANGE[0]] * len(args.modbus))
        if len(units) != len(device.axes) or (len(args.modbus) == 1 and len(set(units)) != len(units)):
            raise ParameterError("--unit-ids", args.unit_ids, f"one unit id per axis of the profile ({len(device.axes)}), "
                                 "or several --modbus addresses, one per axis")
        return [(unit, axis.parameters, args.timing or axis.timing) for unit, axis in zip(units, device.axes)], \
            device.make_hand()
    units = given or [UNIT_ID_RANGE[0]] * len(args.modbus)
    if len(args.modbus) not in (1, len(units)):
        raise ParameterError("--modbus", len(args.modbus), f"one address for every unit, or one per unit ({len(units)})")
    parameters, _, timing = _drive_setup(args)
    return [(unit, parameters, timing) for unit in units], SpaceHand(len(units))


def run_modbus_axes(args: argparse.Namespace) -> int:
    """The simulated multi-axis device over Modbus TCP until SIGINT/SIGTERM: one unit per axis, on one
    server or a server per axis."""
    from sim_drive.modbus import parse_modbus_url
    from sim_drive.modbus.multi_axis import MultiAxisModbusSim

    scheduling = _set_up_process(args.log_wall_clock, "pymodbus", logging.CRITICAL)
    try:
        addresses = [parse_modbus_url(url) for url in args.modbus]
        axes, hand = _modbus_axes_setup(args)
        sim = MultiAxisModbusSim(addresses, axes, hand, clock=args.clock, word_order=args.word_order or "big")
    except ParameterError as exc:
        print(f"{_PROG}: error: {exc}", file=sys.stderr)
        return 2
    units = ", ".join(str(unit) for unit in sim.unit_ids)

    def bound() -> None:
        logger.info("units %s: serving Modbus TCP on %s (one simulated drive per axis, the hand: %s, started %.3f); %s",
                    units, ", ".join(dict.fromkeys(sim.urls)), type(hand).__name__, time.time(), scheduling)

    if not _serve_until_stopped(args, lambda stop: sim.serve(stop, bound)):
        return 1
    for unit, url in zip(sim.units, sim.urls):
        drive = unit.drive
        logger.info("unit %d at %s: stopped after %d cycles, virtual time %.6f s, operator energy %.6g J, wall energy "
                    "%.6g J", unit.unit_id, url, unit.bank.cycles, drive.time, drive.operator_energy, drive.wall_energy)
    return 0
