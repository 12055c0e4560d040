"""One SYNC/TPDO/RPDO cycle on the wire, with one receive loop over the TPDO slots.

The cyclic path does not use canopen's generic PDO objects (they update variables one by one
from a shared buffer, are not atomic per frame, and accept frames of any length).  It packs
and unpacks whole frames with precompiled ``struct`` codecs (:mod:`drives.canopen.pdo_codec`),
reuses its outgoing ``can.Message`` objects, and never sleeps.  Frames reach the loop from
one of two sources:

``direct`` (default)
    the calling thread reads the bus itself (canopen's notifier is paused); frames that are
    not this drive's TPDOs are handed to canopen's dispatcher, so SDO, heartbeat and EMCY
    consumers keep working.  No thread hand-off per cycle.
``listener``
    canopen's notifier thread keeps reading; the TPDOs come through a queue.

Whatever goes wrong on the receive path becomes a typed error: a bus that cannot be read is
a :class:`~drives.errors.DriveError`; a TPDO of the wrong length is dropped and counted; a
frame that canopen's dispatcher cannot handle is counted as malformed and dropped (canopen's
own notifier does the same), and the drive's own EMCY and heartbeat are length-checked before
canopen sees them (:mod:`drives.canopen.events`).
"""

from __future__ import annotations

import logging
import queue
import time
from collections.abc import Callable, Container
from dataclasses import dataclass
from typing import Any

import can

from drives.base import CyclicInputs
from drives.canopen.link import NetworkLink
from drives.canopen.pdo_codec import PdoCodec
from drives.cia301 import SYNC_COB_ID
from drives.cia402 import CONTROLWORD, POSITION_ACTUAL, STATUSWORD, TARGET_TORQUE, VELOCITY_ACTUAL
from drives.cia402_master import SAFE_CONTROLWORD, CyclicStats
from drives.errors import DriveError

logger = logging.getLogger(__name__)

RX_MODES = ("direct", "listener")
Unpack = Callable[[bytes | bytearray], tuple[Any, ...]]  # a TPDO's struct unpack


@dataclass(slots=True)
class CanopenStats(CyclicStats):
    """Counters of the CANopen exchange (all since construction)."""

    syncs_sent: int = 0
    rpdos_sent: int = 0
    dropped_frames: int = 0  # TPDO frames of the wrong length, never decoded
    malformed_frames: int = 0  # other frames canopen's dispatcher could not handle
    missed_tpdos: int = 0  # cycles whose TPDO did not arrive in tpdo_timeout
    stale_tpdos: int = 0  # TPDOs that arrived after their cycle had timed out
    emcy_count: int = 0
    heartbeats: int = 0


class CanopenExchange:
    """SYNC out, this cycle's TPDOs in, RPDOs out, for one drive on ``link``.

    ``tpdo_codecs`` in TPDO order (together holding 0x6041, 0x606C and optionally 0x6064, and
    whatever else a drive's default mapping carries); ``rpdo_codecs`` in RPDO order, together
    holding the controlword 0x6040 and the target torque 0x6071 and nothing else (one frame,
    (controlword, torque), unless the drive's PDOs made commissioning split them);
    ``timeout`` (s) is how long one cycle waits for all its TPDOs.  :meth:`configure` sets the
    layout commissioning chose and resolves, once, how a frame goes out (:meth:`send`).
    ``produces_sync`` (default True): with False, several drives
    share one SYNC that another object sends (:mod:`drives.canopen.axes_cycle`): this exchange
    then sends no SYNC, not even with its safe outputs, and refuses to run a cycle of its own.
    """

    def __init__(
        self,
        name: str,
        link: NetworkLink,
        tpdo_codecs: tuple[PdoCodec, ...],
        rpdo_codecs: tuple[PdoCodec, ...],
        rx_mode: str,
        timeout: float,
        stats: CanopenStats,
    ) -> None:
        self.name = name
        self.link = link
        self.rx_mode = rx_mode
        self.timeout = timeout
        self.stats = stats
        self.tpdo_cobs: tuple[int, ...] = ()
        self._slots: dict[int, tuple[int, int, Unpack]] = {}
        self._transmit: Callable[[can.Message], None] = self._closed
        self._queue: queue.SimpleQueue[tuple[int, bytes]] = queue.SimpleQueue()
        self._subscribed = False
        self._sync = can.Message(arbitration_id=SYNC_COB_ID, data=b"", is_extended_id=False)
        self.produces_sync = True  # False: another object sends the one SYNC of several drives' cycle
        self._layout(tpdo_codecs, rpdo_codecs)

    def _layout(self, tpdo_codecs: tuple[PdoCodec, ...], rpdo_codecs: tuple[PdoCodec, ...]) -> None:
        """Where statusword, velocity and position sit in the TPDOs, and the RPDO frames."""
        self.tpdo_codecs = tpdo_codecs
        self.rpdo_codecs = rpdo_codecs
        flat = [(spec.index, spec.subindex) for codec in tpdo_codecs for spec in codec.entries]
        position = (POSITION_ACTUAL.index, 0)
        self._at = (flat.index((STATUSWORD.index, 0)), flat.index((VELOCITY_ACTUAL.index, 0)),
                    flat.index(position) if position in flat else None)
        outputs = ((CONTROLWORD.index, 0), (TARGET_TORQUE.index, 0))
        # each RPDO frame: its message and which of (controlword, torque) it carries, in frame order
        self._rpdos = [(can.Message(arbitration_id=0, data=bytes(codec.size), is_extended_id=False), codec.struct.pack_into,
                        tuple(outputs.index((e.index, e.subindex)) for e in codec.entries)) for codec in rpdo_codecs]
        self._rpdo, self._rpdo_pack_into, order = self._rpdos[0]
        self._one_rpdo = len(self._rpdos) == 1 and order == (0, 1)  # the hot path: one frame, one pack_into
        safe = (SAFE_CONTROLWORD, 0)
        self._safe = [can.Message(arbitration_id=0, data=codec.encode(*(safe[i] for i in order)), is_extended_id=False)
                      for codec, (_, _, order) in zip(rpdo_codecs, self._rpdos)]

    def configure(self, tpdo_codecs: tuple[PdoCodec, ...], tpdo_cobs: tuple[int, ...],
                  rpdo_codecs: tuple[PdoCodec, ...], rpdo_cobs: tuple[int, ...]) -> None:
        """The TPDOs and RPDOs commissioning set up: codecs and COB-IDs, in order."""
        self.end()
        self._layout(tpdo_codecs, rpdo_codecs)
        self.tpdo_cobs = tpdo_cobs
        self._slots = {cob: (slot, codec.size, codec.struct.unpack)
                       for slot, (cob, codec) in enumerate(zip(tpdo_cobs, self.tpdo_codecs))}
        for (message, _, _), safe, cob in zip(self._rpdos, self._safe, rpdo_cobs):
            message.arbitration_id = safe.arbitration_id = cob
        self._transmit = self._transmitter()

    def release(self) -> None:
        """Leave the cyclic phase and forget the bus: every later send is "the bus is closed"."""
        self.end()
        self._transmit = self._closed

    def _transmitter(self) -> Callable[[can.Message], None]:
        """How a frame goes out, resolved once: under the network's send lock (shared with canopen's
        SDO and NMT), unless the bus says its ``send`` is safe from several threads at once
        (``concurrent_send``, e.g. the lock-step bus, whose ``send`` runs the receiving node inline:
        holding the lock through that for most of every cycle starves the heartbeat thread, which
        takes the same lock)."""
        network = self.link.network
        bus = network.bus if network is not None else None
        if network is None or bus is None:
            return self._closed
        if getattr(bus, "concurrent_send", False):
            return bus.send
        lock, send = network.send_lock, bus.send

        def locked(msg: can.Message) -> None:
            with lock:
                send(msg)
        return locked

    def _closed(self, msg: can.Message) -> None:
        raise DriveError(self.name, "the bus is closed")

    # ------------------------------------------------------------------ phases

    def begin(self) -> None:
        """Enter the cyclic phase (direct: pause canopen's notifier; listener: subscribe the TPDOs)."""
        if self.rx_mode == "direct":
            self.link.read_directly(frozenset(self.tpdo_cobs))
        elif not self._subscribed and self.link.network is not None:
            for cob in self.tpdo_cobs:
                self.link.network.subscribe(cob, self._on_tpdo)
            self._subscribed = True

    def end(self) -> None:
        """Leave the cyclic phase (canopen's notifier reads the bus again, for SDO)."""
        if self.rx_mode == "direct":
            self.link.read_by_notifier()
        elif self._subscribed and self.link.network is not None:
            for cob in self.tpdo_cobs:
                self.link.network.unsubscribe(cob, self._on_tpdo)
            self._subscribed = False

    def _on_tpdo(self, can_id: int, data: bytearray, timestamp: float) -> None:
        self._queue.put((can_id, bytes(data)))

    # ------------------------------------------------------------------ receive

    def _receive(self, deadline: float) -> tuple[int, bytes | bytearray] | None:
        """The next frame on one of the TPDO COB-IDs before ``deadline`` (perf_counter s), or None."""
        if self.link.direct:
            return receive_direct(self.name, self.link, self._slots, deadline, self.dispatch)
        failure = self.link.receive_failure()
        if failure is not None:
            raise DriveError(self.name, f"CAN receive failed: {failure!r}")
        remaining = deadline - time.perf_counter()
        try:
            return self._queue.get(remaining > 0.0, remaining if remaining > 0.0 else None)
        except queue.Empty:
            return None

    def dispatch(self, msg: can.Message) -> None:
        """Direct mode: a frame that is not ours goes to canopen's subscribers (SDO, heartbeat, EMCY)."""
        network = self.link.network
        if network is None:
            return
        try:
            network.notify(msg.arbitration_id, msg.data, msg.timestamp)
        except Exception as exc:  # canopen's notifier logs and drops such a frame; so do we, counted
            self.stats.malformed_frames += 1
            logger.debug("%s: frame 0x%03X %s dropped: %r", self.name, msg.arbitration_id, bytes(msg.data).hex(), exc)

    def drain(self) -> None:
        """Before a SYNC: consume what arrived since the last cycle (late TPDOs are counted, not used)."""
        now = time.perf_counter()
        slots = self._slots
        while (frame := self._receive(now)) is not None:
            if len(frame[1]) != slots[frame[0]][1]:
                self.stats.dropped_frames += 1
            else:
                self.stats.stale_tpdos += 1

    @property
    def slots(self) -> dict[int, tuple[int, int, Unpack]]:
        """TPDO COB-ID -> (its place among this drive's TPDOs, its length in bytes, its ``struct`` unpack)."""
        return self._slots

    def inputs(self, parts: list[tuple[Any, ...]], synced: int) -> CyclicInputs:
        """One cycle's inputs from the decoded TPDOs ``parts`` (in TPDO order, all present);
        ``synced``: ``time.perf_counter_ns()`` right after the SYNC left."""
        values = parts[0] if len(parts) == 1 else sum(parts, ())
        sw, vel, pos = self._at
        return CyclicInputs(values[sw], values[vel], None if pos is None else values[pos], sampled_by_ns=synced)

    def exchange(self) -> CyclicInputs | None:
        """SYNC out, then this cycle's inputs from every TPDO of the cycle; None on timeout."""
        if not self.produces_sync:
            raise DriveError(self.name, "this drive shares a SYNC another object sends: its cycles run there")
        self.send(self._sync)
        synced = time.perf_counter_ns()  # the drive samples at the SYNC: by now it has
        self.stats.syncs_sent += 1
        slots = self._slots
        count = len(slots)
        parts: list[tuple[Any, ...]] = [()] * count  # () until the slot's TPDO arrived
        missing = count
        deadline = time.perf_counter() + self.timeout
        while missing:
            frame = self._receive(deadline)
            if frame is None:
                return None
            slot, size, unpack = slots[frame[0]]
            data = frame[1]
            if len(data) != size:
                self.stats.dropped_frames += 1
                continue
            if parts[slot]:
                self.stats.stale_tpdos += 1
            else:
                missing -= 1
            parts[slot] = unpack(data)
        return self.inputs(parts, synced)

    # ------------------------------------------------------------------ send

    def send(self, msg: can.Message) -> None:
        """Send one frame the way :meth:`configure` resolved (:meth:`_transmitter`), then hand it to
        the link's tap, if set; DriveError "the bus is closed" before it and after :meth:`release`."""
        try:
            self._transmit(msg)
        except (can.CanError, OSError) as exc:
            raise DriveError(self.name, f"CAN send failed: {exc!r}") from exc
        tap = self.link.tap
        if tap is not None:
            tap(msg, True)

    def send_rpdo(self, controlword: int, torque: int) -> None:
        """The RPDO(s): ``controlword`` and ``torque`` (per mille), packed in place."""
        if self._one_rpdo:
            msg = self._rpdo
            self._rpdo_pack_into(msg.data, 0, controlword, torque)
            self.send(msg)
            self.stats.rpdos_sent += 1
            return
        values = (controlword, torque)
        for msg, pack_into, order in self._rpdos:
            pack_into(msg.data, 0, *[values[i] for i in order])
            self.send(msg)
            self.stats.rpdos_sent += 1

    def send_safe(self) -> None:
        """Zero torque with DISABLE VOLTAGE, and one SYNC so that a synchronous drive applies it (none
        where another object sends the SYNC: it sends one after every drive's safe outputs).

        Never raises: it runs while another error is being raised, which matters more.
        """
        try:
            for msg in self._safe:
                self.send(msg)
                self.stats.rpdos_sent += 1
            if self.produces_sync:
                self.send(self._sync)
                self.stats.syncs_sent += 1
        except DriveError as exc:
            logger.error("%s: could not send the safe stop frame: %s", self.name, exc)


def receive_direct(name: str, link: NetworkLink, wanted: Container[int], deadline: float,
                   dispatch: Callable[[can.Message], None]) -> tuple[int, bytearray] | None:
    """Read ``link``'s bus in this thread until a standard data frame with a COB-ID in ``wanted``
    arrives (returned as ``(cob_id, data)``) or ``deadline`` (``time.perf_counter()`` s) passes
    (None); every other data frame goes to ``dispatch``; every frame to ``link.tap`` first, if set.
    A receive that fails is a DriveError naming ``name``."""
    bus = link.bus
    if bus is None:
        raise DriveError(name, "the bus is closed")
    while True:
        remaining = deadline - time.perf_counter()
        try:
            msg = bus.recv(remaining if remaining > 0.0 else 0.0)
        except Exception as exc:  # any interface's failure: the receive path is gone
            raise DriveError(name, f"CAN receive failed: {exc!r}") from exc
        if msg is None:
            return None
        tap = link.tap
        if tap is not None:
            tap(msg, False)
        if msg.is_error_frame or msg.is_remote_frame:
            continue
        can_id = msg.arbitration_id
        if can_id in wanted and not msg.is_extended_id:
            return can_id, msg.data
        dispatch(msg)
