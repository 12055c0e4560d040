"""One SYNC cycle on the wire for the drives on one bus, one drive or several: SYNC out, every
drive's TPDOs of the cycle in, read in the control thread.

A :class:`~drives.canopen.drive.CanopenDrive` alone owns a cycle of its one
:class:`~drives.canopen.exchange.CanopenExchange`; :class:`~drives.canopen.axes.CanopenAxes`
owns one cycle of every axis' exchange (``shared``), so that one SYNC serves every drive: each
samples (and a synchronous drive latches its torque) at the same instant, and the bus carries
the SYNC frame once, not once per axis.

The calling thread reads the bus itself (canopen's notifier paused: :meth:`SyncCycle.begin`)
into one table of every drive's TPDO COB-IDs, until every drive's TPDOs of the cycle are in or
the cycle's timeout passes.  Frames that are no TPDO go to canopen's dispatcher (SDO answers,
heartbeat and EMCY of every node, SDO requests to the controller node) in the same thread.  Each
drive's exchange decodes its own TPDOs (its codecs and layout,
:meth:`~drives.canopen.exchange.CanopenExchange.inputs`) and sends its RPDOs; none sends a SYNC.

Whatever goes wrong on the receive path becomes a typed error: a bus that cannot be read is a
:class:`~drives.errors.DriveError`; a TPDO of the wrong length is dropped and counted in its
drive's ``dropped_frames``, one that arrives after its cycle in ``stale_tpdos``.  Every SYNC
counts in the ``syncs_sent`` of every drive it serves.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Container, Sequence
from typing import Any

import can

from drives.base import CyclicInputs
from drives.canopen.exchange import CanopenExchange, CanopenStats, Unpack
from drives.canopen.link import NetworkLink
from drives.cia301 import SYNC_COB_ID
from drives.errors import DriveError, DriveProtocolError, DriveTimeout
from drives.udp_multicast import FilteredMulticastBus, parts_message

logger = logging.getLogger(__name__)

Slot = tuple[int, int, Unpack, CanopenStats]  # place among every drive's TPDOs, length, unpack, its drive's counters
Inputs = Callable[[list[tuple[Any, ...]], int], CyclicInputs]  # a drive's inputs from its decoded TPDOs


class SyncCycle:
    """SYNC out, every joined drive's TPDOs of the cycle in, on ``link``.

    ``timeout`` (s): how long one cycle waits for all of them.  ``shared``: the cycle serves
    several drives and its owner (:mod:`drives.canopen.axes`) runs it; the drives then run no
    cycle of their own and send no SYNC.  Each drive joins it at construction, in axis order
    (:meth:`join`), and configures it again once commissioning has set its TPDOs up
    (:meth:`configure`).
    """

    def __init__(self, name: str, link: NetworkLink, timeout: float, *, shared: bool = False) -> None:
        self.name = name
        self.link = link
        self.timeout = timeout
        self.shared = shared
        self.exchanges: tuple[CanopenExchange, ...] = ()
        self._sync = can.Message(arbitration_id=SYNC_COB_ID, data=b"", is_extended_id=False)
        self._slots: dict[int, Slot] = {}
        self._count = 0  # TPDOs of one cycle, every drive's
        self._axes: tuple[tuple[Inputs, int, int], ...] = ()  # per drive: its inputs(), its TPDOs' places
        self._stats: tuple[CanopenStats, ...] = ()
        self._alone: Inputs | None = None  # the inputs() of the one drive the cycle serves (None: several)
        self._held: list[can.Message] = []  # frames for canopen's dispatcher the drain read, until the SYNC is out

    def join(self, exchange: CanopenExchange) -> None:
        """Serve ``exchange``'s drive too (the next axis); DriveError if the cycle already serves one
        and is not ``shared``."""
        if self.exchanges and not self.shared:
            raise DriveError(self.name, f"this cycle serves one drive; {exchange.name} needs a shared cycle")
        self.exchanges += (exchange,)
        self.configure()

    def configure(self) -> None:
        """The table of every drive's TPDO COB-IDs as their exchanges hold them now; DriveProtocolError
        if two drives send on one."""
        slots: dict[int, Slot] = {}
        axes = []
        start = 0
        for exchange in self.exchanges:
            for cob, (place, size, unpack) in exchange.slots.items():
                if cob in slots:
                    other = next(e.name for e in self.exchanges if cob in e.slots)
                    raise DriveProtocolError(exchange.name, f"its TPDO COB-ID 0x{cob:03X} is also {other}'s: two "
                                                            "drives cannot share a TPDO on one bus")
                slots[cob] = (start + place, size, unpack, exchange.stats)
            stop = start + len(exchange.slots)
            axes.append((exchange.inputs, start, stop))
            start = stop
        self._slots, self._count, self._axes = slots, start, tuple(axes)
        self._stats = tuple(exchange.stats for exchange in self.exchanges)
        self._alone = self.exchanges[0].inputs if len(self.exchanges) == 1 else None

    # ------------------------------------------------------------------ phases

    def begin(self) -> None:
        """Read the bus in this thread from now on (canopen's notifier paused), every drive's TPDOs let through."""
        self.link.read_directly(frozenset(self._slots))

    def end(self) -> None:
        """Give the bus back to canopen's notifier (SDO needs it)."""
        self.link.read_by_notifier()

    def _dispatch(self, msg: can.Message) -> None:
        self.exchanges[0].dispatch(msg)  # one network for all: any drive's dispatcher reaches every node's subscribers

    # ------------------------------------------------------------------ the cycle

    def drain(self) -> None:
        """Before a SYNC: consume what arrived since the last cycle (late TPDOs are counted, not used).
        Every other frame is held and handed to canopen's dispatcher right after the SYNC, while the
        drives answer it (:meth:`sync_and_collect`): handled before it, a drive's heartbeat (30-350 us in the
        control thread) sent the SYNC that much late, its period varying +-140 us at p1/p99 where the
        cycle's start lateness p99 was 28 us."""
        now = time.perf_counter()
        slots = self._slots
        while (frame := receive_direct(self.name, self.link, slots, now, self._held.append)) is not None:
            _, size, _, stats = slots[frame[0]]
            if len(frame[1]) != size:
                stats.dropped_frames += 1
            else:
                stats.stale_tpdos += 1

    def sync_and_collect(self, check: Callable[[], None] | None = None) -> list[CyclicInputs | None]:
        """SYNC out, then every drive's TPDOs of this cycle: per drive (in axis order) its inputs, None
        where one of its TPDOs did not arrive within ``timeout`` (the cycle waits for the last drive).
        ``check``: called once the frames the drain held are handed on, before the TPDOs are waited for
        (the drives' events: a drive that sent an EMCY and stopped answering trips now, not after the
        timeout; breaker: 15.7 ms at T = 1 ms, 31 ms for three axes, where it had tripped in 0.6 ms)."""
        self.send_sync()
        synced = time.perf_counter_ns()  # every drive samples at the SYNC: by now they have
        if self._held:  # what the drain held, while the drives answer (drain); most cycles none
            held, self._held = self._held, []
            for msg in held:
                self._dispatch(msg)
        if check is not None:
            check()
        slots = self._slots
        parts: list[tuple[Any, ...]] = [()] * self._count  # () until the slot's TPDO arrived
        missing = self._count
        deadline = time.perf_counter() + self.timeout
        while missing:
            frame = receive_direct(self.name, self.link, slots, deadline, self._dispatch)
            if frame is None:
                break
            place, size, unpack, stats = slots[frame[0]]
            data = frame[1]
            if len(data) != size:
                stats.dropped_frames += 1
                continue
            if parts[place]:
                stats.stale_tpdos += 1
            else:
                missing -= 1
            parts[place] = unpack(data)
        if not missing:  # every TPDO in (the hot path): each drive's inputs, no test of its TPDOs
            alone = self._alone
            if alone is not None:  # a drive alone: its inputs, unsliced
                return [alone(parts, synced)]
            return [inputs(parts[start:stop], synced) for inputs, start, stop in self._axes]
        found = [parts[start:stop] for _, start, stop in self._axes]
        return [inputs(part, synced) if () not in part else None for (inputs, _, _), part in zip(self._axes, found)]

    def command(self, words: Sequence[int]) -> list[CyclicInputs]:
        """One exchange for the drives' state machines: the bus read in this thread, SYNC, every drive's
        TPDOs, then each drive's RPDO(``words[i]``, zero torque); every drive's inputs of it, in axis
        order.  DriveTimeout, naming the first drive whose TPDOs did not all arrive within ``timeout``
        (and the others), after the RPDOs went out."""
        self.begin()
        self.drain()
        received = self.sync_and_collect()
        for exchange, word in zip(self.exchanges, words):
            exchange.send_rpdo(word, 0)
        silent = [exchange.name for exchange, inputs in zip(self.exchanges, received) if inputs is None]
        if silent:
            others = f" (nor from {', '.join(silent[1:])})" if silent[1:] else ""
            raise DriveTimeout(silent[0], f"no TPDO within {self.timeout * 1e3:g} ms while commanding the state "
                                          f"machine{others}")
        return [inputs for inputs in received if inputs is not None]

    def send_sync(self) -> None:
        """One SYNC frame (every drive samples, and a synchronous drive latches its torque target)."""
        self.exchanges[0].send(self._sync)  # one bus: the first drive's send, its errors named for it
        for stats in self._stats:
            stats.syncs_sent += 1

    def send_safe(self) -> None:
        """Zero torque with DISABLE VOLTAGE on every drive, then one SYNC: each latches it at that SYNC.
        Never raises (it runs while an error is being raised, which matters more)."""
        for exchange in self.exchanges:
            exchange.send_safe()
        try:
            self.send_sync()
        except DriveError as exc:
            logger.error("%s: could not send the SYNC after the safe outputs: %s", self.name, exc)


def receive_direct(name: str, link: NetworkLink, wanted: Container[int], deadline: float,
                   dispatch: Callable[[can.Message], None]) -> tuple[int, bytes | bytearray] | None:
    """Read ``link``'s bus in this thread until a standard data frame with a COB-ID in ``wanted``
    arrives (returned as ``(cob_id, data)``) or ``deadline`` (``time.perf_counter()`` s) passes
    (None); every other data frame goes to ``dispatch``.  Every frame received is shown to the
    link's tap first.  A receive that fails is a DriveError naming ``name``.

    On ``udp_multicast`` with no tap set, the frames of ``wanted`` are read without building a
    :class:`can.Message` (:meth:`~drives.udp_multicast.FilteredMulticastBus.recv_wanted`); with one, as
    their parts (:meth:`~drives.udp_multicast.FilteredMulticastBus.recv_parts`), which a
    :class:`~drives.canopen.link.PartsTap` takes as they are and any other tap as the message :meth:`recv`
    would have returned, built of them."""
    bus = link.bus
    if bus is None:
        raise DriveError(name, "the bus is closed")
    tap, parts = link.tap, link.tap_parts
    if isinstance(bus, FilteredMulticastBus):
        receive = bus.recv_wanted if tap is None else bus.recv_parts
    else:
        receive = None
    while True:
        remaining = deadline - time.perf_counter()
        try:
            got = bus.recv(remaining if remaining > 0.0 else 0.0) if receive is None else receive(wanted, remaining)
        except Exception as exc:  # any interface's failure: the receive path is gone
            raise DriveError(name, f"CAN receive failed: {exc!r}") from exc
        if got is None:
            return None
        if isinstance(got, tuple):
            if len(got) == 2:  # recv_wanted's (no tap)
                return got
            if parts is not None:
                parts(got[2], got[0], got[1])
            elif tap is not None:
                tap(parts_message(*got), False)
            return got[0], got[1]
        msg = got
        if tap is not None:
            tap(msg, False)
        if msg.is_error_frame or msg.is_remote_frame:
            continue
        can_id = msg.arbitration_id
        if can_id in wanted and not msg.is_extended_id:
            return can_id, msg.data
        dispatch(msg)
