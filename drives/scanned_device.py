"""What both bus scans (:mod:`drives.canopen.scan`, :mod:`drives.modbus.scan`) read of a CiA-402
drive's objects, and how they show it: 0x6502 (supported drive modes), the statusword 0x6041 and
the error code 0x603F (None: not read)."""

from __future__ import annotations

from typing import Any

from drives.cia301 import describe_emcy_code
from drives.cia402 import cst_announced
from drives.fault_reset import state_text


class DriveReadings:
    """The CiA-402 objects a scan read of one device; a base of the scans' result dataclasses,
    which declare the three fields."""

    supported_drive_modes: int | None  # 0x6502
    statusword: int | None  # 0x6041
    error_code: int | None  # 0x603F

    @property
    def cst_supported(self) -> bool | None:
        """0x6502 announces cyclic synchronous torque; None where 0x6502 was not read."""
        return cst_announced(self.supported_drive_modes)

    @property
    def cia402_state(self) -> str | None:
        """The CiA-402 state 0x6041 shows ("FAULT", ...); None where 0x6041 was not read."""
        return None if self.statusword is None else state_text(self.statusword)

    def readings_dict(self) -> dict[str, Any]:
        """The readings JSON-ready (numbers as numbers, None as null), with their meaning in words."""
        return {
            "supported_drive_modes": self.supported_drive_modes,
            "cst_supported": self.cst_supported,
            "statusword": self.statusword,
            "cia402_state": self.cia402_state,
            "error_code": self.error_code,
            "error_code_text": None if self.error_code is None else describe_emcy_code(self.error_code),
        }
