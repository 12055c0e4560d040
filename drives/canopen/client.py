"""One CANopen node reached the way a service tool reaches it: SDO, and listening.

:class:`NodeClient` opens the bus (python-can keyword arguments, as every command takes them),
puts canopen's SDO client for the node on it, and from that moment listens: the heartbeats of
every node (:class:`~drives.canopen.listen.HeartbeatLog`: the NMT state), the node's EMCYs
(:class:`~drives.canopen.listen.EmcyLog`) and the SYNC frames of whoever produces them.  It
sends only what its caller asks: SDO requests (and the abort canopen's client sends when an
answer does not come).  No NMT command, no SYNC, no PDO, no heartbeat of its own.

It is an :class:`~drives.object_access.ObjectAccess` (``read``/``write`` of an
:class:`~drives.cia402.ObjectSpec`).  An SDO request left unanswered raises
:class:`~drives.errors.DriveTimeout` with what the listening heard of the node (its heartbeat
state, or the nodes heard instead), so a wrong node id or a STOPPED node says so in one line.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from typing import Any

import canopen
from canopen import objectdictionary as od

from drives.canopen.link import NetworkLink
from drives.canopen.listen import EmcyLog, FrameCounter, HeartbeatLog
from drives.canopen.master_dictionary import minimal_cia402_od
from drives.canopen.sdo import SdoAccess
from drives.cia301 import HEARTBEAT_BASE, NODE_ID_RANGE, SYNC_COB_ID, NmtState
from drives.cia402 import ObjectSpec
from drives.errors import DriveError, DriveTimeout
from drives.object_access import object_label


class NodeClient:
    """Node ``node_id`` on the bus ``bus``; SDO answers awaited ``timeout`` s.  A context manager:
    the bus is open (and the listening on) inside it.  ``dictionary`` names objects in errors
    (default: the standard CiA-301/402 objects)."""

    def __init__(self, bus: Mapping[str, Any], node_id: int, timeout: float,
                 dictionary: od.ObjectDictionary | None = None) -> None:
        options = dict(bus)
        self.node_id = node_id
        self.name = f"CANopen node {node_id}"
        self.timeout = timeout
        self.link = NetworkLink(self.name, bus_args=(options.pop("interface", None), options.pop("channel", None),
                                                     options.pop("bitrate", None), options))
        self.node = canopen.RemoteNode(node_id, dictionary if dictionary is not None else minimal_cia402_od())
        self.heartbeats = HeartbeatLog()
        self.emcys = EmcyLog(node_id)
        self.syncs = FrameCounter()
        self.opened = 0.0
        self._sdo: SdoAccess | None = None

    def __enter__(self) -> NodeClient:
        network = self.link.open()
        try:
            network.add_node(self.node)
            # canopen's own EMCY and heartbeat decoders assume well-formed frames: ours count the others
            network.unsubscribe(self.emcys.cob_id, self.node.emcy.on_emcy)
            network.unsubscribe(HEARTBEAT_BASE + self.node_id, self.node.nmt.on_heartbeat)
            network.subscribe(self.emcys.cob_id, self.emcys.on_emcy)
            for node_id in range(NODE_ID_RANGE[0], NODE_ID_RANGE[1] + 1):
                network.subscribe(HEARTBEAT_BASE + node_id, self.heartbeats.on_heartbeat)
            network.subscribe(SYNC_COB_ID, self.syncs.on_frame)
        except BaseException:
            self.link.close()
            raise
        self.opened = time.monotonic()
        self._sdo = SdoAccess(self.name, self.node, self.timeout, lambda: None)
        return self

    def __exit__(self, *exc: object) -> None:
        self.link.close()

    @property
    def sdo(self) -> SdoAccess:
        """The node's SDO access (inside the context only)."""
        if self._sdo is None:
            raise DriveError(self.name, "the client is not open")
        return self._sdo

    # ------------------------------------------------------------------ listening

    def listened(self) -> float:
        """Seconds listened so far."""
        return time.monotonic() - self.opened

    def listen_until(self, seconds: float) -> None:
        """Keep listening until ``seconds`` have passed since the bus was opened."""
        time.sleep(max(0.0, seconds - self.listened()))

    def nmt_state(self) -> str | None:
        """The NMT state of the node's last heartbeat, or None if none was heard."""
        return self.heartbeats.state(self.node_id)[0]

    def check_receive(self) -> None:
        """DriveError if canopen's receive thread failed (what was heard may be incomplete)."""
        failure = self.link.receive_failure()
        if failure is not None:
            raise DriveError(self.name, f"CAN receive failed: {failure!r}")

    def silence_hint(self) -> str:
        """What the listening says about a node that did not answer an SDO request."""
        state = self.nmt_state()
        heard = f"{self.listened():.2g} s"
        if state == NmtState.STOPPED.label:
            return "its heartbeat says STOPPED: a STOPPED node serves no SDO (NMT pre-operational or start it first)"
        if state is not None:
            return f"its heartbeat says {state}, yet it does not answer SDO"
        others = sorted(self.heartbeats.heard() - {self.node_id})
        seen = f"heartbeats heard from node(s) {', '.join(map(str, others))}" if others else "no heartbeat heard at all"
        return f"no heartbeat of node {self.node_id} in {heard} either ({seen}): check the node id, bitrate and wiring"

    # ------------------------------------------------------------------ ObjectAccess

    @contextmanager
    def _explained(self) -> Iterator[None]:
        """A DriveTimeout inside gets what the listening heard of the node appended."""
        try:
            yield
        except DriveTimeout as exc:
            raise DriveTimeout(self.name, f"{exc.message}; {self.silence_hint()}") from exc

    def read(self, spec: ObjectSpec) -> int:
        """Object ``spec`` over SDO, in drive units."""
        with self._explained():
            return self.sdo.read_int(spec.index, spec.subindex, spec.data_type)

    def write(self, spec: ObjectSpec, value: int) -> None:
        """Write ``value`` (drive units) to object ``spec`` over SDO."""
        with self._explained():
            self.sdo.write_int(spec.index, spec.subindex, spec.data_type, value)

    def source(self, spec: ObjectSpec) -> str:
        """``"0x6041"`` or ``"0x1400:05"``."""
        return object_label(spec)

    def upload(self, index: int, subindex: int) -> bytes:
        """Raw SDO upload of ``index:subindex``."""
        with self._explained():
            return self.sdo.upload(index, subindex)

    def download(self, index: int, subindex: int, data: bytes) -> None:
        """Raw SDO download of ``data`` to ``index:subindex``."""
        with self._explained():
            self.sdo.download(index, subindex, data)
