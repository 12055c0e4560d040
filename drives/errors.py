"""The root of every error the distribution raises on purpose, and the errors of ``drives``.

``drives`` is the bottom layer and imports nothing of ours, so the root lives here and
``haptic_bus`` derives its own errors from it.  Every error carries its data from construction
(the way canopen's ``SdoAbortedError`` carries its code).  A silence is a :class:`DriveTimeout`,
which is also the builtin :class:`TimeoutError` (as python-can's ``CanTimeoutError`` is); invalid
input is a :class:`ParameterError`, also a :class:`ValueError`.  The tree is drawn once, in
:mod:`haptic_bus.errors`, which is also where users import every class from.
"""

from __future__ import annotations

from typing import Any


class HapticBusError(Exception):
    """Base class of every error the distribution (``haptic_bus``, ``drives``, ``sim_drive``) raises on purpose."""


class ParameterError(HapticBusError, ValueError):
    """A value outside its allowed range (or not a number at all), found before anything moved
    (exit 2): a parameter of the analysis, a profile field, a bus setting, a node id.

    ``name``, ``value`` and ``allowed`` are given at construction, so a commissioning engineer can
    act on the message without reading code; ``context`` says where it was read (``profile PATH``).

    One rule for a value that is not there: ``value`` None means nothing was given (a flag not on the
    command line, a key not in the profile, a keyword left at None), and the message says
    ``NAME is missing; allowed: ...``, never ``NAME = None``.  A reader that meets an explicit null
    (run.json's JSON ``null``) says so in its own words (:mod:`haptic_bus.app.run_folder`).
    """

    def __init__(self, name: str, value: object, allowed: str, context: str = "") -> None:
        self.name = name
        self.value = value
        self.allowed = allowed
        self.context = context
        said = "is missing" if value is None else f"= {value!r} is invalid"
        self.detail = f"{name} {said}; allowed: {allowed}"  # the message without its context
        super().__init__(f"{context}: {self.detail}" if context else self.detail)


class DriveError(HapticBusError):
    """A drive or its bus failed (a bus configuration python-can cannot open, a mode or scaling the drive
    cannot give, a node that is no controller); ``node`` names the drive (node id or unit id)."""

    def __init__(self, node: str, message: str) -> None:
        self.node = node
        self.message = message
        super().__init__(f"{node}: {message}")


class DriveTimeout(DriveError, TimeoutError):
    """The drive did not answer within its timeout (silent node, wrong node id)."""


class ModbusLinkLost(DriveError):
    """The link to the drive is gone (dropped connection, or closed after a timeout because a late
    answer could not be told from the next one): down until the master reconnects (the Modbus
    master's ``reconnect()``; a command line's next run)."""


class DriveFault(DriveError):
    """The drive is in FAULT or does not follow its state machine: it reported a fault (EMCY, fault
    bit, heartbeat loss; ``code`` its error code, or None), or a CiA-402 step stalled (``state``
    where it stuck: a :class:`~drives.cia402.State`, or None for a mode that is not shown)."""

    def __init__(self, node: str, message: str, code: int | None = None, state: Any = None) -> None:
        self.code = code
        self.state = state
        super().__init__(node, message)


class DriveProtocolError(DriveError):
    """The drive's answer cannot be used: it refused the request (a :class:`DriveRefusal`), or it
    answered with something the protocol forbids (a value no drive may report, a value that does
    not read back), or a frame could not be used (a PDO of the wrong length)."""


class DriveRefusal(DriveProtocolError):
    """The drive refused one request: an SDO abort (``code`` the CiA 301 abort code, 0x05030000 and
    up) or a Modbus exception response (``code`` the exception code, 0x01..0x0B; an object the
    register map does not hold is refused before asking, with 0x02 ILLEGAL DATA ADDRESS, what the
    drive would answer); ``index`` and ``subindex`` name the object where one was asked."""

    def __init__(self, node: str, message: str, code: int, index: int | None = None, subindex: int = 0) -> None:
        self.code = code
        self.index = index
        self.subindex = subindex
        super().__init__(node, message)
