"""The bus load of several axes on one SYNC, checked before a start (issue 22).

Each axis' drive exchanges its PDOs every cycle; a profile names the mapping per axis:

* ``minimal`` (what the controller configures): TPDO1 = statusword 0x6041 + velocity actual
  0x606C (6 bytes), RPDO1 = controlword 0x6040 + target torque 0x6071 (4 bytes);
* ``with-position`` (a scene that reads the position): TPDO1 as above plus TPDO2 = position
  actual 0x6064 (4 bytes), RPDO1 as above.

These are the frames the CANopen master maps (``drives.canopen.drive.DEFAULT_TPDO``,
``DEFAULT_TPDO_WITH_POSITION``, ``DEFAULT_RPDO``; tests/test_bus_load.py holds them equal).  One
SYNC per cycle serves every axis; :func:`~haptic_bus.analysis.can_timing.check_bus_load` refuses
a cycle above 70 % of the bitrate, naming the load and the smallest ``T`` that fits.  Three axes
with the minimal mapping are 685 bit times per cycle: 68.5 % at 1 Mbit/s and ``T = 1 ms``,
548 % at 125 kbit/s (``T >= 7.83 ms`` fits).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from drives.cia402 import CONTROLWORD, POSITION_ACTUAL, STATUSWORD, TARGET_TORQUE, VELOCITY_ACTUAL, ObjectSpec
from haptic_bus.analysis.can_timing import BusLoad, check_bus_load
from haptic_bus.errors import ParameterError


@dataclass(frozen=True)
class PdoMapping:
    """The objects of each TPDO and RPDO frame of one axis, in mapping order."""

    tpdo: tuple[tuple[ObjectSpec, ...], ...]
    rpdo: tuple[tuple[ObjectSpec, ...], ...]

    def frame_bytes(self) -> tuple[int, ...]:
        """The data length (bytes) of every frame the axis exchanges per cycle, TPDOs then RPDOs."""
        return tuple(sum(spec.data_type.size for spec in frame) for frame in (*self.tpdo, *self.rpdo))


_RPDO = ((CONTROLWORD, TARGET_TORQUE),)
PDO_MAPPINGS: dict[str, PdoMapping] = {
    "minimal": PdoMapping(((STATUSWORD, VELOCITY_ACTUAL),), _RPDO),
    "with-position": PdoMapping(((STATUSWORD, VELOCITY_ACTUAL), (POSITION_ACTUAL,)), _RPDO),
}


def axes_bus_load(mappings: Sequence[str], bitrate: float, period: float) -> BusLoad:
    """The load of one SYNC and every axis' PDOs (``mappings``: one name of :data:`PDO_MAPPINGS` per axis)
    at ``bitrate`` bit/s every ``period`` s; ParameterError above 70 % (the load and the smallest T named)."""
    unknown = [name for name in mappings if name not in PDO_MAPPINGS]
    if unknown:
        raise ParameterError("mapping", unknown[0], " or ".join(repr(m) for m in PDO_MAPPINGS), "bus load")
    return check_bus_load([PDO_MAPPINGS[name].frame_bytes() for name in mappings], bitrate, period)
