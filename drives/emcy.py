"""CANopen emergency (EMCY) error codes of CiA-301 and CiA-402, decoded to text.

An EMCY frame is ``code`` (UNSIGNED16), ``error register`` (0x1001, UNSIGNED8) and five
manufacturer bytes.  :func:`describe_emcy_code` names the most specific known class.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

_EMCY = struct.Struct("<HB")

# Exact codes (CiA-301 table 21 and CiA-402-2 annex), most specific first when looked up.
EMCY_CODES: dict[int, str] = {
    0x0000: "Error reset or no error",
    0x1000: "Generic error",
    0x2000: "Current",
    0x2100: "Current, device input side",
    0x2200: "Current inside the device",
    0x2300: "Current, device output side",
    0x2310: "Continuous over-current",
    0x2320: "Short circuit / earth leakage",
    0x2330: "Earth leakage",
    0x2340: "Short circuit",
    0x3000: "Voltage",
    0x3100: "Mains voltage",
    0x3200: "Voltage inside the device",
    0x3210: "DC link over-voltage",
    0x3220: "DC link under-voltage",
    0x3300: "Output voltage",
    0x4000: "Temperature",
    0x4100: "Ambient temperature",
    0x4200: "Device temperature",
    0x4210: "Excess temperature device",
    0x4300: "Drive temperature",
    0x4310: "Excess temperature drive",
    0x5000: "Device hardware",
    0x5500: "Data storage",
    0x5510: "Working memory",
    0x5520: "Program memory",
    0x5530: "Non-volatile data memory",
    0x6000: "Device software",
    0x6100: "Internal software",
    0x6200: "User software",
    0x6300: "Data set",
    0x7000: "Additional modules",
    0x7300: "Sensor",
    0x7305: "Incremental sensor 1 fault",
    0x8000: "Monitoring",
    0x8100: "Communication",
    0x8110: "CAN overrun (objects lost)",
    0x8120: "CAN in error passive mode",
    0x8130: "Life guard error or heartbeat error",
    0x8140: "Recovered from bus off",
    0x8150: "CAN-ID collision",
    0x8200: "Protocol error",
    0x8210: "PDO not processed due to length error",
    0x8220: "PDO length exceeded",
    0x8230: "DAM MPDO not processed, destination object not available",
    0x8240: "Unexpected SYNC data length",
    0x8250: "RPDO timeout",
    0x8300: "Torque control",
    0x8311: "Excess torque",
    0x8400: "Velocity speed controller",
    0x8500: "Position controller",
    0x8600: "Positioning controller",
    0x8611: "Following error",
    0x9000: "External error",
    0xF000: "Additional functions",
    0xFF00: "Device specific (manufacturer)",
}


def describe_emcy_code(code: int) -> str:
    """The most specific CiA-301/402 description of an EMCY error code."""
    for mask in (0xFFFF, 0xFFF0, 0xFF00, 0xF000):
        text = EMCY_CODES.get(code & mask)
        if text is not None:
            if mask == 0xFF00 and code & 0xFF00 == 0xFF00 and code != 0xFF00:
                return f"{text}, code 0x{code & 0xFF:02X}"
            return text
    return "Unknown error code"


@dataclass(frozen=True, slots=True)
class EmcyMessage:
    """One received EMCY: error code, error register (0x1001), manufacturer bytes, receive time (s)."""

    code: int
    register: int
    data: bytes
    received_at: float

    @property
    def is_reset(self) -> bool:
        """True for 'error reset or no error' (code 0x00xx)."""
        return self.code & 0xFF00 == 0

    @property
    def description(self) -> str:
        """Readable description of the code."""
        return describe_emcy_code(self.code)

    def __str__(self) -> str:
        return f"EMCY 0x{self.code:04X} ({self.description}), error register 0x{self.register:02X}"


def decode_emcy(data: bytes | bytearray, received_at: float = 0.0) -> EmcyMessage | None:
    """Decode an EMCY frame's data; None for a frame too short to carry code and register."""
    if len(data) < _EMCY.size:
        return None
    code, register = _EMCY.unpack_from(data)
    return EmcyMessage(code, register, bytes(data[3:8]), received_at)
