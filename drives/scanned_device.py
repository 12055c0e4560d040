"""What both bus scans (:mod:`drives.canopen.scan`, :mod:`drives.modbus.scan`) tell of a device
they found, and how they show it: which protocol, what the device is (each scan's own fields),
whether it is a CiA-402 drive, its CiA-402 objects 0x6502 (supported drive modes), the
statusword 0x6041 and the error code 0x603F (None: not read), and notes on what could not be read."""

from __future__ import annotations

from typing import Any, ClassVar

from drives.cia301 import describe_emcy_code
from drives.cia402 import cst_announced
from drives.fault_reset import state_text

_SHOWN = ("supported_drive_modes", "cst_supported", "statusword", "cia402_state", "error_code")  # in this order


class ScannedDevice:
    """A device a scan found; the base of the scans' result dataclasses, which declare the fields
    annotated here and say what the device is in :meth:`identity_dict`."""

    protocol: ClassVar[str]
    supported_drive_modes: int | None  # 0x6502
    statusword: int | None  # 0x6041
    error_code: int | None  # 0x603F
    notes: tuple[str, ...]

    @property
    def cia402(self) -> bool:
        """True for a CiA-402 drive."""
        raise NotImplementedError

    @property
    def cst_supported(self) -> bool | None:
        """0x6502 announces cyclic synchronous torque; None where 0x6502 was not read."""
        return cst_announced(self.supported_drive_modes)

    @property
    def cia402_state(self) -> str | None:
        """The CiA-402 state 0x6041 shows ("FAULT", ...); None where 0x6041 was not read."""
        return None if self.statusword is None else state_text(self.statusword)

    def identity_dict(self) -> dict[str, Any]:
        """What the device is and where, JSON-ready (each scan's own fields)."""
        raise NotImplementedError

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: numbers as numbers, None as null, the readings also in words."""
        return {"protocol": self.protocol, **self.identity_dict(), "cia402": self.cia402,
                **{name: getattr(self, name) for name in _SHOWN},
                "error_code_text": None if self.error_code is None else describe_emcy_code(self.error_code),
                "notes": list(self.notes)}
