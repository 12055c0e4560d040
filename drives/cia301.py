"""CiA-301 (CANopen application layer) tables: NMT, COB-IDs, SDO abort codes, EMCY codes.

Pure data and pure functions, shared by the CANopen master (:mod:`drives.canopen`) and the
simulated slave (``sim_drive.canopen``); nothing here touches a bus.
"""

from __future__ import annotations

import enum

# --------------------------------------------------------------------------- NMT (CiA 301 7.2.8)


class NmtCommand(enum.IntEnum):
    """NMT command specifiers (first byte of a COB-ID 0x000 frame)."""

    START = 0x01
    STOP = 0x02
    ENTER_PRE_OPERATIONAL = 0x80
    RESET_NODE = 0x81
    RESET_COMMUNICATION = 0x82


class NmtState(enum.IntEnum):
    """NMT states as a heartbeat carries them (bit 7 is the node-guarding toggle)."""

    BOOT_UP = 0x00
    STOPPED = 0x04
    OPERATIONAL = 0x05
    PRE_OPERATIONAL = 0x7F

    @property
    def label(self) -> str:
        """The state's CiA-301 name ("PRE-OPERATIONAL", ...)."""
        return self.name.replace("_", "-")


def nmt_state_name(code: int) -> str:
    """The name of a heartbeat state byte, or ``"unknown state 0x.."``."""
    try:
        return NmtState(code & 0x7F).label
    except ValueError:
        return f"unknown state 0x{code:02X}"


# --------------------------------------------------------------------------- COB-IDs (7.3.3, 7.3.5)

NMT_COB_ID = 0x000
SYNC_COB_ID = 0x080
EMCY_BASE = 0x080  # + node id
TPDO_BASES = (0x180, 0x280, 0x380, 0x480)  # + node id, TPDO1..4
RPDO_BASES = (0x200, 0x300, 0x400, 0x500)  # + node id, RPDO1..4
SDO_TX_BASE = 0x580  # server -> client, + node id
SDO_RX_BASE = 0x600  # client -> server, + node id
HEARTBEAT_BASE = 0x700  # + node id
COB_ID_MASK = 0x7FF
NODE_ID_RANGE = (1, 127)
NODE_IDS = f"CANopen node ids {NODE_ID_RANGE[0]}..{NODE_ID_RANGE[1]}"  # what every refusal of a node id allows

COB_ID_INVALID = 1 << 31  # PDO / EMCY / SYNC-consumer COB-ID: the object does not exist (not valid)
COB_ID_NO_RTR = 1 << 30  # PDO: remote transmission not allowed
COB_ID_SYNC_GENERATOR = 1 << 30  # 0x1005: this node produces the SYNC
COB_ID_29_BIT = 1 << 29  # extended (29-bit) frame

# CAN-IDs no PDO, EMCY or SYNC may use (CiA 301 table 3, "restricted CAN-IDs").
RESTRICTED_COB_IDS: tuple[tuple[int, int], ...] = (
    (0x000, 0x000),
    (0x001, 0x07F),
    (0x101, 0x180),
    (0x581, 0x5FF),
    (0x601, 0x67F),
    (0x6E0, 0x6FF),
    (0x701, 0x77F),
    (0x780, 0x7FF),
)


def is_restricted_cob_id(cob_id: int) -> bool:
    """True for an 11-bit CAN-ID that CiA 301 reserves (NMT, SDO, heartbeat, reserved ranges)."""
    return any(low <= cob_id <= high for low, high in RESTRICTED_COB_IDS)


# --------------------------------------------------------------------------- objects

DEVICE_TYPE = 0x1000
ERROR_REGISTER = 0x1001
PRE_DEFINED_ERROR_FIELD = 0x1003  # sub 0: number of errors; sub n: error code (bits 0-15), manufacturer info (16-31)
COB_ID_SYNC = 0x1005
COMMUNICATION_CYCLE_PERIOD = 0x1006  # us
SYNCHRONOUS_WINDOW_LENGTH = 0x1007  # us
COB_ID_EMCY = 0x1014
CONSUMER_HEARTBEAT_TIME = 0x1016  # sub n: node id << 16 | time ms
PRODUCER_HEARTBEAT_TIME = 0x1017  # ms
IDENTITY = 0x1018  # sub 1 vendor, 2 product, 3 revision, 4 serial
RPDO_COMMUNICATION, RPDO_MAPPING = 0x1400, 0x1600
TPDO_COMMUNICATION, TPDO_MAPPING = 0x1800, 0x1A00
PDO_COB_ID, PDO_TRANSMISSION_TYPE, PDO_INHIBIT_TIME, PDO_EVENT_TIMER = 1, 2, 3, 5  # sub-indices
TRANSMISSION_SYNCHRONOUS_EVERY_SYNC = 1
DEVICE_PROFILE_402 = 402  # 0x1000 low word of a CiA-402 drive

# 0x1001 error register (CiA 301 7.5.2.2): what each bit means, bit 0 first.
ERROR_REGISTER_BITS = ("generic", "current", "voltage", "temperature", "communication", "device profile specific",
                       "reserved bit 6", "manufacturer specific")
ERROR_REGISTER_GENERIC = 1 << ERROR_REGISTER_BITS.index("generic")
ERROR_REGISTER_COMMUNICATION = 1 << ERROR_REGISTER_BITS.index("communication")


def describe_error_register(value: int) -> str:
    """The 0x1001 bits set, in words (``"generic, communication"``), or ``"no error"``."""
    return ", ".join(name for bit, name in enumerate(ERROR_REGISTER_BITS) if value >> bit & 1) or "no error"

COMMUNICATION_OBJECT_NAMES: dict[int, str] = {
    0x1000: "Device type",
    0x1001: "Error register",
    0x1003: "Pre-defined error field",
    0x1005: "COB-ID SYNC message",
    0x1006: "Communication cycle period",
    0x1007: "Synchronous window length",
    0x1014: "COB-ID EMCY",
    0x1016: "Consumer heartbeat time",
    0x1017: "Producer heartbeat time",
    0x1018: "Identity object",
    **{0x1400 + n: f"RPDO{n + 1} communication parameter" for n in range(4)},
    **{0x1600 + n: f"RPDO{n + 1} mapping parameter" for n in range(4)},
    **{0x1800 + n: f"TPDO{n + 1} communication parameter" for n in range(4)},
    **{0x1A00 + n: f"TPDO{n + 1} mapping parameter" for n in range(4)},
}

# --------------------------------------------------------------------------- SDO abort codes (7.2.4.3.17)


class SdoAbort(enum.IntEnum):
    """The SDO abort codes of CiA 301, each with its text (:attr:`text`)."""

    text: str

    def __new__(cls, code: int, text: str) -> SdoAbort:
        member = int.__new__(cls, code)
        member._value_ = code
        member.text = text
        return member

    TOGGLE_BIT = 0x05030000, "Toggle bit not alternated"
    TIMEOUT = 0x05040000, "SDO protocol timed out"
    UNKNOWN_COMMAND = 0x05040001, "Client/server command specifier not valid or unknown"
    BLOCK_SIZE = 0x05040002, "Invalid block size"
    SEQUENCE_NUMBER = 0x05040003, "Invalid sequence number"
    CRC = 0x05040004, "CRC error"
    OUT_OF_MEMORY = 0x05040005, "Out of memory"
    UNSUPPORTED_ACCESS = 0x06010000, "Unsupported access to an object"
    WRITE_ONLY = 0x06010001, "Attempt to read a write only object"
    READ_ONLY = 0x06010002, "Attempt to write a read only object"
    NO_OBJECT = 0x06020000, "Object does not exist in the object dictionary"
    NOT_MAPPABLE = 0x06040041, "Object cannot be mapped to the PDO"
    PDO_LENGTH_EXCEEDED = 0x06040042, "The number and length of the objects to be mapped would exceed PDO length"
    PARAMETER_INCOMPATIBLE = 0x06040043, "General parameter incompatibility reason"
    INTERNAL_INCOMPATIBLE = 0x06040047, "General internal incompatibility in the device"
    HARDWARE = 0x06060000, "Access failed due to a hardware error"
    LENGTH_MISMATCH = 0x06070010, "Data type does not match, length of service parameter does not match"
    LENGTH_TOO_HIGH = 0x06070012, "Data type does not match, length of service parameter too high"
    LENGTH_TOO_LOW = 0x06070013, "Data type does not match, length of service parameter too low"
    NO_SUBINDEX = 0x06090011, "Sub-index does not exist"
    VALUE_RANGE = 0x06090030, "Invalid value for parameter (download only)"
    VALUE_TOO_HIGH = 0x06090031, "Value of parameter written too high (download only)"
    VALUE_TOO_LOW = 0x06090032, "Value of parameter written too low (download only)"
    MAX_BELOW_MIN = 0x06090036, "Maximum value is less than minimum value"
    RESOURCE = 0x060A0023, "Resource not available: SDO connection"
    GENERAL = 0x08000000, "General error"
    NOT_STORED = 0x08000020, "Data cannot be transferred or stored to the application"
    LOCAL_CONTROL = 0x08000021, "Data cannot be transferred or stored to the application because of local control"
    DEVICE_STATE = 0x08000022, "Data cannot be transferred or stored to the application because of the present device state"
    NO_DICTIONARY = 0x08000023, "Object dictionary dynamic generation fails or no object dictionary is present"
    NO_DATA = 0x08000024, "No data available"


def sdo_abort_text(code: int) -> str:
    """The CiA-301 text of an SDO abort code."""
    return next((abort.text for abort in SdoAbort if abort == code), "unknown abort code")


# --------------------------------------------------------------------------- EMCY (7.2.7)

EMCY_LENGTH = 8  # error code (2), error register (1), manufacturer-specific (5)


class EmcyCode(enum.IntEnum):
    """EMCY error codes this project produces or acts on (their texts, and every other code's, are in :data:`EMCY_CODES`)."""

    NO_ERROR = 0x0000
    GENERIC = 0x1000
    COMMUNICATION = 0x8100
    HEARTBEAT = 0x8130
    PROTOCOL = 0x8200
    PDO_LENGTH = 0x8210
    PDO_TOO_LONG = 0x8220
    SYNC_LENGTH = 0x8240
    RPDO_TIMEOUT = 0x8250


# Exact codes (CiA-301 table 21 and CiA-402-2 annex); looked up most specific first.
EMCY_CODES: dict[int, str] = {
    EmcyCode.NO_ERROR: "Error reset or no error",
    EmcyCode.GENERIC: "Generic error",
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
    EmcyCode.COMMUNICATION: "Communication",
    0x8110: "CAN overrun (objects lost)",
    0x8120: "CAN in error passive mode",
    EmcyCode.HEARTBEAT: "Life guard error or heartbeat error",
    0x8140: "Recovered from bus off",
    0x8150: "CAN-ID collision",
    EmcyCode.PROTOCOL: "Protocol error",
    EmcyCode.PDO_LENGTH: "PDO not processed due to length error",
    EmcyCode.PDO_TOO_LONG: "PDO length exceeded",
    0x8230: "DAM MPDO not processed, destination object not available",
    EmcyCode.SYNC_LENGTH: "Unexpected SYNC data length",
    EmcyCode.RPDO_TIMEOUT: "RPDO timeout",
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
