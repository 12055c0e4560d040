"""The command-line options of a run that reaches one drive, shared by ``haptic-bus run`` and ``haptic-bus validate``.

:func:`add_link_arguments` names the drive (the bus options and ``--node-id``, or ``--modbus`` and
``--unit-id``) and this controller's node (``--controller-node-id``); :func:`add_pacing_arguments`
how the cycles are paced (``--virtual-time`` or ``--realtime``); :func:`add_output_arguments`
where the run writes (``--out``, ``--no-bus-log``).  :func:`one_axis_link` turns them into the
drive's address, refusing conflicting options (exit 2) before anything is touched.
"""

from __future__ import annotations

import argparse

from haptic_bus.app.arguments import node_id, refuse_can_options_with_modbus
from haptic_bus.app.drive_address import DriveAddress, add_address_arguments, drive_address
from haptic_bus.errors import ParameterError


def add_link_arguments(parser: argparse.ArgumentParser) -> None:
    """The drive's address and ``--controller-node-id``."""
    add_address_arguments(parser)
    parser.add_argument("--controller-node-id", type=node_id,
                        help="this controller's CANopen node id: its heartbeat, which the drive watches, and gated wall "
                             "uploads (default 127)")


def add_pacing_arguments(parser: argparse.ArgumentParser) -> None:
    """``--virtual-time`` or ``--realtime`` (default: each cycle at its deadline on the wall clock)."""
    pacing = parser.add_mutually_exclusive_group()
    pacing.add_argument("--virtual-time", action="store_true",
                        help="lock-step with a simulated drive, no wall-clock pacing (default: each cycle at its "
                             "deadline on the wall clock)")
    pacing.add_argument("--realtime", action="store_true",
                        help="ask the OS for real-time scheduling of the control thread: SCHED_FIFO priority 80, one CPU, "
                             "memory locked (mlockall); what it cannot get is logged as a warning and kept in run.json")


def add_output_arguments(parser: argparse.ArgumentParser) -> None:
    """``--out`` (the run's folder) and ``--no-bus-log``."""
    parser.add_argument("--out", help="folder for record.csv, run.json, bus.asc and plots (default: runs/<UTC time>-<profile>)")
    parser.add_argument("--no-bus-log", action="store_true",
                        help="do not log the CAN bus's frames into bus.asc (on by default; Modbus runs have none)")


def one_axis_link(args: argparse.Namespace, command: str) -> DriveAddress:
    """The one drive ``args`` name; conflicting or ignored options refused (ParameterError, ``command``
    naming the command that refuses Modbus with CAN options) before anything is touched."""
    if args.modbus:
        refuse_can_options_with_modbus(args, command, ("node_id", "controller_node_id"))
    address = drive_address(args)
    if args.controller_node_id is not None and args.controller_node_id == args.node_id:
        raise ParameterError("--controller-node-id", args.controller_node_id,
                             f"a node id other than the drive's ({args.node_id})")
    return address
