"""Which objects the slave's PDOs may carry, and how each is read or written every cycle.

The objects the simulated CiA-402 core implements (:meth:`SimulatedDrive.readable_objects` /
:meth:`~SimulatedDrive.writable_objects`, sub-index 0) are live: a TPDO samples the drive, an
RPDO commands it.  Any other PDO-mappable object of the slave's object dictionary -- in a
vendor's EDS (``haptic-bus sim --eds FILE``) the target position 0x607A, a record's sub-index
such as 0x60C1:01, a manufacturer object -- holds its value as a parameter does: a TPDO sends
what was last written over SDO or RPDO (the EDS default at first), an RPDO stores what it
carries.  So a vendor's default mapping runs as the EDS declares it.

An object may be mapped when the dictionary marks it PDO-mappable, its access allows the
direction (readable for a TPDO, writable for an RPDO) and, for a core object, the core
serves that direction.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from canopen import LocalNode
from canopen.objectdictionary import ODVariable

from sim_drive.device import ObjectAccessError, SimulatedDrive

logger = logging.getLogger(__name__)

Value = int | float


class PdoAccess:
    """PDO access to the objects of ``node``'s dictionary, live for those ``drive`` implements."""

    def __init__(self, drive: SimulatedDrive, node: LocalNode) -> None:
        self._drive = drive
        self._node = node
        self._readable = drive.readable_objects()
        self._writable = drive.writable_objects()

    def _core(self, variable: ODVariable) -> bool:
        return variable.subindex == 0 and variable.index in self._readable

    def mappable(self, variable: ODVariable, transmit: bool) -> bool:
        """True if ``variable`` may be mapped into a TPDO (``transmit``) or an RPDO."""
        if not variable.pdo_mappable or not (variable.readable if transmit else variable.writable):
            return False
        return not self._core(variable) or variable.index in (self._readable if transmit else self._writable)

    def reader(self, variable: ODVariable) -> Callable[[], Value]:
        """What a TPDO sends for ``variable`` each time."""
        if self._core(variable):
            return self._drive.reader(variable.index)
        index, subindex, node = variable.index, variable.subindex, self._node

        def stored() -> Value:
            value = variable.decode_raw(node.get_data(index, subindex))
            return value if isinstance(value, (int, float)) else 0  # a mappable object of this slave is a number

        return stored

    def writer(self, variable: ODVariable) -> Callable[[Value], None]:
        """What an RPDO does with its value for ``variable``."""
        if self._core(variable):
            drive, index = self._drive, variable.index

            def command(value: Value) -> None:
                try:
                    drive.write_object(index, int(value))
                except ObjectAccessError as exc:
                    logger.warning("%s: RPDO value refused: %s", drive.name, exc)

            return command
        return lambda value: self.keep(variable, value)

    def keep(self, variable: ODVariable, value: Value) -> None:
        """Hold ``value`` as ``variable``'s value: what an SDO read answers from now on."""
        self._node.data_store.setdefault(variable.index, {})[variable.subindex] = variable.encode_raw(value)
