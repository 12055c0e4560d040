"""A service tool's two jobs on one Modbus CiA-402 unit: read its status, reset its fault.

Through :class:`~drives.modbus.objects.ModbusObjects` (the register map; the map identity is
read first).  :func:`read_status` reads only (FC03): the statusword, mode display, error code,
position, velocity, 0x6007 and the communication watchdog register 0x002A; a register the unit
refuses (exception 0x02) is reported absent.  A Modbus drive has no NMT, heartbeat or EMCY.
:func:`reset_fault` writes the controlword register (0x0010) with the sequence of
:func:`drives.fault_reset.reset_drive_fault` and reads the statusword (0x0000) after each write.
"""

from __future__ import annotations

from drives.drive_status import DEFAULT_ANSWER_TIMEOUT, DriveStatus, Reading, missing_reading, read_readings
from drives.errors import DriveProtocolError
from drives.fault_reset import DEFAULT_WAIT, FaultResetOutcome, reset_drive_fault
from drives.modbus.objects import ModbusObjects
from drives.modbus.register_map import REGISTER_BY_NAME

_WATCHDOG = REGISTER_BY_NAME["comm_watchdog_ms"]


def _watchdog(unit: ModbusObjects) -> Reading:
    """Register 0x002A: no valid request from the commanding connection for that long faults the drive."""
    key, label, source = "communication_watchdog", "watchdog", f"register 0x{_WATCHDOG.address:04X}"
    try:
        value = int(unit.read_register(_WATCHDOG))
    except DriveProtocolError as exc:
        return missing_reading(key, label, source, exc)
    return Reading(key, label, source, value, f"{value} ms" if value else "0: off")


def read_status(url: str, unit_id: int, timeout: float = DEFAULT_ANSWER_TIMEOUT) -> DriveStatus:
    """Unit ``unit_id``'s status at ``url`` (``tcp://HOST:PORT`` or ``rtu:/dev/...``), each request
    answered within ``timeout`` s; DriveTimeout if the server cannot be reached."""
    with ModbusObjects(url, unit_id, timeout) as unit:
        readings = read_readings(unit, (), (_watchdog,))
    return DriveStatus(unit.name, "modbus", readings)


def reset_fault(url: str, unit_id: int, wait: float = DEFAULT_WAIT, timeout: float = DEFAULT_ANSWER_TIMEOUT) -> FaultResetOutcome:
    """Reset unit ``unit_id``'s fault at ``url`` and wait (``wait`` s) for SWITCH ON DISABLED."""
    with ModbusObjects(url, unit_id, timeout) as unit:
        return reset_drive_fault(unit, wait)
