"""haptic_bus' errors: the distribution's error tree (drawn in :mod:`drives.errors`), re-exported.

``from haptic_bus.errors import DriveError, ParameterError, ...`` works for every class of the
tree; :class:`~haptic_bus.control.gate.GateRefusal` (exit 1) and
:class:`~haptic_bus.control.supervisor.AssumptionBroken` (exit 3) live beside the code that raises them.
"""

from drives.errors import (
    BusConfigError,
    DriveError,
    DriveFault,
    DriveProtocolError,
    DriveStateError,
    DriveTimeout,
    HapticBusError,
    ModbusExceptionError,
    ModbusLinkLost,
    ParameterError,
    PdoLengthError,
    ScalingConflict,
    ScalingObjectError,
    SdoAbortError,
    UnsupportedModeError,
)

__all__ = [
    "BusConfigError",
    "DriveError",
    "DriveFault",
    "DriveProtocolError",
    "DriveStateError",
    "DriveTimeout",
    "HapticBusError",
    "ModbusExceptionError",
    "ModbusLinkLost",
    "ParameterError",
    "PdoLengthError",
    "ScalingConflict",
    "ScalingObjectError",
    "SdoAbortError",
    "UnsupportedModeError",
]
