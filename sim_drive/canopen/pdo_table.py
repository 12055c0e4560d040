"""The slave's live PDO configuration, following SDO writes to 0x1400.., 0x1600.., 0x1800.., 0x1A00...

canopen's ``LocalNode`` stores what a master writes to the PDO objects but never links its
``PdoMap`` objects to them, so its PDOs would keep their initial layout.  :class:`PdoTable`
closes that gap: it validates each write as CiA 301 asks (raising
:class:`canopen.SdoAbortedError`, which the SDO server turns into an abort) and recompiles a
``struct`` codec for the PDO whose configuration changed, so encoding and decoding on the
hot path is one ``pack``/``unpack`` call.

Rules enforced (CiA 301 7.5.2.35-7.5.2.38):

- the COB-ID (sub 1) of a valid PDO may only change its valid bit (31); 29-bit ids and the
  restricted CAN-IDs of CiA 301 table 3 (NMT, SDO, heartbeat, reserved) are refused;
- transmission type (sub 2): TPDO 0..240, 254, 255; RPDO 0..240, 254, 255 (no RTR-only types);
- inhibit time (sub 3, 100 us) and event timer (sub 5, ms; for an RPDO the receive deadline)
  are kept per PDO;
- mapping entries (sub 1..n) are writable only while the PDO is invalid and sub 0 is 0;
- sub 0 may be set only while the PDO is invalid, to at most the entries the mapping record
  has (and its HighLimit, if the dictionary gives one); the entries it enables must name
  PDO-mappable objects of the right direction (:mod:`~sim_drive.canopen.pdo_access`) with
  their full bit length, 64 bits at most.

The PDOs and their limits are the object dictionary's: a PDO whose communication record the
dictionary lacks does not exist (SDO abort 0x06020000 from the SDO server), a mapping record
holds the sub-indices it declares, a communication record without sub 5 has no event timer.
A default mapping the slave cannot carry (an object it cannot map) starts unmapped (sub 0 reads
0), logged.

Abort codes: 0x06090030 value range, 0x06010000 unsupported access (PDO valid / mapping
enabled), 0x06040041 object cannot be mapped, 0x06040042 mapping exceeds the PDO length.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable
from dataclasses import dataclass, field

from canopen import ObjectDictionary, SdoAbortedError
from canopen.objectdictionary import ODArray, ODRecord, ODVariable

from drives.cia301 import COB_ID_29_BIT, COB_ID_INVALID, COB_ID_MASK, is_restricted_cob_id
from sim_drive.canopen.od_defaults import default_int
from sim_drive.canopen.pdo_access import PdoAccess

logger = logging.getLogger(__name__)

MAX_ENTRIES = 8
MAX_BITS = 64
ABORT_RANGE = 0x06090030
ABORT_ACCESS = 0x06010000
ABORT_NOT_MAPPABLE = 0x06040041
ABORT_TOO_LONG = 0x06040042
VALID_TRANS_TYPES = frozenset(range(0, 241)) | {254, 255}
RX_COM, RX_MAP, TX_COM, TX_MAP = 0x1400, 0x1600, 0x1800, 0x1A00
CHANNELS = 4


@dataclass
class PdoChannel:
    """One PDO: its communication words and mapping entries, and the codec compiled from them.

    ``variables`` are the mapped objects in frame order; ``codec`` packs/unpacks them;
    ``entries`` are the mapping record's entry sub-indices 1..n, ``capacity`` how many of them
    sub 0 may enable.
    """

    number: int
    transmit: bool
    cob_word: int
    trans_type: int
    inhibit_time: int = 0  # 100 us
    event_timer: int = 0  # ms; an RPDO's receive deadline
    capacity: int = MAX_ENTRIES  # entries sub 0 may enable
    entries: list[int] = field(default_factory=lambda: [0] * MAX_ENTRIES)
    count: int = 0
    variables: tuple[ODVariable, ...] = ()
    codec: struct.Struct = field(default_factory=lambda: struct.Struct("<"))

    @property
    def valid(self) -> bool:
        """True when the PDO exists (COB-ID bit 31 clear) and maps at least one object."""
        return not self.cob_word & COB_ID_INVALID and self.count > 0

    @property
    def cob_id(self) -> int:
        """The 11-bit CAN identifier."""
        return self.cob_word & COB_ID_MASK

    @property
    def synchronous(self) -> bool:
        """Transmission types 0..240 are tied to the SYNC."""
        return self.trans_type <= 240


class PdoTable:
    """The RPDOs and TPDOs (up to four each) of a slave, initialised from the object dictionary.

    ``object_dictionary`` must be imported for the slave's node id (so ``$NODEID`` COB-IDs
    are resolved); ``access`` tells which objects a PDO may carry.  ``on_change`` is called
    with the channel after each accepted write.  ``rx`` and ``tx`` list the PDOs the dictionary
    has, in number order.
    """

    def __init__(
        self,
        object_dictionary: ObjectDictionary,
        access: PdoAccess,
        on_change: Callable[[PdoChannel | None], None],
    ) -> None:
        self._od = object_dictionary
        self._access = access
        self._on_change = on_change
        self.rx: list[PdoChannel] = []
        self.tx: list[PdoChannel] = []
        self._by_index: dict[int, PdoChannel] = {}
        self.reset()

    def reset(self) -> None:
        """Back to the object dictionary's defaults (communication reset)."""
        self.rx = [c for n in range(1, CHANNELS + 1) if (c := self._channel_from_od(n, transmit=False))]
        self.tx = [c for n in range(1, CHANNELS + 1) if (c := self._channel_from_od(n, transmit=True))]
        self._by_index = {base + c.number - 1: c for c in self.rx for base in (RX_COM, RX_MAP)}
        self._by_index.update({base + c.number - 1: c for c in self.tx for base in (TX_COM, TX_MAP)})

    def _channel_from_od(self, number: int, transmit: bool) -> PdoChannel | None:
        od, com = self._od, (TX_COM if transmit else RX_COM) + number - 1
        record = od.get(com)
        if not isinstance(record, ODRecord) or 1 not in record:
            return None
        mapping = (TX_MAP if transmit else RX_MAP) + number - 1
        channel = PdoChannel(number, transmit, default_int(od, com, 1), default_int(od, com, 2, absent=255),
                             inhibit_time=default_int(od, com, 3, absent=0), event_timer=default_int(od, com, 5, absent=0))
        declared, channel.capacity = _entries(od.get(mapping))
        channel.entries = [default_int(od, mapping, k, absent=0) for k in range(1, declared + 1)]
        channel.count = default_int(od, mapping, 0, absent=0)
        try:
            self._compile(channel)
        except SdoAbortedError:
            words = ", ".join(f"0x{e:08X}" for e in channel.entries[: channel.count])
            logger.warning("%s%d: the dictionary's default mapping (%s) holds an object this slave cannot map; it starts "
                           "unmapped", "TPDO" if transmit else "RPDO", number, words)
            channel.count = 0
            self._compile(channel)
            record = od[mapping]
            if isinstance(record, (ODRecord, ODArray)) and 0 in record:
                self._access.keep(record[0], 0)  # an SDO read of sub 0 says so
        return channel

    def owns(self, index: int) -> bool:
        """True if ``index`` is a PDO communication or mapping object this table handles."""
        return index in self._by_index

    def write(self, index: int, subindex: int, value: int) -> None:
        """Validate and apply one SDO write; raise SdoAbortedError to refuse it."""
        channel = self._by_index[index]
        if index & 0x0200:
            self._write_map(channel, subindex, value)
        else:
            self._write_com(channel, subindex, value)
        self._on_change(channel)

    def _write_com(self, channel: PdoChannel, subindex: int, value: int) -> None:
        if subindex == 1:
            if value & COB_ID_29_BIT or is_restricted_cob_id(value & COB_ID_MASK):
                raise SdoAbortedError(ABORT_RANGE)
            exists = not channel.cob_word & COB_ID_INVALID
            if exists and not value & COB_ID_INVALID and value & COB_ID_MASK != channel.cob_id:
                raise SdoAbortedError(ABORT_RANGE)
            if not value & COB_ID_INVALID:
                self._check_mapping(channel, channel.count)
            channel.cob_word = value
        elif subindex == 2:
            if value not in VALID_TRANS_TYPES:
                raise SdoAbortedError(ABORT_RANGE)
            channel.trans_type = value
        elif subindex == 3:
            channel.inhibit_time = value
        elif subindex == 5:
            channel.event_timer = value

    def _write_map(self, channel: PdoChannel, subindex: int, value: int) -> None:
        if not channel.cob_word & COB_ID_INVALID:
            raise SdoAbortedError(ABORT_ACCESS)
        if subindex == 0:
            if value > channel.capacity:
                raise SdoAbortedError(ABORT_TOO_LONG)
            self._check_mapping(channel, value)
            channel.count = value
            self._compile(channel)
        else:
            if channel.count:
                raise SdoAbortedError(ABORT_ACCESS)
            channel.entries[subindex - 1] = value

    def _mapped_variable(self, channel: PdoChannel, entry: int) -> ODVariable:
        index, subindex, bits = entry >> 16, entry >> 8 & 0xFF, entry & 0xFF
        obj = self._od.get(index)
        if isinstance(obj, (ODRecord, ODArray)):
            obj = obj.get(subindex) if subindex in obj else None
        elif subindex:
            obj = None
        if not isinstance(obj, ODVariable) or bits != len(obj) or not self._access.mappable(obj, channel.transmit):
            raise SdoAbortedError(ABORT_NOT_MAPPABLE)
        return obj

    def _check_mapping(self, channel: PdoChannel, count: int) -> None:
        total = sum(len(self._mapped_variable(channel, e)) for e in channel.entries[:count])
        if total > MAX_BITS:
            raise SdoAbortedError(ABORT_TOO_LONG)

    def _compile(self, channel: PdoChannel) -> None:
        variables = tuple(self._mapped_variable(channel, e) for e in channel.entries[: channel.count])
        channel.codec = struct.Struct("<" + "".join(_struct_code(v) for v in variables))
        channel.variables = variables


def _entries(mapping: object) -> tuple[int, int]:
    """A mapping record's entry sub-indices (its highest, at most :data:`MAX_ENTRIES`) and how many
    of them sub 0 may enable (also at most its HighLimit, when the dictionary gives one); (0, 0)
    without a record."""
    if not isinstance(mapping, (ODRecord, ODArray)):
        return 0, 0
    declared = min(max((s for s in mapping.subindices if isinstance(s, int)), default=0), MAX_ENTRIES)
    limit = mapping[0].max if 0 in mapping else None
    return declared, min(declared, limit) if isinstance(limit, int) else declared


def _struct_code(variable: ODVariable) -> str:
    """The ``struct`` format character of a mapped variable (a type without one cannot be mapped)."""
    codec = None if variable.data_type is None else variable.STRUCT_TYPES.get(variable.data_type)
    if codec is None:
        raise SdoAbortedError(ABORT_NOT_MAPPABLE)
    return codec.format[-1]
