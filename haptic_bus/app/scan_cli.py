"""``haptic-bus scan``: who is on the bus, read-only: CANopen nodes, or the units of a Modbus server.

    haptic-bus scan [--interface I] [--channel C] [--bitrate R] [--bus-option KEY=VALUE ...]
                    [--node-ids 1-127] [--timeout 1] [--answer-timeout 0.1] [--json]
    haptic-bus scan --modbus tcp://HOST:PORT [--unit-ids 1-247] [--timeout 1] [--answer-timeout 0.1] [--json]

CANopen (:mod:`drives.canopen.scan`): listens for boot-ups and heartbeats, sends one SDO read
of 0x1000 to every node id at once, listens ``--timeout`` s, then reads 0x1000, 0x1018 and
(CiA-402 devices) 0x6502, 0x6041 (the CiA-402 state) and 0x603F (the error code) from every
node seen, in parallel, each read within ``--answer-timeout`` s.  At most
``timeout + 8 * answer_timeout`` s plus opening the bus.
Sends SDO reads only: no NMT command, no write.  Modbus (:mod:`drives.modbus.scan`): per unit id,
FC03 reads of the map identity, 0x6502, 0x6041 and 0x603F and an FC43/14 device identification,
each within ``--answer-timeout`` s; new units are started for ``--timeout`` s, the ones not
reached are named on stderr (at worst ``timeout + 16 * answer_timeout`` s in all).

Output: one line per node (unit), or with ``--json`` one JSON list of objects (numbers as
numbers; null where a value could not be read, with the reason in ``notes``).
Exit status: 0 at least one node (unit) answered; 1 none did ("no node answered" on stderr,
``[]`` on stdout with ``--json``, so a script can tell an empty bus from a full one), or the bus
failed (one line on stderr); 2 invalid arguments, refused before the bus is touched.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from drives.cia301 import NODE_ID_RANGE, NODE_IDS
from drives.modbus.register_map import UNIT_ID_RANGE, UNIT_IDS
from drives.scan_arguments import DEFAULT_ANSWER_TIMEOUT, DEFAULT_TIMEOUT, MAX_SECONDS
from haptic_bus.app.arguments import (
    EXIT_NO,
    EXIT_OK,
    add_bus_arguments,
    add_command,
    bus_arguments,
    number,
    refuse_can_options_with_modbus,
)
from haptic_bus.errors import ParameterError
from haptic_bus.validation import ids_in_order

if TYPE_CHECKING:  # the scans import canopen and pymodbus: only when a scan runs
    from drives.canopen.scan import CanopenNode
    from drives.modbus.scan import ModbusScan

SCAN_HELP = ("list the CANopen nodes on a CAN bus (or the units of a Modbus server): identity, NMT state, CST support, "
             "CiA-402 state and error code 0x603F")


# --------------------------------------------------------------------------- argument types

def id_list(text: str, name: str, allowed: str, low: int, high: int) -> list[int]:
    """``"5"``, ``"1-10"``, ``"5,9,20-30"`` -> the ids, sorted, read as every flag that takes ids reads
    them (:func:`~haptic_bus.validation.ids_in_order`); ParameterError otherwise, and for an id given
    twice (``1-3,2``) as ``run`` and ``sim`` refuse it (it was dropped quietly).  Read first as ``run``
    reads its text (a list that cannot be is refused in run's words), then as distinct."""
    ids_in_order(name, text, allowed, low, high)
    return sorted(ids_in_order(name, text, allowed, low, high, distinct=True))


def node_ids(text: str) -> list[int]:
    """CANopen node ids (``1-127``, ``5,9``)."""
    return id_list(text, "node ids", NODE_IDS, *NODE_ID_RANGE)


def unit_ids(text: str) -> list[int]:
    """Modbus unit ids (``1-247``, ``1,2``)."""
    return id_list(text, "unit ids", UNIT_IDS, *UNIT_ID_RANGE)


def add_scan_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``scan`` on ``subparsers``; it sets ``handler``."""
    parser = add_command(subparsers, "scan", SCAN_HELP, run_scan)
    add_bus_arguments(parser)
    parser.add_argument("--node-ids", type=node_ids, metavar="IDS", help="CANopen node ids to probe, e.g. 5,9 or 1-10,127; "
                        "default: all, 1-127")
    parser.add_argument("--modbus", metavar="URL", help="scan a Modbus server instead: tcp://HOST:PORT or rtu:/dev/ttyUSB0")
    parser.add_argument("--unit-ids", type=unit_ids, metavar="IDS", help="Modbus unit ids to probe, e.g. 1,2 or 1-10 "
                        "(only with --modbus); default: all, 1-247")
    parser.add_argument("--timeout", type=number("--timeout", 0.0, MAX_SECONDS, "s", low_open=True), default=DEFAULT_TIMEOUT,
                        help="CANopen: listening window after the probe; Modbus: time in which new units are started; s")
    parser.add_argument("--answer-timeout", type=number("--answer-timeout", 0.0, MAX_SECONDS, "s", low_open=True),
                        default=DEFAULT_ANSWER_TIMEOUT,
                        help="each SDO read (CANopen) or request (Modbus), s")
    parser.add_argument("--json", action="store_true", help="one JSON list on stdout")
    return parser


def _validate(args: argparse.Namespace) -> None:
    """Refuse options of the other protocol, and a Modbus URL without host and port, before anything is touched."""
    from drives.modbus.link import ModbusAddress

    if args.modbus is None:
        if args.unit_ids is not None:
            raise ParameterError("--unit-ids", args.unit_ids, "a Modbus option: give it with --modbus URL", "scan")
        return
    refuse_can_options_with_modbus(args, "scan", ("node_ids",), "--unit-ids")
    try:
        ModbusAddress.from_url(args.modbus)
    except ParameterError as exc:
        raise ParameterError("--modbus", args.modbus, exc.allowed, "scan") from None


# --------------------------------------------------------------------------- output

def _hex(value: int | None) -> str:
    return "-" if value is None else f"0x{value:08X}"


def _yes(value: bool | None) -> str:
    return "-" if value is None else ("yes" if value else "no")


def _word(value: int | None) -> str:
    return "-" if value is None else f"0x{value:04X}"


def format_canopen(nodes: Sequence[CanopenNode]) -> str:
    """One line per node (and its notes indented below)."""
    lines = [f"{'node':>4}  {'device type':<11}  {'kind':<22}  {'vendor':<10}  {'product':<10}  {'revision':<10}  "
             f"{'serial':<10}  {'NMT state':<15}  CST  CiA-402  {'CiA-402 state':<22}  0x603F"]
    from drives.canopen.scan import device_kind

    for node in nodes:
        kind = "-" if node.device_type is None else device_kind(node.device_type)
        ident = node.identity
        lines.append(f"{node.node_id:>4}  {_hex(node.device_type):<11}  {kind:<22}  {_hex(ident.vendor_id):<10}  "
                     f"{_hex(ident.product_code):<10}  {_hex(ident.revision):<10}  {_hex(ident.serial):<10}  "
                     f"{node.nmt_state or '-':<15}  {_yes(node.cst_supported):<3}  {_yes(node.cia402):<7}  "
                     f"{node.cia402_state or '-':<22}  {_word(node.error_code)}")
        if node.boot_up_seen:
            lines.append("      boot-up seen during the scan")
        lines += [f"      note: {note}" for note in node.notes]
    return "\n".join(lines)


def format_modbus(scan: ModbusScan) -> str:
    """One line per unit (and its notes indented below)."""
    lines = [f"{'unit':>4}  {'register map':<20}  {'word order':<10}  {'0x6502':<10}  CST  CiA-402  "
             f"{'CiA-402 state':<22}  0x603F  device identification"]
    for unit in scan.units:
        where = f"ours {_hex(unit.map_identity)}" if unit.our_map else "not ours"
        info = unit.device_identification
        ident = "-" if info is None else (", ".join(f"{k}={v!r}" for k, v in info.items()) or "answered, no objects")
        lines.append(f"{unit.unit_id:>4}  {where:<20}  {unit.word_order or '-':<10}  {_hex(unit.supported_drive_modes):<10}  "
                     f"{_yes(unit.cst_supported):<3}  {_yes(unit.cia402):<7}  {unit.cia402_state or '-':<22}  "
                     f"{_word(unit.error_code):<6}  {ident}")
        lines += [f"      note: {note}" for note in unit.notes]
    return "\n".join(lines)


def _ranges(ids: Sequence[int]) -> str:
    """``[1, 2, 3, 7]`` -> ``"1-3,7"``."""
    parts: list[str] = []
    for i in ids:
        if parts and parts[-1].split("-")[-1] == str(i - 1):
            parts[-1] = f"{parts[-1].split('-')[0]}-{i}"
        else:
            parts.append(str(i))
    return ",".join(parts)


# --------------------------------------------------------------------------- handler

def run_scan(args: argparse.Namespace) -> int:
    """Scan as ``args`` say, print the result; exit status (module docstring)."""
    from drives.canopen.scan import scan_canopen
    from drives.modbus.scan import scan_modbus

    _validate(args)
    unprobed_note = ""
    if args.modbus is not None:
        scan = scan_modbus(args.modbus, args.unit_ids or range(UNIT_ID_RANGE[0], UNIT_ID_RANGE[1] + 1),
                           args.timeout, args.answer_timeout)
        found: Sequence[Any] = scan.units
        text = format_modbus(scan)
        where = f"at {scan.url}"
        if scan.unprobed:
            unprobed = (f"unit ids {_ranges(scan.unprobed)} not probed: --timeout {args.timeout:g} s spent (raise it, or "
                        "narrow --unit-ids)")
            if scan.units:  # a note beside what answered; nothing answered: the one failure line says it too
                print(f"haptic-bus scan: {unprobed}", file=sys.stderr)
            else:
                unprobed_note = f"; {unprobed}"
    else:
        bus = bus_arguments(args)
        found = scan_canopen(bus, args.node_ids or range(NODE_ID_RANGE[0], NODE_ID_RANGE[1] + 1),
                             args.timeout, args.answer_timeout)
        text = format_canopen(found)
        named = ":".join(str(bus[key]) for key in ("interface", "channel") if key in bus)
        where = f"on {named or 'the bus of the python-can configuration'}"
    if args.json:
        print(json.dumps([item.to_dict() for item in found], indent=2))
    elif found:
        print(text)
    if not found:
        print(f"haptic-bus scan: no node answered {where} within {args.timeout:g} s{unprobed_note}", file=sys.stderr)
        return EXIT_NO
    return EXIT_OK
