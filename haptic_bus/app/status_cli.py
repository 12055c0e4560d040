"""``haptic-bus status``: one drive's state, read only, the way a vendor's service tool shows it.

CANopen (:func:`drives.canopen.service.read_status`): SDO reads of 0x6041 (the CiA-402 state),
0x6061, 0x603F, 0x1001, 0x1003, 0x6064, 0x606C, 0x1016, 0x1400:05 and 0x6007, while listening
``--listen`` s for the node's heartbeat (its NMT state), its EMCYs and SYNC frames.  Nothing is
written and no NMT command is sent: the drive's state is the same after.  Modbus
(:func:`drives.modbus.service.read_status`): the register map's statusword, mode, error code,
position, velocity, 0x6007 and watchdog.  An object the drive lacks is said absent.

Output: a table, or with ``--json`` one JSON object (every reading by key, with its source,
value, meaning, and ``missing`` where absent).  Exit status: 0 the drive answered and is not
in FAULT; 1 it is in FAULT (or FAULT REACTION ACTIVE: the status is printed, and one line on
stderr names the error and the command that clears it), or it did not answer, or the bus
failed (one line on stderr); 2 invalid arguments, refused before the bus is touched.
"""

from __future__ import annotations

import argparse
import json
import sys

from drives.drive_status import DEFAULT_LISTEN
from haptic_bus.app.arguments import EXIT_NO, EXIT_OK, add_command
from haptic_bus.app.drive_address import add_drive_arguments, drive_address, seconds
from haptic_bus.errors import ParameterError

STATUS_HELP = ("a drive's state, read only: NMT state, CiA-402 state, mode, error code and register, EMCYs, "
               "position, velocity, the safety objects")


def add_status_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``status`` on ``subparsers``; it sets ``handler``."""
    parser = add_command(subparsers, "status", STATUS_HELP, run_status)
    add_drive_arguments(parser)
    parser.add_argument("--listen", type=seconds("--listen"),
                        help=f"CANopen: how long to listen for the heartbeat, EMCYs and SYNC, s (default {DEFAULT_LISTEN})")
    return parser


def run_status(args: argparse.Namespace) -> int:
    """Read and print the drive's status; exit status (module docstring)."""
    address = drive_address(args)
    if address.modbus and args.listen is not None:
        raise ParameterError("--listen", args.listen, "a CANopen option (Modbus has no heartbeat or EMCY)")
    status = address.read_status(args.listen or DEFAULT_LISTEN, args.timeout)
    print(json.dumps(status.to_dict(), indent=2) if args.json else "\n".join(status.lines()))
    if status.faulted:
        print(f"haptic-bus status: {status.headline()}; {address.fault_reset_hint()}", file=sys.stderr)
        return EXIT_NO
    return EXIT_OK
