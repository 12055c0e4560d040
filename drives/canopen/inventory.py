"""What a CANopen drive has, read over SDO before commissioning writes anything.

A drive's object dictionary is its vendor's: the optional CiA-301 objects (0x1006, 0x1016,
0x1017), 0x6007, the sub-indices of the PDO communication records (0x1400:05, the RPDO
deadline, is often missing: CiA 301 makes sub 3..6 optional) and the number of entries a
mapping record holds all vary.  :func:`read_inventory` asks the drive itself (not an EDS the
master may not have): an object is absent when the drive answers SDO abort 0x06020000
(object) or 0x06090011 (sub-index); any other abort means it exists.  Reads only: the writes
come after, to objects the inventory found.

- communication record 0x1400+n / 0x1800+n: sub 0 (highest sub-index; absent: no such PDO),
  sub 1 (COB-ID as it stands), and sub 3 (inhibit time) / sub 5 (event timer) where sub 0 says
  they may be, each read to be sure;
- mapping record 0x1600+n / 0x1A00+n: how many entries it holds (the highest of sub 1..8 that
  exists: sub 8 first, then a bisection, <= 4 reads), and the mapping as it stands (after the NMT
  reset communication: the drive's default), sub 0 then each entry;
- the objects the cycle maps (0x6040, 0x6041, 0x606C, 0x6071, ...): a drive without one cannot be
  driven in cyclic synchronous torque mode;
- the PDO length limit: :data:`~drives.canopen.pdo_codec.MAX_PDO_BYTES` (8 bytes, classical CAN).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from drives.canopen.pdo_codec import MAX_PDO_BYTES
from drives.canopen.sdo import SdoAccess
from drives.cia301 import (
    COMMUNICATION_CYCLE_PERIOD,
    CONSUMER_HEARTBEAT_TIME,
    PDO_COB_ID,
    PDO_EVENT_TIMER,
    PDO_INHIBIT_TIME,
    PRODUCER_HEARTBEAT_TIME,
    RPDO_COMMUNICATION,
    TPDO_COMMUNICATION,
    SdoAbort,
)
from drives.cia402 import ABORT_CONNECTION_OPTION_CODE, DataType, ObjectSpec
from drives.errors import DriveRefusal

PDO_CHANNELS = 4
MAX_MAPPING_ENTRIES = 8  # CiA 301: sub 1..8 of a mapping record at most for 8-byte frames
ABSENT = frozenset({SdoAbort.NO_OBJECT, SdoAbort.NO_SUBINDEX})
MAPPING_OFFSET = 0x200  # mapping record = communication record + 0x200


@dataclass(frozen=True)
class DrivePdo:
    """One PDO the drive has: ``number`` 1..4, its direction, its communication record
    (``communication``, and ``communication + 0x200`` the mapping record), the COB-ID word as
    read, whether sub 3 (inhibit time) and sub 5 (event timer) exist, how many entries the
    mapping record holds, and the mapping words as they
    stand (index << 16 | subindex << 8 | bits)."""

    number: int
    transmit: bool
    communication: int
    cob_word: int
    has_inhibit_time: bool
    has_event_timer: bool
    capacity: int
    mapping: tuple[int, ...]

    @property
    def mapping_record(self) -> int:
        """The index of the mapping record (0x1600+n / 0x1A00+n)."""
        return self.communication + MAPPING_OFFSET

    @property
    def label(self) -> str:
        """"TPDO1", "RPDO2", ..."""
        return f"{'TPDO' if self.transmit else 'RPDO'}{self.number}"


@dataclass(frozen=True)
class DriveInventory:
    """What the drive answered for: the objects probed (``present``: ``(index, subindex)`` ->
    exists), its RPDOs and TPDOs (only those it has), and the PDO length limit (bytes)."""

    present: dict[tuple[int, int], bool]
    rpdos: tuple[DrivePdo, ...]
    tpdos: tuple[DrivePdo, ...]
    max_pdo_bytes: int = MAX_PDO_BYTES

    def has(self, index: int, subindex: int = 0) -> bool:
        """True if the drive has ``index:subindex`` (False for an object that was not probed)."""
        return self.present.get((index, subindex), False)


# (index, subindex) the master may write outside the PDOs, probed up front
PROBED_OBJECTS = (
    (COMMUNICATION_CYCLE_PERIOD, 0),
    (CONSUMER_HEARTBEAT_TIME, 1),
    (PRODUCER_HEARTBEAT_TIME, 0),
    (ABORT_CONNECTION_OPTION_CODE.index, 0),
)


class InventoryReader:
    """Reads a :class:`DriveInventory` through ``sdo`` (reads only)."""

    def __init__(self, sdo: SdoAccess) -> None:
        self.sdo = sdo

    def read(self, cyclic: Iterable[ObjectSpec] = ()) -> DriveInventory:
        """The drive's optional objects, the ``cyclic`` objects and its PDOs (see the module docstring)."""
        keys = [*PROBED_OBJECTS, *((spec.index, spec.subindex) for spec in cyclic)]
        present = {key: self._exists(*key) for key in dict.fromkeys(keys)}
        rpdos = tuple(c for n in range(PDO_CHANNELS) if (c := self._channel(RPDO_COMMUNICATION + n, n + 1, False)))
        tpdos = tuple(c for n in range(PDO_CHANNELS) if (c := self._channel(TPDO_COMMUNICATION + n, n + 1, True)))
        for channel in rpdos:
            present[channel.communication, PDO_EVENT_TIMER] = channel.has_event_timer
        return DriveInventory(present, rpdos, tpdos)

    def _read(self, index: int, subindex: int, data_type: DataType) -> int | None:
        """The value, or None if the drive lacks the object or sub-index."""
        try:
            return self.sdo.read_int(index, subindex, data_type)
        except DriveRefusal as exc:
            if exc.code in ABSENT:
                return None
            raise

    def _exists(self, index: int, subindex: int) -> bool:
        try:
            self.sdo.upload(index, subindex)
        except DriveRefusal as exc:
            return exc.code not in ABSENT  # e.g. write-only, no data available: it is there
        return True

    def _channel(self, communication: int, number: int, transmit: bool) -> DrivePdo | None:
        highest = self._read(communication, 0, DataType.UNSIGNED8)
        cob_word = self._read(communication, PDO_COB_ID, DataType.UNSIGNED32) if highest is not None else None
        if highest is None or cob_word is None:
            return None
        inhibit = highest >= PDO_INHIBIT_TIME and self._exists(communication, PDO_INHIBIT_TIME)
        timer = highest >= PDO_EVENT_TIMER and self._exists(communication, PDO_EVENT_TIMER)
        mapping_record = communication + MAPPING_OFFSET
        count = self._read(mapping_record, 0, DataType.UNSIGNED8)
        capacity = self._capacity(mapping_record) if count is not None else 0
        words = tuple(self._read(mapping_record, k, DataType.UNSIGNED32) or 0 for k in range(1, min(count or 0, capacity) + 1))
        return DrivePdo(number, transmit, communication, cob_word, inhibit, timer, capacity, words)

    def _capacity(self, mapping_record: int) -> int:
        """The highest of sub 1..8 the mapping record has (its entries are contiguous from sub 1)."""
        if self._exists(mapping_record, MAX_MAPPING_ENTRIES):
            return MAX_MAPPING_ENTRIES
        low, high = 0, MAX_MAPPING_ENTRIES  # sub ``low`` exists (0: the count), ``high`` does not
        while high - low > 1:
            middle = (low + high) // 2
            if self._exists(mapping_record, middle):
                low = middle
            else:
                high = middle
        return low
