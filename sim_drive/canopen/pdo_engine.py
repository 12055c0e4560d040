"""The slave's PDO traffic against the drive, by the live configuration of :mod:`sim_drive.canopen.pdo_table`.

- TPDOs by transmission type: 1..240 every n-th SYNC, 0 on a SYNC when the data changed,
  254/255 whenever the data changed (:meth:`PdoEngine.send_event_tpdos`, called after every
  SYNC, RPDO and SDO write).
- RPDOs with type 0..240 are applied at the next SYNC, 254/255 on reception.  With a sync
  window 0x1007 > 0, a *synchronous* RPDO arriving later than the window after the last SYNC
  (message timestamps) is discarded, counted and answered with EMCY 0x8250 (it missed its
  cycle); the window does not apply to asynchronous RPDOs (CiA 301 7.5.2.6).  A short RPDO is
  discarded with EMCY 0x8210, a long one is used and reported with EMCY 0x8220.

Each frame is one precompiled ``struct`` call.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import can

from drives.cia301 import EmcyCode
from sim_drive.canopen.emergency import Emergency
from sim_drive.canopen.pdo_access import PdoAccess, Value
from sim_drive.canopen.pdo_table import PdoChannel, PdoTable
from sim_drive.device import SimulatedDrive
from sim_drive.sync_clock import SyncClock

Readers = tuple[Callable[[], Value], ...]
Writers = tuple[Callable[[Value], None], ...]


@dataclass
class SlaveCounters:
    """Communication errors the slave counted."""

    late_rpdos: int = 0
    rpdo_length_errors: int = 0
    malformed_frames: int = 0  # frames the slave could not use (wrong SYNC, SDO or NMT length, ...)
    receive_errors: int = 0  # exceptions the bus raised on receive


class PdoEngine:
    """TPDO encoding and RPDO decoding for one slave (objects read and written through ``access``);
    ``send(cob_id, data)`` puts a frame on the bus."""

    def __init__(self, table: PdoTable, drive: SimulatedDrive, access: PdoAccess, send: Callable[[int, bytes], None],
                 emergency: Emergency, counters: SlaveCounters, sync_clock: SyncClock | None = None) -> None:
        self.table = table
        self.drive = drive
        self.access = access
        self.send = send
        self.emergency = emergency
        self.counters = counters
        self.sync_clock = sync_clock  # None: each SYNC closes exactly one period (virtual time)
        self.rx_by_cob: dict[int, PdoChannel] = {}
        self._writers: dict[int, Writers] = {}
        self.tx_cobs: frozenset[int] = frozenset()
        self._tx_plan: list[tuple[PdoChannel, Readers]] = []
        self._sync_counts: dict[int, int] = {}
        self._last: dict[int, bytes] = {}
        self._pending: list[tuple[PdoChannel, bytes]] = []
        self._short_next: dict[int, int] = {}
        self._sync_timestamp: float | None = None
        self.rebuild()

    def rebuild(self) -> None:
        """Recompute the plan after a configuration change (every TPDO counts as changed)."""
        access = self.access
        self.rx_by_cob = {ch.cob_id: ch for ch in self.table.rx if ch.valid}
        self._writers = {ch.number: tuple(access.writer(v) for v in ch.variables) for ch in self.table.rx}
        self.tx_cobs = frozenset(ch.cob_id for ch in self.table.tx)
        self._tx_plan = [(ch, tuple(access.reader(v) for v in ch.variables)) for ch in self.table.tx if ch.valid]
        self._sync_counts = {ch.number: 0 for ch, _ in self._tx_plan}
        self._last = {}

    def forget_sent(self) -> None:
        """Entering OPERATIONAL: every event TPDO goes out again."""
        self._last.clear()

    def short_next(self, number: int, missing_bytes: int) -> None:
        """Fault injection: the next transmission of TPDO ``number`` is ``missing_bytes`` short."""
        self._short_next[number] = missing_bytes

    # ------------------------------------------------------------------ TPDOs

    def _encode(self, channel: PdoChannel, readers: Readers) -> bytes:
        return channel.codec.pack(*[read() for read in readers])

    def _transmit(self, channel: PdoChannel, data: bytes) -> None:
        self._last[channel.number] = data
        missing = self._short_next.pop(channel.number, 0)
        self.send(channel.cob_id, data[: max(len(data) - missing, 0)] if missing else data)

    def send_event_tpdos(self) -> None:
        """Event-driven TPDOs (254/255) whose data changed."""
        for channel, readers in self._tx_plan:
            if channel.trans_type >= 254:
                data = self._encode(channel, readers)
                if self._last.get(channel.number) != data:
                    self._transmit(channel, data)

    def on_sync(self, timestamp: float, operational: bool) -> None:
        """A SYNC: buffered synchronous RPDOs, one drive SYNC, then the synchronous TPDOs."""
        self._sync_timestamp = timestamp
        for channel, data in self._pending:
            self._apply(channel, data)
        self._pending.clear()
        if self.sync_clock is None:
            self.drive.sync()
        else:
            self.drive.sync(self.sync_clock(timestamp))
        if not operational:
            return
        counts = self._sync_counts
        for channel, readers in self._tx_plan:
            trans_type = channel.trans_type
            if trans_type >= 254:
                continue
            if trans_type == 0:
                data = self._encode(channel, readers)
                if self._last.get(channel.number) != data:
                    self._transmit(channel, data)
                continue
            count = counts[channel.number]
            counts[channel.number] = count + 1
            if count % trans_type == 0:
                self._transmit(channel, self._encode(channel, readers))
        self.send_event_tpdos()

    # ------------------------------------------------------------------ RPDOs

    def on_rpdo(self, channel: PdoChannel, message: can.Message, window_us: int) -> bool:
        """An RPDO in OPERATIONAL; True if it was taken (not late, not short)."""
        synchronous = channel.synchronous
        if (synchronous and window_us and self._sync_timestamp is not None
                and (message.timestamp - self._sync_timestamp) * 1e6 > window_us):
            self.counters.late_rpdos += 1
            self.emergency.communication_event(EmcyCode.RPDO_TIMEOUT)
            return False
        data = bytes(message.data)
        size = channel.codec.size
        if len(data) < size:
            self.counters.rpdo_length_errors += 1
            self.emergency.communication_event(EmcyCode.PDO_LENGTH)
            return False
        if len(data) > size:
            self.emergency.communication_event(EmcyCode.PDO_TOO_LONG)
            data = data[:size]
        if synchronous:
            self._pending.append((channel, data))
        else:
            self._apply(channel, data)
            self.send_event_tpdos()
        return True

    def _apply(self, channel: PdoChannel, data: bytes) -> None:
        for write, value in zip(self._writers[channel.number], channel.codec.unpack(data)):
            write(value)
