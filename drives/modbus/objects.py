"""A Modbus drive's CiA-402 objects through the register map, acyclically: what ``haptic-bus
status``, ``fault-reset`` and ``sdo --modbus`` read and write.

:class:`ModbusObjects` is an :class:`~drives.object_access.ObjectAccess`: on entering, it
connects (one TCP connection, or the RTU line) and reads the map identity (0x0030), which
tells the word order of 32-bit values (:func:`~drives.modbus.register_map.word_order_of`); a
unit whose identity is not ours is refused (the addresses would mean something else there).
An object the map does not carry is :class:`~drives.errors.DriveRefusal`, before any request.
Nothing is written but what the caller writes: no scaling read, no watchdog set.
"""

from __future__ import annotations

from drives.cia402 import ObjectSpec
from drives.errors import DriveProtocolError, DriveRefusal
from drives.modbus.link import ModbusAddress, ModbusLink, ModbusStats
from drives.modbus.register_map import (
    MAP_IDENTITY,
    REGISTER_BY_NAME,
    RegisterSpec,
    decode_value,
    encode_value,
    register_for_object,
    word_order_of,
)
from drives.object_access import ILLEGAL_DATA_ADDRESS, object_label

_IDENTITY = REGISTER_BY_NAME["map_identity"]


class ModbusObjects:
    """Unit ``unit_id`` at ``url`` (``tcp://HOST:PORT`` or ``rtu:/dev/...``), each request
    answered within ``timeout`` s; use it as a context manager (connects, checks the map)."""

    def __init__(self, url: str, unit_id: int, timeout: float) -> None:
        address = ModbusAddress.from_url(url, timeout)
        self.unit_id = unit_id
        self.name = f"Modbus unit {unit_id} at {address.url}"
        self.link = ModbusLink(self.name, address, ModbusStats())
        self.word_order = "big"

    def __enter__(self) -> ModbusObjects:
        self.link.open()
        try:
            registers = self.link.read_holding(self.unit_id, _IDENTITY.address, _IDENTITY.count)
            order = word_order_of(registers)
            if order is None:
                found = int(decode_value(_IDENTITY, registers, "big"))
                raise DriveProtocolError(self.name, f"map identity register 0x0030 reads 0x{found:08X}, ours is "
                                                    f"0x{MAP_IDENTITY:08X}: not the haptic_bus register map")
        except BaseException:
            self.link.drop()
            raise
        self.word_order = order
        return self

    def __exit__(self, *exc: object) -> None:
        self.link.drop()

    def register(self, spec: ObjectSpec) -> RegisterSpec:
        """The register carrying ``spec``; DriveRefusal (0x02, as the drive would answer) if the map has none."""
        try:
            if spec.subindex == 0:
                return register_for_object(spec.index)
        except KeyError:
            pass
        raise DriveRefusal(self.name, f"{object_label(spec)} ({spec.name}) is not in the Modbus register map",
                           ILLEGAL_DATA_ADDRESS, spec.index, spec.subindex)

    def source(self, spec: ObjectSpec) -> str:
        """``"register 0x0000"`` for a mapped object, else the object's own label."""
        try:
            return f"register 0x{self.register(spec).address:04X}"
        except DriveRefusal:
            return object_label(spec)

    def read_register(self, register: RegisterSpec) -> int | float:
        """The value of one mapped register (or register pair) in the unit's word order."""
        return decode_value(register, self.link.read_holding(self.unit_id, register.address, register.count), self.word_order)

    def write_register(self, register: RegisterSpec, value: int | float) -> None:
        """Write one mapped value (ValueError if outside its kind's range: check first)."""
        self.link.write_holding(self.unit_id, register.address, encode_value(register, value, self.word_order))

    def read(self, spec: ObjectSpec) -> int:
        """Object ``spec`` in drive units."""
        return int(self.read_register(self.register(spec)))

    def write(self, spec: ObjectSpec, value: int) -> None:
        """Write ``value`` (drive units) to object ``spec``."""
        self.write_register(self.register(spec), value)
