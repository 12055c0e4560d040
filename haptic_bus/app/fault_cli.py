"""``haptic-bus fault-reset``: clear a drive's fault whose cause is gone (CiA-402 transition 15).

A drive in FAULT gets the controlword's fault-reset edge (0x6040 bit 7: low, high while it
shows FAULT, low again; :func:`drives.fault_reset.reset_drive_fault`), over SDO on CANopen or
the register map's controlword on Modbus, and the command waits at most ``--wait`` s for SWITCH
ON DISABLED.  A drive in any other state is left alone.  On CANopen the bus is listened to
first: SYNC frames mean a master is cycling (its RPDOs carry the controlword), and the reset
is refused.  Nothing else is written; the drive is never enabled.

Exit status: 0 the drive is in SWITCH ON DISABLED (or was not in FAULT: nothing done);
1 the cause persists (still FAULT after ``--wait`` s: one line with its error code 0x603F),
a master is cycling, the drive did not answer or the bus failed; 2 invalid arguments, refused
before the bus is touched.  ``--json`` prints what was found and left as one JSON object.
"""

from __future__ import annotations

import argparse
import json
import sys

from drives.fault_reset import DEFAULT_WAIT
from haptic_bus.app.arguments import EXIT_NO, EXIT_OK, add_command
from haptic_bus.app.drive_address import add_drive_arguments, drive_address, seconds

FAULT_RESET_HELP = "clear a drive's fault whose cause is gone (controlword fault-reset edge), wait for SWITCH ON DISABLED"


def add_fault_reset_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``fault-reset`` on ``subparsers``; it sets ``handler``."""
    parser = add_command(subparsers, "fault-reset", FAULT_RESET_HELP, run_fault_reset)
    add_drive_arguments(parser)
    parser.add_argument("--wait", type=seconds("--wait"), default=DEFAULT_WAIT,
                        help="longest wait for SWITCH ON DISABLED after the reset edge, s")
    return parser


def run_fault_reset(args: argparse.Namespace) -> int:
    """Reset the drive's fault and say where it is now; exit status (module docstring)."""
    outcome = drive_address(args).reset_fault(args.wait, args.timeout)
    if args.json:
        print(json.dumps(outcome.to_dict(), indent=2))
    if not outcome.cleared:
        print(f"haptic-bus fault-reset: {outcome.message()}", file=sys.stderr)
        return EXIT_NO
    if not args.json:
        print(outcome.message())
    return EXIT_OK
