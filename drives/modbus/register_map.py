"""The Modbus register map of the CiA-402 torque drive, and its pure encode/decode functions.

Shared by the master (:mod:`drives.modbus.drive`) and the simulated server
(:mod:`sim_drive.modbus`).  Every object lives in the **holding registers** (function
codes 03 read, 06/16 write, 23 read/write), addressed from 0 (protocol addresses; a "4xxxx"
register number is address + 40001).  Within a register the bytes are big-endian, as Modbus
says; a 32-bit value occupies two consecutive registers whose order is the map's
``word_order``: ``"big"`` = high word first (at the lower address), ``"little"`` = low word
first.  64-bit floats (scaling, simulator extras) occupy four registers in the same order.

========  =====  ======  ======  =====  ================================================
address   regs   object  type    acc.   meaning
========  =====  ======  ======  =====  ================================================
**cyclic input block** (one read per cycle; read 3 registers without position)
0x0000    1      0x6041  U16     ro     statusword
0x0001    2      0x606C  I32     ro     velocity actual value (velocity units)
0x0003    2      0x6064  I32     ro     position actual value (increments)
**cyclic output block** (one write per cycle; a write of the whole block closes the cycle)
0x0010    1      0x6040  U16     rw     controlword
0x0011    1      0x6071  I16     rw     target torque (per mille of rated torque)
**acyclic CiA-402 objects**
0x0020    1      0x6060  I8      rw     modes of operation (sign-extended into 16 bits)
0x0021    1      0x6061  I8      ro     modes of operation display
0x0022    1      0x6072  U16     rw     max torque (per mille of rated torque)
0x0023    1      0x6077  I16     ro     torque actual value (per mille of rated torque)
0x0024    2      0x6076  U32     rw     motor rated torque (mN m)
0x0026    2      0x6502  U32     ro     supported drive modes
0x0028    1      0x603F  U16     ro     error code
0x0029    1      0x605A  I16     rw     quick stop option code
0x002A    1      --      U16     rw     communication watchdog, ms (0 = off): no valid request for
                                        that long with the power stage on -> 0x6007's reaction
0x002B    1      0x6007  I16     rw     abort connection option code (1 fault, 2 disable voltage, ...)
0x0030    2      --      U32     ro     map identity 0x48420402 ("HB", 402): checks the word order
**manufacturer scaling** (REAL64, SI units)
0x0040    4      --      F64     ro     velocity per count (m/s per 0x606C unit)
0x0044    4      --      F64     ro     position per count (m per 0x6064 increment)
0x0048    4      --      F64     ro     force per torque (N at the handle per N m)
**simulated drive only** (a real drive answers "illegal address" here)
0x0050    1      --      U16     ro     loop timing (0 cia402, 1 ideal, 2 reception)
0x0051    2      --      U32     ro     cycle count (closed cycles + 1, like the SYNC count)
0x0054    4      --      F64     ro     virtual time (s)
0x0058    4      --      F64     ro     operator energy (J)
0x005C    4      --      F64     ro     wall energy (J)
0x0060    4      --      F64     ro     reception delay delta (samples, in [0, 1): reception timing)
========  =====  ======  ======  =====  ================================================

Any other address is unmapped (exception 0x02, illegal data address), and so is an access
that covers only one half (or part) of a multi-register value.  A value outside the object's
range is refused with exception 0x03 (illegal data value); a write to a read-only register
with 0x02.  The blocks are contiguous so that one cycle is one read of the input block plus
one write of the output block, or a single FC23 request (write first, then read, as the
Modbus specification orders it).
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from drives.cia402 import (
    ABORT_CONNECTION_OPTION_CODE,
    CONTROLWORD,
    ERROR_CODE,
    MAX_TORQUE,
    MODES_OF_OPERATION,
    MODES_OF_OPERATION_DISPLAY,
    MOTOR_RATED_TORQUE,
    POSITION_ACTUAL,
    QUICK_STOP_OPTION_CODE,
    STATUSWORD,
    SUPPORTED_DRIVE_MODES,
    TARGET_TORQUE,
    TORQUE_ACTUAL,
    VELOCITY_ACTUAL,
    DataType,
    ObjectSpec,
)

UNIT_ID_RANGE = (1, 247)  # Modbus unit ids that answer: 0 is broadcast (no answer), 248..255 reserved
UNIT_IDS = f"Modbus unit ids {UNIT_ID_RANGE[0]}..{UNIT_ID_RANGE[1]}"  # what every refusal of a unit id allows

__all__ = [
    "EXCEPTION_NAMES",
    "INPUT_BLOCK",
    "INPUT_BLOCK_COUNT",
    "INPUT_BLOCK_COUNT_NO_POSITION",
    "MAP_IDENTITY",
    "OUTPUT_BLOCK",
    "OUTPUT_BLOCK_COUNT",
    "REGISTERS",
    "REGISTER_BY_NAME",
    "WORD_ORDERS",
    "InputBlockCodec",
    "RegisterSpec",
    "decode_value",
    "describe_range",
    "encode_value",
    "exception_name",
    "register_at",
    "register_for_object",
    "word_order_of",
]

WORD_ORDERS = ("big", "little")
MAP_IDENTITY = 0x48420402

INPUT_BLOCK = 0x0000
INPUT_BLOCK_COUNT = 5  # statusword, velocity (2), position (2)
INPUT_BLOCK_COUNT_NO_POSITION = 3
OUTPUT_BLOCK = 0x0010
OUTPUT_BLOCK_COUNT = 2  # controlword, target torque

# Value kinds: (registers, struct format of the value as big-endian bytes in "big" word order)
_KINDS: dict[str, tuple[int, str]] = {
    "u16": (1, ">H"),
    "i16": (1, ">h"),
    "i8": (1, ">h"),  # an INTEGER8 object sign-extended into one register
    "u32": (2, ">I"),
    "i32": (2, ">i"),
    "f64": (4, ">d"),
}
_INT_RANGES = {
    "u16": (0, 0xFFFF),
    "i16": (-0x8000, 0x7FFF),
    "i8": (-0x80, 0x7F),
    "u32": (0, 0xFFFFFFFF),
    "i32": (-0x80000000, 0x7FFFFFFF),
}


@dataclass(frozen=True)
class RegisterSpec:
    """One mapped value: first address, kind (u16 i16 i8 u32 i32 f64), access, name, CiA-402 object."""

    address: int
    name: str
    kind: str
    access: str
    obj: ObjectSpec | None = None
    unit: str = ""

    @property
    def count(self) -> int:
        """Number of 16-bit registers the value occupies."""
        return _KINDS[self.kind][0]

    @property
    def end(self) -> int:
        """One past the last address."""
        return self.address + self.count

    @property
    def range(self) -> tuple[int, int] | None:
        """Smallest and largest integer value, None for a float."""
        return _INT_RANGES.get(self.kind)

    @property
    def label(self) -> str:
        """``"0x0011 (0x6071 Target torque)"``: the address and what it maps to."""
        what = f"0x{self.obj.index:04X} {self.obj.name}" if self.obj is not None else self.name
        return f"0x{self.address:04X} ({what})"


_KIND_OF_TYPE: dict[DataType, str] = {
    DataType.INTEGER8: "i8",
    DataType.INTEGER16: "i16",
    DataType.INTEGER32: "i32",
    DataType.UNSIGNED16: "u16",
    DataType.UNSIGNED32: "u32",
}


@dataclass(frozen=True)
class _Extra:
    """A mapped value that is no CiA-402 object: its name, kind, access and unit."""

    name: str
    kind: str
    access: str = "ro"
    unit: str = ""


def _contiguous(address: int, *values: ObjectSpec | _Extra) -> tuple[RegisterSpec, ...]:
    """``values`` laid out one after another from ``address``, each taking its kind's registers
    (an object's kind is its CiA-402 data type)."""
    specs: list[RegisterSpec] = []
    for value in values:
        if isinstance(value, ObjectSpec):
            spec = RegisterSpec(address, value.name.lower().replace(" ", "_"), _KIND_OF_TYPE[value.data_type],
                                value.access, value, value.unit)
        else:
            spec = RegisterSpec(address, value.name, value.kind, value.access, unit=value.unit)
        specs.append(spec)
        address = spec.end
    return tuple(specs)


# The module's table, block by block.
REGISTERS: tuple[RegisterSpec, ...] = (
    *_contiguous(INPUT_BLOCK, STATUSWORD, VELOCITY_ACTUAL, POSITION_ACTUAL),
    *_contiguous(OUTPUT_BLOCK, CONTROLWORD, TARGET_TORQUE),
    *_contiguous(0x0020, MODES_OF_OPERATION, MODES_OF_OPERATION_DISPLAY, MAX_TORQUE, TORQUE_ACTUAL, MOTOR_RATED_TORQUE,
                 SUPPORTED_DRIVE_MODES, ERROR_CODE, QUICK_STOP_OPTION_CODE, _Extra("comm_watchdog_ms", "u16", "rw", "ms"),
                 ABORT_CONNECTION_OPTION_CODE),
    *_contiguous(0x0030, _Extra("map_identity", "u32")),
    *_contiguous(0x0040, _Extra("velocity_per_count", "f64", unit="m/s"), _Extra("position_per_count", "f64", unit="m"),
                 _Extra("force_per_torque", "f64", unit="N/(N m)")),
    *_contiguous(0x0050, _Extra("sim_timing", "u16"), _Extra("sim_cycle_count", "u32")),
    *_contiguous(0x0054, _Extra("sim_time", "f64", unit="s"), _Extra("sim_operator_energy", "f64", unit="J"),
                 _Extra("sim_wall_energy", "f64", unit="J"), _Extra("sim_reception_delay", "f64", unit="samples")),
)
REGISTER_BY_NAME: dict[str, RegisterSpec] = {spec.name: spec for spec in REGISTERS}
_BY_OBJECT: dict[int, RegisterSpec] = {spec.obj.index: spec for spec in REGISTERS if spec.obj is not None}
_BY_ADDRESS: dict[int, RegisterSpec] = {a: spec for spec in REGISTERS for a in range(spec.address, spec.end)}

SIM_TIMING_CODES = {"cia402": 0, "ideal": 1, "reception": 2}


def register_for_object(obj: ObjectSpec | int) -> RegisterSpec:
    """The register of CiA-402 object ``obj`` (ObjectSpec or index); KeyError if unmapped."""
    index = obj if isinstance(obj, int) else obj.index
    try:
        return _BY_OBJECT[index]
    except KeyError:
        raise KeyError(f"object 0x{index:04X} is not in the Modbus register map") from None


def register_at(address: int) -> RegisterSpec | None:
    """The mapped value that covers ``address`` (not necessarily starting there), or None."""
    return _BY_ADDRESS.get(address)


def describe_range(address: int, count: int) -> str:
    """Human text of registers ``address .. address+count-1`` and the objects they map to."""
    names: list[str] = []
    for a in range(address, address + max(count, 1)):
        spec = _BY_ADDRESS.get(a)
        text = spec.label if spec is not None else f"0x{a:04X} (unmapped)"
        if text not in names:
            names.append(text)
    span = f"register 0x{address:04X}" if count <= 1 else f"registers 0x{address:04X}..0x{address + count - 1:04X}"
    return f"{span}: {', '.join(names)}" if names else span


def word_order_of(identity_registers: Sequence[int]) -> str | None:
    """The word order in which the map identity registers (0x0030, 2 registers) read
    :data:`MAP_IDENTITY`: ``"big"`` or ``"little"``; None if neither (not this map)."""
    spec = REGISTER_BY_NAME["map_identity"]
    return next((order for order in WORD_ORDERS if decode_value(spec, identity_registers, order) == MAP_IDENTITY), None)


def _check_order(word_order: str) -> None:
    if word_order not in WORD_ORDERS:
        raise ValueError(f"word_order = {word_order!r} is invalid; allowed: 'big' (high word first), 'little'")


def encode_value(spec: RegisterSpec, value: int | float, word_order: str = "big") -> list[int]:
    """The registers (each 0..0xFFFF) carrying ``value`` of ``spec``; ValueError if out of range."""
    _check_order(word_order)
    count, fmt = _KINDS[spec.kind]
    limits = spec.range
    whole = isinstance(value, int) and not isinstance(value, bool)
    if limits is not None and not (whole and limits[0] <= value <= limits[1]):
        raise ValueError(f"{spec.label} = {value!r} is invalid; allowed: integers {limits[0]}..{limits[1]}")
    words = list(struct.unpack(f">{count}H", struct.pack(fmt, value)))
    if word_order == "little":
        words.reverse()
    return words


def decode_value(spec: RegisterSpec, registers: Sequence[int], word_order: str = "big") -> int | float:
    """The value of ``spec`` from its registers (exactly ``spec.count`` of them)."""
    _check_order(word_order)
    count, fmt = _KINDS[spec.kind]
    if len(registers) != count:
        raise ValueError(f"{spec.label} needs {count} registers, got {len(registers)}")
    words = list(registers) if word_order == "big" else list(reversed(registers))
    value = struct.unpack(fmt, struct.pack(f">{count}H", *words))[0]
    if spec.kind == "i8" and not -0x80 <= value <= 0x7F:
        raise ValueError(f"{spec.label} register 0x{registers[0]:04X} is not a sign-extended INTEGER8")
    return value


class InputBlockCodec:
    """Precompiled codec of the cyclic input block: statusword, velocity[, position].

    ``decode(registers)`` returns ``(statusword, velocity, position)`` (position None when the
    block is read without it); ``encode(...)`` is the server's side.
    """

    def __init__(self, word_order: str = "big", with_position: bool = True) -> None:
        _check_order(word_order)
        self.word_order = word_order
        self.with_position = with_position
        self.count = INPUT_BLOCK_COUNT if with_position else INPUT_BLOCK_COUNT_NO_POSITION
        self._words = struct.Struct(f">{self.count}H")
        self._values = struct.Struct(">Hii" if with_position else ">Hi")
        self.decode: Callable[[Sequence[int]], tuple[int, int, int | None]] = self._build_decode()
        self.encode: Callable[..., list[int]] = self._build_encode()

    def _build_decode(self) -> Callable[[Sequence[int]], tuple[int, int, int | None]]:
        pack, unpack = self._words.pack, self._values.unpack
        big = self.word_order == "big"
        if self.with_position:
            if big:
                def decode(r: Sequence[int]) -> tuple[int, int, int | None]:
                    return unpack(pack(*r))
            else:
                def decode(r: Sequence[int]) -> tuple[int, int, int | None]:
                    return unpack(pack(r[0], r[2], r[1], r[4], r[3]))
        else:
            if big:
                def decode(r: Sequence[int]) -> tuple[int, int, int | None]:
                    sw, vel = unpack(pack(*r))
                    return sw, vel, None
            else:
                def decode(r: Sequence[int]) -> tuple[int, int, int | None]:
                    sw, vel = unpack(pack(r[0], r[2], r[1]))
                    return sw, vel, None
        return decode

    def _build_encode(self) -> Callable[..., list[int]]:
        pack, unpack = self._values.pack, self._words.unpack
        big = self.word_order == "big"
        if self.with_position:
            def encode(statusword: int, velocity: int, position: int = 0) -> list[int]:
                r = unpack(pack(statusword, velocity, position))
                return list(r) if big else [r[0], r[2], r[1], r[4], r[3]]
        else:
            def encode(statusword: int, velocity: int, position: int = 0) -> list[int]:
                r = unpack(pack(statusword, velocity))
                return list(r) if big else [r[0], r[2], r[1]]
        return encode


EXCEPTION_NAMES = {
    0x01: "ILLEGAL FUNCTION",
    0x02: "ILLEGAL DATA ADDRESS",
    0x03: "ILLEGAL DATA VALUE",
    0x04: "SERVER DEVICE FAILURE",
    0x05: "ACKNOWLEDGE",
    0x06: "SERVER DEVICE BUSY",
    0x08: "MEMORY PARITY ERROR",
    0x0A: "GATEWAY PATH UNAVAILABLE",
    0x0B: "GATEWAY TARGET DEVICE FAILED TO RESPOND",
}
NO_UNIT_CODES = (0x0A, 0x0B)  # what a gateway answers for a unit id nobody answers for: path unavailable, target silent


def exception_name(code: int) -> str:
    """``"0x02 ILLEGAL DATA ADDRESS"`` for a Modbus exception code."""
    return f"0x{code:02X} {EXCEPTION_NAMES.get(code, 'unknown exception')}"
