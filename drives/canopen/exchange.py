"""One drive's part of the SYNC cycle on the wire: its TPDO layout and codecs, its RPDOs, its counters.

The cyclic path does not use canopen's generic PDO objects (they update variables one by one
from a shared buffer, are not atomic per frame, and accept frames of any length).  It packs
and unpacks whole frames with precompiled ``struct`` codecs (:mod:`drives.canopen.pdo_codec`)
and reuses its outgoing ``can.Message`` objects.  The SYNC and the receive loop are the
cycle's, one for every drive on the bus (:mod:`drives.canopen.sync_cycle`): it reads the
frames in the control thread and hands this exchange's TPDOs back decoded (:attr:`~CanopenExchange.slots`),
which :meth:`~CanopenExchange.inputs` turns into the cycle's inputs; frames that are no
TPDO of the cycle go to canopen's dispatcher (:meth:`~CanopenExchange.dispatch`), so SDO,
heartbeat and EMCY consumers keep working.

Whatever goes wrong on the send path becomes a :class:`~drives.errors.DriveError`; a frame
that canopen's dispatcher cannot handle is counted as malformed and dropped (canopen's own
notifier does the same), and the drive's own EMCY and heartbeat are length-checked before
canopen sees them (:mod:`drives.canopen.events`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import can

from drives.base import CyclicInputs
from drives.canopen.link import NetworkLink
from drives.canopen.pdo_codec import PdoCodec
from drives.cia402 import CONTROLWORD, POSITION_ACTUAL, SAFE_CONTROLWORD, STATUSWORD, TARGET_TORQUE, VELOCITY_ACTUAL
from drives.cia402_master import CyclicStats
from drives.errors import DriveError

logger = logging.getLogger(__name__)

Unpack = Callable[[bytes | bytearray], tuple[Any, ...]]  # a TPDO's struct unpack


@dataclass(slots=True)
class CanopenStats(CyclicStats):
    """Counters of one CANopen drive (all since construction)."""

    syncs_sent: int = 0  # SYNC frames of the cycle that serves this drive (one SYNC serves every drive on it)
    rpdos_sent: int = 0
    dropped_frames: int = 0  # TPDO frames of the wrong length, never decoded
    malformed_frames: int = 0  # other frames canopen's dispatcher could not handle
    missed_tpdos: int = 0  # cycles whose TPDO did not arrive in tpdo_timeout
    stale_tpdos: int = 0  # TPDOs that arrived after their cycle had timed out
    emcy_count: int = 0
    heartbeats: int = 0


class CanopenExchange:
    """One drive's TPDOs decoded and RPDOs sent on ``link`` (every frame through the link:
    :meth:`~drives.canopen.link.NetworkLink.send`, and its tap); the SYNC and the receive loop are
    its :class:`~drives.canopen.sync_cycle.SyncCycle`'s.

    ``tpdo_codecs`` in TPDO order (together holding 0x6041, 0x606C and optionally 0x6064, and
    whatever else a drive's default mapping carries); ``rpdo_codecs`` in RPDO order, together
    holding the controlword 0x6040 and the target torque 0x6071 and nothing else (one frame,
    (controlword, torque), unless the drive's PDOs made commissioning split them).
    :meth:`configure` sets the layout commissioning chose and resolves, once, how a frame goes
    out (:meth:`send`).
    """

    def __init__(
        self,
        name: str,
        link: NetworkLink,
        tpdo_codecs: tuple[PdoCodec, ...],
        rpdo_codecs: tuple[PdoCodec, ...],
        stats: CanopenStats,
    ) -> None:
        self.name = name
        self.link = link
        self.stats = stats
        self.tpdo_cobs: tuple[int, ...] = ()
        self._slots: dict[int, tuple[int, int, Unpack]] = {}
        self._transmit: Callable[[can.Message], None] = self._closed
        self._layout(tpdo_codecs, rpdo_codecs)

    def _layout(self, tpdo_codecs: tuple[PdoCodec, ...], rpdo_codecs: tuple[PdoCodec, ...]) -> None:
        """Where statusword, velocity and position sit in the TPDOs, and the RPDO frames."""
        self.tpdo_codecs = tpdo_codecs
        self.rpdo_codecs = rpdo_codecs
        flat = [(spec.index, spec.subindex) for codec in tpdo_codecs for spec in codec.entries]
        where = [(tpdo, value) for tpdo, codec in enumerate(tpdo_codecs) for value in range(len(codec.entries))]
        position = (POSITION_ACTUAL.index, 0)
        # each as (which TPDO, which of its values): a cycle reads it there, no tuple of every TPDO's values joined
        self._at = (where[flat.index((STATUSWORD.index, 0))], where[flat.index((VELOCITY_ACTUAL.index, 0))],
                    where[flat.index(position)] if position in flat else None)
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
        self._layout(tpdo_codecs, rpdo_codecs)
        self.tpdo_cobs = tpdo_cobs
        self._slots = {cob: (slot, codec.size, codec.struct.unpack)
                       for slot, (cob, codec) in enumerate(zip(tpdo_cobs, self.tpdo_codecs))}
        for (message, _, _), safe, cob in zip(self._rpdos, self._safe, rpdo_cobs):
            message.arbitration_id = safe.arbitration_id = cob
        self._transmit = self.link.send  # under the network's send lock where the bus needs one; tapped

    def release(self) -> None:
        """Forget the bus: every later send is "the bus is closed"."""
        self._transmit = self._closed

    def _closed(self, msg: can.Message) -> None:
        raise DriveError(self.name, "the bus is closed")

    # ------------------------------------------------------------------ receive

    def dispatch(self, msg: can.Message) -> None:
        """A frame that is no TPDO of the cycle goes to canopen's subscribers (SDO, heartbeat, EMCY)."""
        network = self.link.network
        if network is None:
            return
        try:
            network.notify(msg.arbitration_id, msg.data, msg.timestamp)
        except Exception as exc:  # canopen's notifier logs and drops such a frame; so do we, counted
            self.stats.malformed_frames += 1
            logger.debug("%s: frame 0x%03X %s dropped: %r", self.name, msg.arbitration_id, bytes(msg.data).hex(), exc)

    @property
    def slots(self) -> dict[int, tuple[int, int, Unpack]]:
        """TPDO COB-ID -> (its place among this drive's TPDOs, its length in bytes, its ``struct`` unpack)."""
        return self._slots

    def inputs(self, parts: list[tuple[Any, ...]], synced: int) -> CyclicInputs:
        """One cycle's inputs from the decoded TPDOs ``parts`` (in TPDO order, all present);
        ``synced``: ``time.perf_counter_ns()`` right after the SYNC left."""
        (sw, sw_at), (vel, vel_at), pos = self._at
        return CyclicInputs(parts[sw][sw_at], parts[vel][vel_at], None if pos is None else parts[pos[0]][pos[1]],
                            sampled_by_ns=synced)

    # ------------------------------------------------------------------ send

    def send(self, msg: can.Message) -> None:
        """Send one frame through the link (:meth:`~drives.canopen.link.NetworkLink.send`); DriveError "the
        bus is closed" before it and after :meth:`release`."""
        try:
            self._transmit(msg)
        except (can.CanError, OSError) as exc:
            raise DriveError(self.name, f"CAN send failed: {exc!r}") from exc

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
        """Zero torque with DISABLE VOLTAGE (no SYNC: the cycle sends one after every drive's,
        :meth:`~drives.canopen.sync_cycle.SyncCycle.send_safe`).

        Never raises: it runs while another error is being raised, which matters more.
        """
        try:
            for msg in self._safe:
                self.send(msg)
                self.stats.rpdos_sent += 1
        except DriveError as exc:
            logger.error("%s: could not send the safe stop frame: %s", self.name, exc)
