"""Which Modbus units answer at an address, and which of them carry our register map (read-only).

Every request is a read: FC03 (read holding registers) and FC43/14 (read device
identification).  For each unit id in turn, until the time budget is spent:

1. FC03 of the map identity (0x0030, 2 registers, :data:`~drives.modbus.register_map.MAP_IDENTITY`).
   Read high word first it is our map in word order ``"big"``, swapped in ``"little"``; another
   value, or an exception response (0x01, 0x02, ...), is a unit that is there but is not our
   map.  No answer within ``answer_timeout``, or exception 0x0A/0x0B (a gateway reporting that
   no device answers behind it), is no unit: it is skipped.
2. Our map: FC03 of 0x6502 (0x0026, 2 registers) in that word order, of the statusword 0x6041
   (0x0000: its CiA-402 state) and of the error code 0x603F (0x0028).
3. Every unit found: FC43/14 basic device identification (objects 0x00 vendor name, 0x01
   product code, 0x02 major/minor revision), where the server supports it.

One connection, one request at a time: Modbus TCP servers serve a connection's requests in
order (and a gateway's serial line is one at a time anyway), so the sweep is sequential; after
a request that timed out the connection is replaced (see :class:`_Prober`).  It stops starting
new units ``timeout`` s after it began; the units it did not reach are returned as
``unprobed``.  Total time, bounded: every request and every connect waits at most
``answer_timeout``, and the last unit started makes at most five requests, each at worst a
drop, a reconnect, a resend that times out and a reconnect: ``timeout + 16 * answer_timeout`` s
at the very worst (the first connect included); on a server that answers, ``timeout`` plus a
few round trips.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any, ClassVar

from pymodbus.pdu.mei_message import ReadDeviceInformationRequest
from pymodbus.pdu.register_message import ReadHoldingRegistersRequest

from drives.cia402 import ERROR_CODE, STATUSWORD, SUPPORTED_DRIVE_MODES
from drives.errors import DriveError, DriveRefusal, DriveTimeout, ModbusLinkLost
from drives.modbus.link import ModbusAddress, ModbusLink, ModbusStats
from drives.modbus.register_map import (
    MAP_IDENTITY,
    NO_UNIT_CODES,
    REGISTER_BY_NAME,
    UNIT_ID_RANGE,
    UNIT_IDS,
    RegisterSpec,
    decode_value,
    register_for_object,
    word_order_of,
)
from drives.scan_arguments import DEFAULT_ANSWER_TIMEOUT, DEFAULT_TIMEOUT, checked_ids, checked_seconds
from drives.scanned_device import ScannedDevice

__all__ = ["UNIT_ID_RANGE", "ModbusScan", "ModbusUnit", "scan_modbus"]

DEVICE_IDENTIFICATION_NAMES = {0x00: "vendor_name", 0x01: "product_code", 0x02: "revision"}
_IDENTITY_REGISTER = REGISTER_BY_NAME["map_identity"]
_MODES_REGISTER = register_for_object(SUPPORTED_DRIVE_MODES)
_STATUSWORD_REGISTER = register_for_object(STATUSWORD)
_ERROR_CODE_REGISTER = register_for_object(ERROR_CODE)


@dataclass(frozen=True)
class ModbusUnit(ScannedDevice):
    """One unit that answered; None where a value could not be read (see ``notes``)."""

    protocol: ClassVar[str] = "modbus"

    unit_id: int
    word_order: str | None  # "big"/"little": our map, in that word order; None: not our map
    map_identity: int | None  # registers 0x0030..0x0031 read high word first; None: refused
    supported_drive_modes: int | None  # 0x6502, our map only
    device_identification: dict[str, str] | None  # FC43/14 basic objects; None: not supported
    notes: tuple[str, ...] = ()
    statusword: int | None = None  # 0x6041, our map only
    error_code: int | None = None  # 0x603F, our map only

    @property
    def our_map(self) -> bool:
        """True if the unit carries the register map of :mod:`drives.modbus.register_map`."""
        return self.word_order is not None

    @property
    def cia402(self) -> bool:
        """True for our map: it is the CiA-402 drive's map (nothing else is known of other units)."""
        return self.our_map

    def identity_dict(self) -> dict[str, Any]:
        """The unit id, whether it carries our map (in which word order), and its FC43/14 identification."""
        return {"unit_id": self.unit_id, "our_map": self.our_map, "word_order": self.word_order,
                "map_identity": self.map_identity, "device_identification": self.device_identification}


@dataclass
class ModbusScan:
    """What :func:`scan_modbus` found: the units that answered, and the unit ids it had no time for."""

    url: str
    units: list[ModbusUnit] = field(default_factory=list)
    unprobed: list[int] = field(default_factory=list)


class _Prober:
    """The requests of the sweep over one link.

    A request that times out may still be answered later, and a server serves a connection's
    requests in order: the link is replaced by a fresh connection at once, so a late answer can
    neither be taken for the next unit's nor hold it up.  A dropped connection is reopened and
    the request sent once more.  A server that cannot be reached again ends the scan (DriveError).
    """

    def __init__(self, link: ModbusLink) -> None:
        self.link = link

    def _reconnect(self) -> None:
        self.link.drop()
        try:
            self.link.open()
        except DriveTimeout as exc:  # not "this unit is silent": the server is gone
            raise DriveError(self.link.name, f"the server went away during the scan: {exc.message}") from exc

    def _send_once(self, request: Any, what: str) -> Any:
        try:
            return self.link.send(request, what)
        except ModbusLinkLost:
            raise
        except DriveTimeout:
            self._reconnect()
            raise

    def send(self, request: Any, what: str) -> Any:
        """One request's answer; DriveTimeout (on a fresh link) if none came in time."""
        try:
            return self._send_once(request, what)
        except ModbusLinkLost:
            self._reconnect()
            return self._send_once(request, what)

    def read(self, unit: int, address: int, count: int, what: str) -> list[int]:
        response = self.send(ReadHoldingRegistersRequest(address=address, count=count, dev_id=unit), what)
        registers = list(response.registers)
        if len(registers) != count:
            raise DriveError(self.link.name, f"{what}: {len(registers)} registers in the answer, asked for {count}")
        return registers

    def probe(self, unit: int) -> ModbusUnit | None:
        """The unit's record, or None if no unit answers at ``unit``."""
        notes: list[str] = []
        try:
            registers = self.read(unit, _IDENTITY_REGISTER.address, _IDENTITY_REGISTER.count, f"unit {unit}: map identity")
        except DriveTimeout:
            return None
        except DriveRefusal as exc:
            if exc.code in NO_UNIT_CODES:
                return None
            notes.append(exc.message)
            registers = None
        identity = None if registers is None else int(decode_value(_IDENTITY_REGISTER, registers, "big"))
        order = None if registers is None else word_order_of(registers)
        values: dict[RegisterSpec, int | None] = {}
        if order is not None:
            for spec in (_MODES_REGISTER, _STATUSWORD_REGISTER, _ERROR_CODE_REGISTER):
                values[spec] = self._optional(notes, functools.partial(self.value, unit, spec, order))
        elif identity is not None:
            notes.append(f"map identity register reads 0x{identity:08X}, ours is 0x{MAP_IDENTITY:08X}: not our map")
        information = self._optional(notes, lambda: self.identification(unit))
        return ModbusUnit(unit, order, identity, values.get(_MODES_REGISTER), information, tuple(notes),
                          values.get(_STATUSWORD_REGISTER), values.get(_ERROR_CODE_REGISTER))

    def value(self, unit: int, spec: RegisterSpec, word_order: str) -> int:
        """The integer of ``spec`` at ``unit``, read in ``word_order``."""
        return int(decode_value(spec, self.read(unit, spec.address, spec.count, f"unit {unit}: {spec.label}"), word_order))

    def identification(self, unit: int) -> dict[str, str]:
        """FC43/14 basic device identification, object names to text."""
        response = self.send(ReadDeviceInformationRequest(read_code=1, object_id=0, dev_id=unit),
                             f"unit {unit}: read device identification")
        found: dict[str, str] = {}
        for object_id, value in sorted(getattr(response, "information", {}).items()):
            parts = value if isinstance(value, list) else [value]
            text = "".join(p.decode("latin-1") if isinstance(p, bytes) else str(p) for p in parts)
            found[DEVICE_IDENTIFICATION_NAMES.get(object_id, f"object_0x{object_id:02X}")] = text
        return found

    @staticmethod
    def _optional(notes: list[str], read: Any) -> Any:
        """``read()``, or None and a note if the unit refuses it or stays silent."""
        try:
            return read()
        except (DriveRefusal, DriveTimeout) as exc:
            notes.append(exc.message)
            return None


def scan_modbus(
    url: str,
    unit_ids: Iterable[int] = range(UNIT_ID_RANGE[0], UNIT_ID_RANGE[1] + 1),
    timeout: float = DEFAULT_TIMEOUT,
    answer_timeout: float = DEFAULT_ANSWER_TIMEOUT,
) -> ModbusScan:
    """The units among ``unit_ids`` at ``url`` (``tcp://HOST:PORT`` or ``rtu:/dev/...``), in order
    (module docstring).  ParameterError for bad arguments (before connecting), DriveTimeout if the
    server cannot be reached, DriveError if the link fails."""
    ids = checked_ids("unit ids", unit_ids, UNIT_IDS, *UNIT_ID_RANGE)
    checked_seconds("timeout", timeout)
    address = ModbusAddress.from_url(url, checked_seconds("answer timeout", answer_timeout))
    link = ModbusLink(f"Modbus {address.url}", address, ModbusStats())
    result = ModbusScan(address.url)
    end = time.monotonic() + timeout
    link.open()
    try:
        prober = _Prober(link)
        for position, unit in enumerate(ids):
            if time.monotonic() >= end:
                result.unprobed = ids[position:]
                break
            found = prober.probe(unit)
            if found is not None:
                result.units.append(found)
    finally:
        link.drop()
    return result
