"""Acyclic access to a drive's objects, whatever the fieldbus: what ``status`` and ``fault-reset`` need.

A CANopen drive is read and written over SDO (:class:`drives.canopen.client.NodeClient`), a
Modbus drive through its register map (:class:`drives.modbus.objects.ModbusObjects`); both
give values in the object's own integer units and raise the project's errors:
:class:`~drives.errors.DriveTimeout` for silence, a :class:`~drives.errors.DriveRefusal` (SDO
abort, Modbus exception, an object the register map lacks) or a
:class:`~drives.errors.DriveProtocolError` (an answer that cannot be used) for an object that
cannot be read or written.
"""

from __future__ import annotations

from typing import Protocol

from drives.cia301 import SdoAbort
from drives.cia402 import ObjectSpec
from drives.errors import DriveProtocolError, DriveRefusal, ParameterError

ILLEGAL_DATA_ADDRESS = 0x02  # Modbus exception: no such register
_ABSENT_CODES = frozenset({SdoAbort.NO_OBJECT, SdoAbort.NO_SUBINDEX, ILLEGAL_DATA_ADDRESS})


class ObjectAccess(Protocol):
    """One drive's objects, acyclically; ``name`` names the drive in messages."""

    name: str

    def read(self, spec: ObjectSpec) -> int:
        """The value of ``spec`` (its index and sub-index) in drive units."""

    def write(self, spec: ObjectSpec, value: int) -> None:
        """Write ``value`` (drive units) to ``spec``."""

    def source(self, spec: ObjectSpec) -> str:
        """Where ``spec`` lives on this bus: ``"0x6041"``, ``"0x1400:05"``, ``"register 0x0000"``."""


def is_absent(error: DriveProtocolError | DriveRefusal) -> bool:
    """True if ``error`` says the object does not exist (rather than that it cannot be read now).
    The SDO abort codes (0x05030000 and up) and the Modbus exception codes (0x01..0x0B) never meet."""
    return isinstance(error, DriveRefusal) and error.code in _ABSENT_CODES


def object_label(spec: ObjectSpec) -> str:
    """``"0x6041"`` for sub-index 0, ``"0x1400:05"`` otherwise (how CiA-301 users name an object)."""
    return f"0x{spec.index:04X}" if spec.subindex == 0 else f"0x{spec.index:04X}:{spec.subindex:02X}"


INDEX_RANGE = (0x0001, 0xFFFF)
SUBINDEX_RANGE = (0x00, 0xFF)
OBJECT_SYNTAX = ("INDEX[:SUB], INDEX 0x0001..0xFFFF (0x-hexadecimal, or decimal), SUB 00..FF hexadecimal as "
                 "object labels print it (e.g. 0x6041, 0x1018:04, 0x1A00:10 is sub-index 16)")


def parse_object(text: str) -> tuple[int, int]:
    """``"0x6041"`` -> (0x6041, 0), ``"0x1018:04"`` -> (0x1018, 4), ``"0x1A00:10"`` -> (0x1A00, 0x10): the
    sub-index hexadecimal, as :func:`object_label` prints it, so a label read back names the same
    object; ParameterError naming the syntax otherwise."""
    index_text, colon, sub_text = text.strip().partition(":")
    try:
        index = int(index_text, 0)
        subindex = int(sub_text, 16) if colon else 0
    except ValueError:
        raise ParameterError("object", text, OBJECT_SYNTAX) from None
    if not (INDEX_RANGE[0] <= index <= INDEX_RANGE[1] and SUBINDEX_RANGE[0] <= subindex <= SUBINDEX_RANGE[1]):
        raise ParameterError("object", text, OBJECT_SYNTAX)
    return index, subindex
