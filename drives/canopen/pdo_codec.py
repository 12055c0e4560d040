"""Precompiled ``struct`` codecs for one PDO mapping (CiA-301 byte-aligned, little endian).

A :class:`PdoCodec` is built once from the ordered list of mapped objects and then packs or
unpacks a whole frame in one ``struct`` call: atomic per frame (every value of a decoded
tuple comes from the same CAN frame) and allocation-light.  A frame whose length differs
from the mapping is never decoded (a :class:`~drives.errors.DriveProtocolError`).

Values travel in the objects' own integer units; nothing here knows SI.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Sequence

from drives.cia402 import OBJECTS, ObjectSpec
from drives.errors import DriveProtocolError, ParameterError

MAX_PDO_BYTES = 8  # classical CAN


def object_spec(obj: ObjectSpec | int) -> ObjectSpec:
    """The :class:`ObjectSpec` of ``obj`` (an ObjectSpec, or an index known to drives.cia402)."""
    if isinstance(obj, ObjectSpec):
        return obj
    try:
        return OBJECTS[int(obj)]
    except KeyError:
        known = ", ".join(f"0x{i:04X}" for i in sorted(OBJECTS))
        raise ParameterError("object", f"0x{int(obj):04X}", f"an ObjectSpec, or one of {known}", "PDO mapping") from None


class PdoCodec:
    """Pack/unpack one PDO frame mapped to ``entries`` (in mapping order).

    ``mapping_words`` are the 0x16xx/0x1Axx sub-entries (index << 16 | subindex << 8 | bits).
    """

    __slots__ = ("name", "entries", "struct", "size", "mapping_words", "_ranges")

    def __init__(self, entries: Iterable[ObjectSpec | int], name: str = "PDO") -> None:
        self.name = name
        self.entries: tuple[ObjectSpec, ...] = tuple(object_spec(e) for e in entries)
        if not self.entries:
            raise ParameterError("entries", "()", "at least one mapped object", name)
        fmt = "<" + "".join(e.data_type.struct_format for e in self.entries)
        self.struct = struct.Struct(fmt)
        self.size: int = self.struct.size
        if self.size > MAX_PDO_BYTES:
            names = ", ".join(f"0x{e.index:04X}" for e in self.entries)
            raise ParameterError("entries", names,
                                 f"objects of at most {MAX_PDO_BYTES} bytes in all (these need {self.size})", name)
        self.mapping_words: tuple[int, ...] = tuple(
            e.index << 16 | e.subindex << 8 | 8 * e.data_type.size for e in self.entries
        )
        self._ranges = tuple(e.data_type.range for e in self.entries)

    def __repr__(self) -> str:
        names = ", ".join(f"0x{e.index:04X}:{e.subindex:02X}" for e in self.entries)
        return f"PdoCodec({self.name}: {names}; {self.struct.format!r}, {self.size} bytes)"

    def index_of(self, index: int, subindex: int = 0) -> int:
        """Position of object ``index:subindex`` in the decoded tuple; ValueError if unmapped."""
        for position, entry in enumerate(self.entries):
            if entry.index == index and entry.subindex == subindex:
                return position
        raise ParameterError("object", f"0x{index:04X}:{subindex:02X}", "a mapped object", self.name)

    def decode(self, data: bytes | bytearray | memoryview) -> tuple[int, ...]:
        """Values of one frame, in mapping order; DriveProtocolError if the length does not match (drop the frame)."""
        if len(data) != self.size:
            raise self._length_error(len(data))
        return self.struct.unpack(data)

    def encode(self, *values: int) -> bytes:
        """One frame's data from ``values`` (mapping order); ValueError naming the object if out of range."""
        self.check(values)
        return self.struct.pack(*values)

    def encode_into(self, buffer: bytearray, *values: int) -> None:
        """Pack ``values`` into ``buffer`` (exactly ``size`` bytes long) without allocating."""
        if len(buffer) != self.size:
            raise self._length_error(len(buffer))
        self.check(values)
        self.struct.pack_into(buffer, 0, *values)

    def _length_error(self, got: int) -> DriveProtocolError:
        """A frame (or buffer) of ``got`` bytes where the mapping needs exactly ``size``."""
        return DriveProtocolError(self.name, f"frame of {got} bytes, mapping needs exactly {self.size}")

    def check(self, values: Sequence[int]) -> None:
        """Raise ValueError naming the object if a value does not fit its data type."""
        if len(values) != len(self.entries):
            raise ParameterError("values", len(values), f"exactly {len(self.entries)} values", self.name)
        for value, (low, high), entry in zip(values, self._ranges, self.entries):
            if not low <= value <= high:
                raise ParameterError(f"0x{entry.index:04X} ({entry.name})", value,
                                     f"{entry.data_type.name} range [{low}, {high}]", self.name)
