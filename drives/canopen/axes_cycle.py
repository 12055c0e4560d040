"""One SYNC for several drives on one bus: every drive's TPDOs collected before any RPDO goes out.

A single-drive exchange (:class:`~drives.canopen.exchange.CanopenExchange`) sends its own SYNC
and waits for its own TPDOs.  With several drives on one bus that would be one SYNC per drive:
each drive would sample (and a synchronous drive latch its torque) at another instant, and the
bus would carry the SYNC frame once per axis.  Here one SYNC serves every drive: its frames are
read in the calling thread (canopen's notifier paused, as the ``direct`` exchange does) into one
table of every drive's TPDO COB-IDs, until every drive's TPDOs of the cycle are in or the
cycle's timeout passes.  Frames that are no TPDO go to canopen's dispatcher (SDO, heartbeat,
EMCY of every node).  Each drive's own exchange still decodes its TPDOs (its codecs and layout,
:meth:`~drives.canopen.exchange.CanopenExchange.inputs`) and sends its RPDOs; none of them sends
a SYNC (``produces_sync`` False).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from typing import Any

import can

from drives.base import CyclicInputs
from drives.canopen.exchange import CanopenExchange, Unpack, receive_direct
from drives.canopen.link import NetworkLink
from drives.cia301 import SYNC_COB_ID
from drives.errors import DriveError, DriveProtocolError

logger = logging.getLogger(__name__)

Slot = tuple[int, int, int, Unpack]  # axis, TPDO place, length, unpack


class AxesCycle:
    """SYNC out, every drive's TPDOs of the cycle in, for the drives of ``exchanges`` on ``link``.

    ``timeout`` (s): how long one cycle waits for all of them.  Call :meth:`configure` once every
    drive is commissioned (their TPDO COB-IDs known).  ``syncs_sent`` counts the SYNC frames.
    """

    def __init__(self, name: str, link: NetworkLink, exchanges: Sequence[CanopenExchange], timeout: float) -> None:
        self.name = name
        self.link = link
        self.exchanges = tuple(exchanges)
        self.timeout = timeout
        self.syncs_sent = 0
        self._sync = can.Message(arbitration_id=SYNC_COB_ID, data=b"", is_extended_id=False)
        self._slots: dict[int, Slot] = {}
        self._counts: tuple[int, ...] = ()

    def configure(self) -> None:
        """Build the table of every drive's TPDO COB-IDs; DriveProtocolError if two drives send on one."""
        slots: dict[int, Slot] = {}
        for axis, exchange in enumerate(self.exchanges):
            for cob, (place, size, unpack) in exchange.slots.items():
                if cob in slots:
                    other = self.exchanges[slots[cob][0]].name
                    raise DriveProtocolError(exchange.name, f"its TPDO COB-ID 0x{cob:03X} is also {other}'s: two "
                                                            "drives cannot share a TPDO on one bus")
                slots[cob] = (axis, place, size, unpack)
        self._slots = slots
        self._counts = tuple(len(exchange.slots) for exchange in self.exchanges)

    # ------------------------------------------------------------------ phases

    def begin(self) -> None:
        """Read the bus in this thread from now on (canopen's notifier paused), every axis' TPDOs let through."""
        self.link.read_directly(frozenset(self._slots))

    def end(self) -> None:
        """Give the bus back to canopen's notifier (SDO needs it)."""
        self.link.read_by_notifier()

    def _dispatch(self, msg: can.Message) -> None:
        self.exchanges[0].dispatch(msg)  # one network for all: any drive's dispatcher reaches every node's subscribers

    def drain(self) -> None:
        """Before a SYNC: consume what arrived since the last cycle (late TPDOs are counted, not used)."""
        now = time.perf_counter()
        while (frame := receive_direct(self.name, self.link, self._slots, now, self._dispatch)) is not None:
            axis, _, size, _ = self._slots[frame[0]]
            stats = self.exchanges[axis].stats
            if len(frame[1]) != size:
                stats.dropped_frames += 1
            else:
                stats.stale_tpdos += 1

    def sync_and_collect(self) -> list[CyclicInputs | None]:
        """SYNC out, then every drive's TPDOs of this cycle: per drive its inputs, None where one of its
        TPDOs did not arrive within ``timeout`` (the cycle waits for the last drive, not the first)."""
        self.send_sync()
        synced = time.perf_counter_ns()  # every drive samples at the SYNC: by now they have
        slots = self._slots
        parts: list[list[tuple[Any, ...]]] = [[()] * count for count in self._counts]  # (): not arrived
        missing = sum(self._counts)
        deadline = time.perf_counter() + self.timeout
        while missing:
            frame = receive_direct(self.name, self.link, slots, deadline, self._dispatch)
            if frame is None:
                break
            axis, place, size, unpack = slots[frame[0]]
            stats = self.exchanges[axis].stats
            data = frame[1]
            if len(data) != size:
                stats.dropped_frames += 1
                continue
            if parts[axis][place]:
                stats.stale_tpdos += 1
            else:
                missing -= 1
            parts[axis][place] = unpack(data)
        return [exchange.inputs(found, synced) if () not in found else None
                for exchange, found in zip(self.exchanges, parts)]

    def send_sync(self) -> None:
        """One SYNC frame (every drive samples, and a synchronous drive latches its torque target)."""
        self.exchanges[0].send(self._sync)
        self.syncs_sent += 1

    def send_safe(self) -> None:
        """Zero torque with DISABLE VOLTAGE on every drive, then one SYNC: each latches it at that SYNC.
        Never raises (it runs while an error is being raised, which matters more)."""
        for exchange in self.exchanges:
            exchange.send_safe()  # no SYNC of its own
        try:
            self.send_sync()
        except DriveError as exc:
            logger.error("%s: could not send the SYNC after the safe outputs: %s", self.name, exc)
