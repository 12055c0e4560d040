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

This module parses; what the options ask to simulate is :mod:`sim_drive.setups`, the serving
:mod:`sim_drive.serve`.
"""

from __future__ import annotations

import argparse
import sys
import threading
from collections.abc import Callable, Sequence
from typing import NoReturn, TypeVar

from drives.bus_config import BUS_KWARGS_HELP, BUS_OPTION_HELP, as_typed, parse_bus_option
from drives.cia301 import NODE_IDS
from drives.modbus.register_map import UNIT_IDS
from haptic_bus._version import __version__
from haptic_bus.console import logging_kept
from sim_drive.eds import OD_KINDS
from sim_drive.operator import operator_usage
from sim_drive.parameters import Timing
from sim_drive.scheduling import scheduling_restored
from sim_drive.serve import PROG, run_canopen, run_modbus
from sim_drive.sync_clock import SYNC_CLOCKS

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


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``haptic-bus sim`` (CANopen slave, or Modbus server with ``--modbus``)."""
    parser = _Parser(prog=PROG, description="Simulated CiA-402 drive: a CANopen slave, or a Modbus TCP server with --modbus.")
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
    canopen.add_argument("--node-id", type=_integer_or_text, help=f"its node id, one of the {NODE_IDS}")
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
    modbus.add_argument("--unit-id", type=_integer_or_text, help=f"its unit id, one of the {UNIT_IDS} (default 1)")
    modbus.add_argument("--unit-ids", metavar="IDS",
                        help="several axes (e.g. 1,2,3 or 1-3): one simulated drive per unit, in axis order; with a multi-axis "
                             "--profile ([[axes]]) each unit takes its axis' plant and hidden truth, and the profile's hand "
                             "in space pushes them all (default: the profile's unit_id, else unit 1 on each server)")
    modbus.add_argument("--word-order", choices=["big", "little"], help="32-bit word order (default big: high word first)")
    _add_overrides(parser, canopen)
    return parser


def _add_overrides(parser: argparse.ArgumentParser, canopen: argparse._ArgumentGroup) -> None:
    """``--mass``, ``--friction``, ``--coulomb``, ``--velocity-noise``, ``--noise-seed``, ``--transmission``,
    ``--extra-delay``, ``--operator`` (either server), ``--bus-kwargs`` (CANopen) and ``--version``."""
    truth = parser.add_argument_group("the hidden truth and the operator (either server; over the profile's)")
    truth.add_argument("--mass", type=_number_or_text, metavar="KG", help="handle mass m, kg")
    truth.add_argument("--friction", type=_number_or_text, metavar="N_S_PER_M", help="viscous friction b, N s/m")
    truth.add_argument("--coulomb", type=_number_or_text, metavar="N", help="Coulomb friction, N")
    truth.add_argument("--velocity-noise", type=_number_or_text, metavar="COUNTS", help="rms of the noise on 0x606C, counts")
    truth.add_argument("--noise-seed", type=_integer_or_text, metavar="N", help="seed of that noise (default: fresh entropy)")
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
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")


def add_axes_arguments(group: argparse._ArgumentGroup) -> None:
    """``--node-ids 5,6,7``: a simulated multi-axis device, one CANopen slave per node."""
    group.add_argument("--node-ids", metavar="IDS",
                       help="several axes in one process (e.g. 5,6,7 or 5-7): one simulated drive per node on the bus, each its "
                            "own exact plant; with a multi-axis --profile ([[axes]]) each node takes its axis' plant and "
                            "hidden truth, and the profile's hand in space ([space.operator]) pushes them all")


V = TypeVar("V", int, float)


def _read_or_text(kind: Callable[[str], V]) -> Callable[[str], V | str]:
    """A flag's type: its text as ``kind`` (``float``, ``int``), or as it is where it is none, for the check of the
    value to refuse with its range in one line (argparse's own ``invalid float value: 'x'`` named none)."""

    def read(text: str) -> V | str:
        try:
            return kind(text)
        except ValueError:
            return text

    return read


class _Whole(int):
    """A whole number read as ``haptic-bus run`` reads a node or unit id, decimal or ``0x``-hexadecimal, shown
    in a refusal as typed (``--unit-id = 0x100``, not 256); ``sim --unit-id 0x10`` was refused as text where
    ``run --unit-id 0x10`` and ``sim --unit-ids 0x10`` read unit 16."""

    typed: str

    def __new__(cls, text: str) -> _Whole:
        whole = super().__new__(cls, int(text, 0))
        whole.typed = text
        return whole

    def __repr__(self) -> str:
        return self.typed

    __str__ = int.__repr__


_number_or_text = _read_or_text(float)
_integer_or_text = _read_or_text(_Whole)


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
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    except SystemExit as exc:  # argparse's help through an abbreviation (--he): report, do not exit
        return int(exc.code or 0)
    if threading.current_thread() is not threading.main_thread():
        print(f"{PROG}: error: it serves until SIGINT or SIGTERM, which Python delivers to the main thread alone: "
              "call it from the main thread (a program's thread starts sim_drive.canopen.slave.CanopenSimDrive or "
              "sim_drive.modbus.server.ModbusSimServer and stops it itself)", file=sys.stderr)
        return 2
    # real time while serving (sim_drive.scheduling), and the log lines on stderr (sim_drive.serve), not after: a
    # program that calls this main has its own scheduling and logging back
    with scheduling_restored(), logging_kept():
        return run_modbus(args) if args.modbus is not None else run_canopen(args)
