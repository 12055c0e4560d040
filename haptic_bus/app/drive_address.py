"""Which drive a service command (``status``, ``fault-reset``, ``sdo``) talks to, and how to name it again.

A CANopen node on a python-can bus (``--interface/--channel/--bitrate/--bus-option`` and
``--node-id``), or a Modbus unit (``--modbus URL`` and ``--unit-id``), parsed the way ``run``
parses them; mixing the two is refused before anything is touched (exit 2).
:meth:`DriveAddress.command` writes the command line that reaches the same drive, for
messages that tell a user what to type next (``haptic-bus fault-reset --interface ... --node-id 5``).
"""

from __future__ import annotations

import argparse
import shlex
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from drives.cia301 import NODE_IDS
from drives.drive_status import DEFAULT_ANSWER_TIMEOUT
from drives.modbus.register_map import UNIT_IDS
from haptic_bus.app.arguments import (
    add_bus_arguments,
    bus_arguments,
    modbus_url,
    node_id,
    number,
    refuse_can_options_with_modbus,
    unit_id,
)
from haptic_bus.errors import ParameterError

if TYPE_CHECKING:  # the services import canopen or pymodbus: only when a command runs
    from drives.drive_status import DriveStatus
    from drives.fault_reset import FaultResetOutcome

DEFAULT_UNIT_ID = 1
MAX_SECONDS = 60.0  # the longest any wait of a service command may be
_BUS_FLAGS = ("interface", "channel", "bitrate")

NODE_ID_HELP = f"the drive's node id, one of the {NODE_IDS}"
UNIT_ID_HELP = f"the drive's unit id, one of the {UNIT_IDS} (default {DEFAULT_UNIT_ID}; only with --modbus)"
NODE_ID_WANTED = f"{NODE_ID_HELP} (or --modbus URL)"  # a command that names one drive and was given none


@dataclass(frozen=True)
class DriveAddress:
    """A CANopen node (``bus``: python-can keyword arguments, ``node_id``) or a Modbus unit (``url``, ``unit_id``)."""

    bus: Mapping[str, Any] = field(default_factory=dict)
    node_id: int | None = None
    url: str | None = None
    unit_id: int = DEFAULT_UNIT_ID

    @property
    def modbus(self) -> bool:
        """True for a Modbus unit."""
        return self.url is not None

    def arguments(self) -> list[str]:
        """The command-line options that reach this drive."""
        if self.url is not None:
            return ["--modbus", self.url, *(["--unit-id", str(self.unit_id)] if self.unit_id != DEFAULT_UNIT_ID else [])]
        words = [word for key in _BUS_FLAGS if key in self.bus for word in (f"--{key}", str(self.bus[key]))]
        words += [word for key, value in self.bus.items() if key not in _BUS_FLAGS
                  for word in ("--bus-option", f"{key}={value}")]
        return [*words, "--node-id", str(self.node_id)]

    def command(self, name: str) -> str:
        """``haptic-bus NAME OPTIONS`` for this drive, quoted for a POSIX shell."""
        return shlex.join(["haptic-bus", name, *self.arguments()])

    def fault_reset_hint(self) -> str:
        """What a user types to clear this drive's fault: ``clear the cause, then: haptic-bus fault-reset ...``."""
        return f"clear the cause, then: {self.command('fault-reset')}"

    def read_status(self, listen: float, timeout: float) -> DriveStatus:
        """The drive's status (:mod:`drives.canopen.service`, :mod:`drives.modbus.service`); ``listen``
        (s) is CANopen's listening window, ``timeout`` (s) each answer's."""
        if self.url is not None:
            from drives.modbus import service as modbus

            return modbus.read_status(self.url, self.unit_id, timeout)
        from drives.canopen import service as canopen

        return canopen.read_status(self.bus, self.checked_node_id, listen, timeout)

    def reset_fault(self, wait: float, timeout: float) -> FaultResetOutcome:
        """Reset the drive's fault, waiting at most ``wait`` s for SWITCH ON DISABLED."""
        if self.url is not None:
            from drives.modbus import service as modbus

            return modbus.reset_fault(self.url, self.unit_id, wait, timeout)
        from drives.canopen import service as canopen

        return canopen.reset_fault(self.bus, self.checked_node_id, wait, timeout)

    @property
    def checked_node_id(self) -> int:
        """The CANopen node id (ParameterError if there is none)."""
        if self.node_id is None:
            raise ParameterError("--node-id", None, NODE_ID_WANTED)
        return self.node_id


def add_address_arguments(parser: argparse.ArgumentParser) -> None:
    """The options that name one drive: the bus options and ``--node-id``, or ``--modbus`` and ``--unit-id``."""
    add_bus_arguments(parser)
    add_node_id_argument(parser)
    parser.add_argument("--modbus", type=modbus_url, metavar="URL",
                        help="a Modbus drive instead: tcp://HOST:PORT or rtu:/dev/ttyUSB0")
    add_unit_id_argument(parser)


def add_node_id_argument(parser: argparse.ArgumentParser) -> None:
    """``--node-id``: the drive's CANopen node id (every command that names one drive, and ``run``)."""
    parser.add_argument("--node-id", type=node_id, help=NODE_ID_HELP)


def add_unit_id_argument(parser: argparse.ArgumentParser) -> None:
    """``--unit-id``: the drive's Modbus unit id (every command that names one drive, and ``run``)."""
    parser.add_argument("--unit-id", type=unit_id, help=UNIT_ID_HELP)


def add_drive_arguments(parser: argparse.ArgumentParser) -> None:
    """The options that name one drive (:func:`add_address_arguments`), each answer's ``--timeout`` and ``--json``."""
    add_address_arguments(parser)
    parser.add_argument("--timeout", type=seconds("--timeout"), default=DEFAULT_ANSWER_TIMEOUT,
                        help="each SDO answer or Modbus request, s")
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")


def seconds(flag: str) -> argparse._ActionType:
    """A parser of a time in (0, 60] s for ``flag``."""
    return number(flag, 0.0, MAX_SECONDS, "s", low_open=True)


def drive_address(args: argparse.Namespace, command: str = "", can_only: tuple[str, ...] = ("node_id",),
                  node_required: bool = True) -> DriveAddress:
    """The drive ``args`` name (:func:`add_address_arguments`); ParameterError (exit 2) naming
    ``command`` for options of both kinds (``can_only``: the argparse dests besides the bus options
    that only a CANopen drive takes) or, where ``node_required``, no drive at all."""
    if args.modbus is not None:
        refuse_can_options_with_modbus(args, command, can_only)
        return DriveAddress(url=args.modbus, unit_id=args.unit_id or DEFAULT_UNIT_ID)
    if args.unit_id is not None:
        raise ParameterError("--unit-id", args.unit_id, "a Modbus option: give it with --modbus URL", command)
    if args.node_id is None and node_required:
        raise ParameterError("--node-id", None, NODE_ID_WANTED, command)
    return DriveAddress(bus=bus_arguments(args), node_id=args.node_id)
