"""The command-line options of a run, shared by ``haptic-bus run`` and ``haptic-bus validate``.

:func:`add_link_arguments` names the drive(s) (the bus options and ``--node-id``, or ``--modbus``
and ``--unit-id``/``--unit-ids``) and this controller's node (``--controller-node-id``);
:func:`add_pacing_arguments` how the cycles are paced (``--virtual-time``, or real time with
``--realtime``/``--no-realtime``, :func:`scheduling`); :func:`add_output_arguments` where the run
writes (``--out``, ``--no-bus-log``: :func:`bus_log`).  :func:`one_axis_link` turns them into one drive's address,
refusing conflicting options (exit 2) before anything is touched; :func:`as_flag` names an error of
the run's arguments as the option that gave it.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from haptic_bus.app.arguments import add_bus_arguments, modbus_url, node_id, refuse_can_options_with_modbus, unit_ids
from haptic_bus.app.drive_address import DriveAddress, add_node_id_argument, add_unit_id_argument, drive_address
from haptic_bus.errors import ParameterError
from haptic_bus.validation import typed_repeat

if TYPE_CHECKING:
    from haptic_bus.app.realtime import RealtimeSettings


def add_link_arguments(parser: argparse.ArgumentParser) -> None:
    """The drive's (or the axes') address and ``--controller-node-id``."""
    add_bus_arguments(parser)
    add_node_id_argument(parser)
    parser.add_argument("--controller-node-id", type=node_id,
                        help="this controller's CANopen node id: its heartbeat, which the drive watches, and gated wall "
                             "uploads (default 127)")
    parser.add_argument("--modbus", type=modbus_url, metavar="URL", action="append",
                        help="a Modbus drive instead: tcp://HOST:PORT or rtu:/dev/ttyUSB0; a multi-axis profile: once for "
                             "every axis' unit (one server), or once per axis (a server each)")
    add_unit_id_argument(parser)
    parser.add_argument("--unit-ids", type=unit_ids, metavar="IDS",
                        help="a multi-axis profile over Modbus: each axis' unit id, in axis order (e.g. 1,2,3 or 1-3; "
                             "default: the profile's [[axes]] unit_id, else unit 1 on each of one --modbus per axis)")


def add_pacing_arguments(parser: argparse.ArgumentParser) -> None:
    """``--virtual-time``, or ``--realtime``/``--no-realtime`` (default: real time as the OS grants it)."""
    pacing = parser.add_mutually_exclusive_group()
    pacing.add_argument("--virtual-time", action="store_true",
                        help="lock-step with a simulated drive, no wall-clock pacing (default: each cycle at its "
                             "deadline on the wall clock)")
    pacing.add_argument("--realtime", action=argparse.BooleanOptionalAction, default=None,
                        help="real-time scheduling of the control thread (SCHED_FIFO priority 80, one CPU, memory "
                             "locked) is asked for by default where the OS grants it; --realtime insists (what it "
                             "cannot get is a warning), --no-realtime asks for none of it; kept in run.json")


def add_output_arguments(parser: argparse.ArgumentParser) -> None:
    """``--out`` (the run's folder) and ``--no-bus-log``."""
    parser.add_argument("--out", help="folder for record.csv, run.json, bus.asc and plots (default: runs/<UTC time>-<profile>)")
    parser.add_argument("--no-bus-log", action="store_true",
                        help="do not log the CAN bus's frames into bus.asc (on by default; Modbus runs have none)")


def bus_log(args: argparse.Namespace, command: str) -> bool:
    """Whether the run logs the CAN bus (not ``--no-bus-log``); :class:`ParameterError` for
    ``--no-bus-log`` beside ``--modbus``, which has no bus log to leave out."""
    from haptic_bus.errors import ParameterError

    if args.modbus and args.no_bus_log:
        raise ParameterError("--no-bus-log", True, "CANopen runs only (a Modbus run has no bus.asc to leave out)", command)
    return not args.no_bus_log


def scheduling(realtime: bool | None) -> RealtimeSettings:
    """``--realtime`` (True), ``--no-realtime`` (False) or neither (None) as what the control thread asks of the OS."""
    from haptic_bus.app.realtime import RealtimeSettings

    if realtime is None:
        return RealtimeSettings()
    return RealtimeSettings(insist=True) if realtime else RealtimeSettings.unprivileged()


# run()'s arguments the options give (its bus: a Modbus URL list, the only bus an option can get wrong)
_FLAGS = {"node_id": "--node-id", "controller_node_id": "--controller-node-id", "unit_id": "--unit-id",
          "unit_ids": "--unit-ids", "bus": "--modbus", "out_dir": "--out"}


def as_flag(error: ParameterError) -> ParameterError:
    """``error`` of :func:`haptic_bus.app.runner.run` naming one of its arguments, named as the option
    that gives it (``controller_node_id`` as ``--controller-node-id``, the run folder's ``out_dir`` as
    ``--out``); any other error as it is."""
    flag = _FLAGS.get(error.name)
    return error if flag is None else ParameterError(flag, error.value, error.allowed)


def one_axis_link(args: argparse.Namespace, command: str) -> DriveAddress:
    """The one drive ``args`` name; conflicting or ignored options refused (ParameterError naming
    ``command``) before anything is touched."""
    if args.unit_ids is not None:
        raise ParameterError("--unit-ids", args.unit_ids, "--unit-id for a one-axis profile (--unit-ids: several axes)",
                             command)
    if args.modbus and len(args.modbus) > 1:
        shown, given = typed_repeat(args.modbus)
        raise ParameterError("--modbus", shown, f"one for a one-axis profile ({given}; one per axis: several axes)",
                             command)
    if args.modbus:
        refuse_can_options_with_modbus(args, command, ("node_id", "controller_node_id"))
    address = drive_address(argparse.Namespace(**{**vars(args), "modbus": args.modbus[0] if args.modbus else None}))
    if args.controller_node_id is not None and args.controller_node_id == args.node_id:
        raise ParameterError("--controller-node-id", args.controller_node_id,
                             f"a node id other than the drive's ({args.node_id})")
    return address
