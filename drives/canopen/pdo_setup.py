"""Writing a PDO mapping plan over SDO, one named object at a time, and falling back when refused.

Each PDO of a plan (:mod:`drives.canopen.pdo_plan`) is configured as CiA 301 7.5.2.35-38
prescribes, through :class:`~drives.canopen.sdo.SdoAccess` so that an abort names the object
actually written:

1. COB-ID (sub 1) invalid (bit 31), the RTR bit as the drive had it;
2. transmission type (sub 2) = 1, synchronous every SYNC; a TPDO's inhibit time (sub 3) = 0
   where the drive has it (a drive may default to tens of ms); an RPDO's event timer (sub 5),
   the receive deadline, where the drive has it;
3. mapping: sub 0 = 0, the entries, sub 0 = n, read back (a default-mapping plan keeps the
   drive's entries, rewritten only if an earlier attempt changed them);
4. COB-ID valid.

Only objects the inventory found are written.  The drive refusing a mapping (abort 0x06040041
object cannot be mapped, 0x06040042 PDO length exceeded, 0x06040043 parameter incompatible, or
a read-only / unsupported access to its mapping record: a fixed mapping) moves on to the next
plan, and the refusal is kept as a note; any other abort is an error.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from drives.canopen.inventory import DrivePdo
from drives.canopen.pdo_plan import Frame, MappingPlan, mapping_word
from drives.canopen.sdo import SdoAccess
from drives.cia301 import (
    COB_ID_INVALID,
    COB_ID_MASK,
    COB_ID_NO_RTR,
    PDO_COB_ID,
    PDO_EVENT_TIMER,
    PDO_INHIBIT_TIME,
    PDO_TRANSMISSION_TYPE,
    TRANSMISSION_SYNCHRONOUS_EVERY_SYNC,
    SdoAbort,
)
from drives.cia402 import DataType
from drives.errors import DriveProtocolError, DriveRefusal

MAPPING_REFUSALS = frozenset({SdoAbort.NOT_MAPPABLE, SdoAbort.PDO_LENGTH_EXCEEDED, SdoAbort.PARAMETER_INCOMPATIBLE})
FIXED_MAPPING = frozenset({SdoAbort.READ_ONLY, SdoAbort.UNSUPPORTED_ACCESS})  # at the mapping record


@dataclass(frozen=True)
class AppliedMapping:
    """The plan the drive accepted, the COB-ID of each of its frames, and a note for each plan it refused."""

    plan: MappingPlan
    cob_ids: tuple[int, ...]
    refusals: tuple[str, ...]


class PdoSetup:
    """Configures the PDOs of drive ``name`` through ``sdo``; ``node_id`` gives the predefined COB-IDs."""

    def __init__(self, name: str, sdo: SdoAccess, node_id: int) -> None:
        self.name = name
        self.sdo = sdo
        self.node_id = node_id

    def apply(self, candidates: Sequence[MappingPlan], skipped: Sequence[str], bases: Sequence[int],
              event_timer_ms: int = 0) -> AppliedMapping:
        """The first of ``candidates`` the drive accepts (``bases``: predefined COB-IDs of PDO 1..4
        without the node id); DriveProtocolError naming every refusal if none is accepted."""
        refusals: list[str] = []
        for plan in candidates:
            try:
                cobs = tuple(self.configure(frame, bases[frame.pdo.number - 1] + self.node_id, event_timer_ms)
                             for frame in plan.frames)
            except DriveRefusal as exc:
                if not self._is_refusal(exc, plan):
                    raise
                refusals.append(f"{plan.describe()} refused ({exc.message})")
                continue
            return AppliedMapping(plan, cobs, tuple(refusals))
        tried = "; ".join([*refusals, *skipped]) or "the drive has no PDO of this direction"
        raise DriveProtocolError(self.name, f"no PDO mapping the drive accepts: {tried}")

    @staticmethod
    def _is_refusal(exc: DriveRefusal, plan: MappingPlan) -> bool:
        """A refused mapping: a mapping abort at any PDO record of the plan, or a read-only/unsupported
        access to a mapping record (a fixed mapping)."""
        records = {frame.pdo.communication for frame in plan.frames}
        mappings = {frame.pdo.mapping_record for frame in plan.frames}
        if exc.index in mappings and exc.code in FIXED_MAPPING:
            return True
        return exc.index in records | mappings and exc.code in MAPPING_REFUSALS

    def configure(self, frame: Frame, predefined: int, event_timer_ms: int = 0) -> int:
        """Configure ``frame``'s PDO (see the module docstring); its COB-ID."""
        pdo = frame.pdo
        com, sdo = pdo.communication, self.sdo
        cob_id = pdo.cob_word & COB_ID_MASK or predefined
        rtr = pdo.cob_word & COB_ID_NO_RTR  # keep what the drive had: some refuse RTR
        sdo.write_int(com, PDO_COB_ID, DataType.UNSIGNED32, cob_id | COB_ID_INVALID | rtr)
        sdo.write_int(com, PDO_TRANSMISSION_TYPE, DataType.UNSIGNED8, TRANSMISSION_SYNCHRONOUS_EVERY_SYNC)
        if pdo.transmit and pdo.has_inhibit_time:
            sdo.write_int(com, PDO_INHIBIT_TIME, DataType.UNSIGNED16, 0)
        if not pdo.transmit and pdo.has_event_timer:
            sdo.write_int(com, PDO_EVENT_TIMER, DataType.UNSIGNED16, event_timer_ms)
        words = [mapping_word(spec) for spec in frame.objects]
        if frame.remap or self._mapping(pdo) != pdo.mapping:
            self._write_mapping(pdo, words)
        count = sdo.read_int(pdo.mapping_record, 0, DataType.UNSIGNED8)
        if count != len(words):
            raise DriveProtocolError(self.name, f"0x{pdo.mapping_record:04X}:00 reads back {count} mapped objects "
                                                f"after writing {len(words)}")
        sdo.write_int(com, PDO_COB_ID, DataType.UNSIGNED32, cob_id | rtr)
        return cob_id

    def _mapping(self, pdo: DrivePdo) -> tuple[int, ...]:
        """The mapping words of ``pdo`` as they stand now."""
        count = self.sdo.read_int(pdo.mapping_record, 0, DataType.UNSIGNED8)
        return tuple(self.sdo.read_int(pdo.mapping_record, k, DataType.UNSIGNED32) for k in range(1, count + 1))

    def _write_mapping(self, pdo: DrivePdo, words: Sequence[int]) -> None:
        record = pdo.mapping_record
        self.sdo.write_int(record, 0, DataType.UNSIGNED8, 0)
        for subindex, word in enumerate(words, 1):
            self.sdo.write_int(record, subindex, DataType.UNSIGNED32, word)
        self.sdo.write_int(record, 0, DataType.UNSIGNED8, len(words))

    def invalidate(self, pdo: DrivePdo) -> None:
        """Invalidate ``pdo`` (unused by the cycle) so that only the configured frames travel."""
        current = self.sdo.read_int(pdo.communication, PDO_COB_ID, DataType.UNSIGNED32)
        if not current & COB_ID_INVALID:
            self.sdo.write_int(pdo.communication, PDO_COB_ID, DataType.UNSIGNED32, current | COB_ID_INVALID)
