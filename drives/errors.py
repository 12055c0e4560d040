"""The errors of ``drives``, rooted at :class:`FieldbusError` (``drives`` imports nothing of ours).

Every error raised on purpose carries its data from construction (the way canopen's
``SdoAbortedError`` carries its code).  A silence is a :class:`DriveTimeout`, which is also the
builtin :class:`TimeoutError` (as python-can's ``CanTimeoutError`` is); an invalid argument to drive
code is a :class:`DriveArgumentError`, also an :class:`InvalidInput` (a :class:`ValueError`).  The tree of the whole
distribution, this one and ``haptic_bus``' beside it, is drawn once, in :mod:`haptic_bus.errors`,
which is also where users import every class from.
"""

from __future__ import annotations

from typing import Any


class FieldbusError(Exception):
    """Base class of every error ``drives`` raises on purpose."""


class InvalidInput(ValueError):
    """A value outside its allowed range (or not a number at all): the shape every invalid-input
    error shares, whichever root it belongs to (exit 2).

    ``name``, ``value`` and ``allowed`` are given at construction, so a commissioning engineer can
    act on the message without reading code; ``context`` says where it was read.
    """

    def __init__(self, name: str, value: object, allowed: str, context: str = "") -> None:
        self.name = name
        self.value = value
        self.allowed = allowed
        self.context = context
        where = f"{context}: " if context else ""
        super().__init__(f"{where}{name} = {value!r} is invalid; allowed: {allowed}")


class DriveArgumentError(FieldbusError, InvalidInput):
    """An argument to drive code is outside its allowed range (a bus setting, a node id, a value to
    write), found before the bus is touched."""


class DriveError(FieldbusError):
    """A drive or its bus failed; ``node`` names the drive (node id or unit id)."""

    def __init__(self, node: str, message: str) -> None:
        self.node = node
        self.message = message
        super().__init__(f"{node}: {message}")


class BusConfigError(DriveError):
    """No usable CAN bus configuration (no interface selected, unknown interface, open failed)."""


class DriveTimeout(DriveError, TimeoutError):
    """The drive did not answer within its timeout (silent node, wrong node id, lost link)."""


class DriveStateError(DriveTimeout):
    """The CiA-402 state machine did not reach the expected state in time; ``state`` is where it stuck."""

    def __init__(self, node: str, message: str, state: Any) -> None:
        self.state = state
        super().__init__(node, message)


class ModbusLinkLost(DriveTimeout):
    """The link to the drive is gone (dropped connection, or closed after a timeout); call reconnect()."""


class DriveFault(DriveError):
    """The drive reported a fault (EMCY, fault bit, heartbeat loss); ``code`` is its error code."""

    def __init__(self, node: str, message: str, code: int | None = None) -> None:
        self.code = code
        super().__init__(node, message)


class DriveProtocolError(DriveError):
    """The drive answered with something the protocol forbids, or a frame could not be used."""


class SdoAbortError(DriveProtocolError):
    """The drive aborted an SDO transfer of ``index:subindex`` with ``abort_code`` (CiA 301)."""

    def __init__(self, node: str, message: str, abort_code: int, index: int, subindex: int) -> None:
        self.abort_code = abort_code
        self.index = index
        self.subindex = subindex
        super().__init__(node, message)


class ObjectAbsent(DriveProtocolError):
    """The drive has no object ``index:subindex`` where it was asked for (a register map without it);
    an SDO abort saying the same stays an :class:`SdoAbortError`."""

    def __init__(self, node: str, message: str, index: int, subindex: int = 0) -> None:
        self.index = index
        self.subindex = subindex
        super().__init__(node, message)


class ModbusExceptionError(DriveProtocolError):
    """The drive answered a Modbus request with exception ``exception_code`` (0x01..0x0B)."""

    def __init__(self, node: str, message: str, exception_code: int) -> None:
        self.exception_code = exception_code
        super().__init__(node, message)


class PdoLengthError(DriveProtocolError):
    """A PDO frame's data length does not match its mapping (the frame must be dropped)."""

    def __init__(self, name: str, expected: int, got: int) -> None:
        self.expected = expected
        self.got = got
        super().__init__(name, f"frame of {got} bytes, mapping needs exactly {expected}")


class UnsupportedModeError(DriveError):
    """The drive does not announce the requested mode of operation in 0x6502."""


class ScalingConflict(DriveError):
    """Two sources of one scaling factor (the drive's objects, an EDS-named object, the caller's
    profile) disagree by more than the rounding of the drive's objects allows.

    ``field`` is the :class:`~drives.base.DriveScaling` field; ``first`` and ``second`` are
    ``(value, source)`` pairs, the one in use first; ``relative`` their relative difference and
    ``tolerance`` the relative rounding allowed.
    """

    def __init__(self, node: str, field: str, first: tuple[float | int, str], second: tuple[float | int, str],
                 relative: float, tolerance: float, unit: str = "") -> None:
        self.field = field
        self.first = first
        self.second = second
        self.relative = relative
        self.tolerance = tolerance
        suffix = f" {unit}" if unit else ""
        super().__init__(
            node,
            f"scaling conflict for {field}: {first[0]:.12g}{suffix} from {first[1]} but {second[0]:.12g}{suffix} from "
            f"{second[1]} (relative difference {relative:.3g}, more than the {tolerance:.3g} the objects' rounding "
            f"allows); correct the profile or the drive's objects, the drive is not enabled",
        )


class ScalingObjectError(DriveProtocolError):
    """A CiA-402 factor-group or SI-unit object holds a value no drive may report (a zero
    revolution count, an unknown unit code): ``index``, ``subindex``, ``value``, ``allowed``."""

    def __init__(self, node: str, index: int, subindex: int, name: str, value: int, allowed: str) -> None:
        self.index = index
        self.subindex = subindex
        self.value = value
        self.allowed = allowed
        super().__init__(node, f"0x{index:04X}:{subindex:02X} ({name}) = {value} (0x{value:08X}) is invalid; allowed: {allowed}")
