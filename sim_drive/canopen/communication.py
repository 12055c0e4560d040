"""The slave's CiA-301 communication objects written over SDO: SYNC, cycle period, EMCY, heartbeats.

canopen's :class:`~canopen.LocalNode` stores every written value (what a read returns); this
module validates a write before it is stored (raising :class:`canopen.SdoAbortedError` to
refuse it) and applies it to the running node:

========  ===  ================================================================================
0x1005    0    COB-ID SYNC: 11-bit, not restricted, no SYNC generation (bit 30), no 29-bit frames
0x1006    0    communication cycle period, us: the plant's period (0 = none: the plant keeps its
               period, and 0x1006 reads 0)
0x1007    0    synchronous window length, us (synchronous RPDOs only)
0x1014    0    COB-ID EMCY: bit 31 invalidates; the id may change only while invalid
0x1016    1    consumer heartbeat: node id << 16 | time ms (0 in either disables)
0x1017    0    producer heartbeat time, ms
========  ===  ================================================================================
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from canopen import SdoAbortedError
from canopen.objectdictionary import ObjectDictionary

from drives.cia301 import (
    COB_ID_29_BIT,
    COB_ID_INVALID,
    COB_ID_MASK,
    COB_ID_SYNC,
    COB_ID_SYNC_GENERATOR,
    COMMUNICATION_CYCLE_PERIOD,
    CONSUMER_HEARTBEAT_TIME,
    EMCY_BASE,
    PRODUCER_HEARTBEAT_TIME,
    SYNC_COB_ID,
    SYNCHRONOUS_WINDOW_LENGTH,
    SdoAbort,
    is_restricted_cob_id,
)
from drives.cia301 import COB_ID_EMCY as COB_ID_EMCY_OBJECT
from haptic_bus.errors import HapticBusError
from sim_drive.canopen.emergency import Emergency
from sim_drive.canopen.od_defaults import default_int
from sim_drive.canopen.timers import NodeTimers
from sim_drive.device import SimulatedDrive

HANDLED = frozenset({COB_ID_SYNC, COMMUNICATION_CYCLE_PERIOD, SYNCHRONOUS_WINDOW_LENGTH, COB_ID_EMCY_OBJECT,
                     CONSUMER_HEARTBEAT_TIME, PRODUCER_HEARTBEAT_TIME})


def _refuse() -> SdoAbortedError:
    return SdoAbortedError(SdoAbort.VALUE_RANGE)


@dataclass
class CommunicationObjects:
    """The running values of the objects in the module table, for one slave: ``sync_cob`` (0x1005's
    11-bit id), ``sync_window_us`` (0x1007, us) and ``producer_ms`` (0x1017 as it stands, ms; the
    EDS value after a reset)."""

    dictionary: ObjectDictionary
    drive: SimulatedDrive
    timers: NodeTimers
    emergency: Emergency
    node_id: int
    sync_cob: int = field(init=False)
    sync_window_us: int = field(init=False)
    producer_ms: int = field(init=False)
    _emcy_word: int = field(init=False)  # 0x1014 as it stands

    def __post_init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Back to the object dictionary's values (communication reset); the producer is not started.
        An object the dictionary lacks keeps the CiA-301 predefined value (SYNC 0x80, EMCY 0x80 +
        node id) or is off (no heartbeat consumer, no producer, no sync window)."""
        od = self.dictionary
        self.sync_cob = default_int(od, COB_ID_SYNC, absent=SYNC_COB_ID) & COB_ID_MASK
        self.sync_window_us = default_int(od, SYNCHRONOUS_WINDOW_LENGTH, absent=0)
        self._set_emcy(default_int(od, COB_ID_EMCY_OBJECT, absent=EMCY_BASE + self.node_id))
        self._consumer(default_int(od, CONSUMER_HEARTBEAT_TIME, 1, absent=0))
        self.producer_ms = default_int(od, PRODUCER_HEARTBEAT_TIME, absent=0)

    def owns(self, index: int) -> bool:
        """True for the objects of the module table."""
        return index in HANDLED

    def write(self, index: int, subindex: int, value: int) -> None:
        """Validate and apply one SDO write; raise SdoAbortedError to refuse it."""
        if index == COB_ID_SYNC:
            cob = value & COB_ID_MASK
            if value & (COB_ID_SYNC_GENERATOR | COB_ID_29_BIT) or is_restricted_cob_id(cob):
                raise _refuse()
            self.sync_cob = cob
        elif index == COMMUNICATION_CYCLE_PERIOD:
            if value:
                try:
                    self.drive.reconfigure(period=value * 1e-6)
                except HapticBusError as exc:
                    raise _refuse() from exc
        elif index == SYNCHRONOUS_WINDOW_LENGTH:
            self.sync_window_us = value
        elif index == COB_ID_EMCY_OBJECT:
            valid_now = not self._emcy_word & COB_ID_INVALID
            changes_id = value & COB_ID_MASK != self._emcy_word & COB_ID_MASK
            if value & COB_ID_29_BIT or is_restricted_cob_id(value & COB_ID_MASK) or (valid_now and changes_id):
                raise _refuse()
            self._set_emcy(value)
        elif index == CONSUMER_HEARTBEAT_TIME and subindex == 1:
            self._consumer(value)
        elif index == PRODUCER_HEARTBEAT_TIME:
            self.producer_ms = value
            self.timers.start_producer(value / 1000.0, time.monotonic())

    def _set_emcy(self, word: int) -> None:
        self._emcy_word = word
        self.emergency.enabled = not word & COB_ID_INVALID
        self.emergency.producer.cob_id = word & COB_ID_MASK

    def _consumer(self, entry: int) -> None:
        node, period_ms = entry >> 16 & 0xFF, entry & 0xFFFF
        if node > 127:
            raise _refuse()
        self.timers.configure_consumer(node or None, period_ms / 1000.0)
