"""What the drive says between cycles: EMCY, heartbeat, NMT state, and frames it must not send.

canopen's :class:`~canopen.RemoteNode` already consumes the drive's EMCY (``node.emcy``: its
log, its ``active`` list that an error-reset EMCY clears) and heartbeat (``node.nmt``); this
module registers callbacks on them instead of a second pair of subscriptions.  Their decoders
assume well-formed frames (an EMCY is exactly 8 bytes, a heartbeat at least 1), so each
subscription is replaced by a guard that checks the length first: a malformed EMCY or
heartbeat from the drive is a protocol violation the next cycle reports (and the master
stops the drive), never an exception inside a receive thread.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable

import canopen
from canopen.emcy import EmcyError

from drives.canopen.exchange import CanopenStats
from drives.cia301 import EMCY_BASE, EMCY_LENGTH, HEARTBEAT_BASE, NODE_IDS, NmtState, describe_emcy_code, nmt_state_name
from drives.errors import DriveError, DriveFault, DriveProtocolError, DriveTimeout, ParameterError

logger = logging.getLogger(__name__)

Handler = Callable[[int, bytearray, float], None]
_NMT_STATES = frozenset(int(state) for state in NmtState)


def describe_emcy(emcy: EmcyError) -> str:
    """``EMCY 0x8130 (Life guard error or heartbeat error), error register 0x11``."""
    return f"EMCY 0x{emcy.code:04X} ({describe_emcy_code(emcy.code)}), error register 0x{emcy.register:02X}"


class DriveEvents:
    """The drive's EMCY, heartbeat and NMT state as the master sees them.

    ``armed`` (set by the master while the drive is enabled) decides whether an EMCY or an NMT
    state other than OPERATIONAL is an error; ``heartbeat_limit`` (s, 0 = off) how long the
    heartbeat may be silent while armed.
    """

    def __init__(self, name: str, node: canopen.RemoteNode, network: canopen.Network, stats: CanopenStats) -> None:
        self.name = name
        self.node = node
        self.network = network
        self.stats = stats
        self.armed = False
        self.heartbeat_limit = 0.0
        self.nmt_state: int | None = None
        self.last_emcy: EmcyError | None = None
        self._last_heartbeat: float | None = None
        self._pending: DriveError | None = None
        self._state_seen = threading.Condition()
        node_id = node.id
        if node_id is None:  # canopen lets a node take its id from its dictionary; the master always names it
            raise ParameterError("node_id", None, NODE_IDS, f"{name}: the node watched for EMCY and heartbeat")
        self._guards: list[tuple[int, Handler, Handler]] = [
            (EMCY_BASE + node_id, node.emcy.on_emcy, self._guard(node.emcy.on_emcy, EMCY_LENGTH, "EMCY")),
            (HEARTBEAT_BASE + node_id, node.nmt.on_heartbeat, self._guard(node.nmt.on_heartbeat, 1, "heartbeat", _NMT_STATES)),
        ]
        for can_id, original, guard in self._guards:
            network.unsubscribe(can_id, original)
            network.subscribe(can_id, guard)
        node.emcy.add_callback(self._on_emcy)
        node.nmt.add_heartbeat_callback(self._on_heartbeat)

    def release(self) -> None:
        """Give canopen its own subscriptions back (before the node leaves the network)."""
        for can_id, original, guard in self._guards:
            with contextlib.suppress(KeyError, ValueError):
                self.network.unsubscribe(can_id, guard)
            self.network.subscribe(can_id, original)
        self._guards = []

    def _guard(self, handler: Handler, length: int, what: str, first_bytes: frozenset[int] | None = None) -> Handler:
        """``handler`` behind a check: exactly ``length`` bytes, and a first byte in ``first_bytes``
        (masked to 7 bits) where given; anything else is a protocol violation, never handed on."""
        def guarded(can_id: int, data: bytearray, timestamp: float) -> None:
            if len(data) != length or (first_bytes is not None and data[0] & 0x7F not in first_bytes):
                self.stats.malformed_frames += 1
                wants = f"{length} byte{'s' if length > 1 else ''}"
                if first_bytes is not None:
                    wants += f" holding an NMT state ({', '.join(f'0x{s:02X}' for s in sorted(first_bytes))})"
                self._pending = self._pending or DriveProtocolError(
                    self.name, f"malformed {what} frame 0x{can_id:03X} of {len(data)} bytes ({bytes(data).hex() or 'empty'}); "
                    f"CiA 301 wants {wants}",
                )
                return
            handler(can_id, data, timestamp)
        return guarded

    def _on_emcy(self, emcy: EmcyError) -> None:
        self.stats.emcy_count += 1
        if not emcy.code & 0xFF00:  # an error reset
            return
        self.last_emcy = emcy
        if self.armed:  # while disabled an EMCY is news (e.g. the RPDO deadline during SDO work), not a trip
            self._pending = self._pending or DriveFault(self.name, describe_emcy(emcy), code=emcy.code)
        else:
            logger.info("%s: %s while not enabled", self.name, describe_emcy(emcy))

    def _on_heartbeat(self, state: int) -> None:
        self.stats.heartbeats += 1
        self._last_heartbeat = time.monotonic()
        with self._state_seen:
            self.nmt_state = state
            self._state_seen.notify_all()
        if self.armed and state != NmtState.OPERATIONAL:
            self._pending = self._pending or DriveFault(
                self.name, f"node left NMT OPERATIONAL (heartbeat shows {nmt_state_name(state)})"
            )

    def forget_state(self) -> None:
        """Forget the NMT state seen so far (before a command whose answer :meth:`wait_for_state` awaits)."""
        with self._state_seen:
            self.nmt_state = None

    def wait_for_state(self, wanted: int, timeout: float) -> bool:
        """Block until a heartbeat (since :meth:`forget_state`) shows ``wanted``, at most ``timeout`` s."""
        deadline = time.monotonic() + timeout
        with self._state_seen:
            while self.nmt_state != wanted:
                remaining = deadline - time.monotonic()
                if remaining <= 0 or not self._state_seen.wait(remaining):
                    return self.nmt_state == wanted
        return True

    def clear(self) -> None:
        """Forget what was seen before an enable or a fault reset."""
        self._pending = None

    def check(self) -> None:
        """Raise the first event seen since the last check (EMCY, NMT change, malformed frame),
        or a heartbeat silence longer than ``heartbeat_limit`` while armed."""
        if self._pending is not None:
            error, self._pending = self._pending, None
            raise error
        last = self._last_heartbeat
        if self.armed and self.heartbeat_limit and last is not None:
            silent = time.monotonic() - last
            if silent > self.heartbeat_limit:
                raise DriveTimeout(
                    self.name,
                    f"heartbeat lost: none for {silent * 1e3:.0f} ms (consumer time {self.heartbeat_limit * 1e3:.0f} ms)",
                )

    def fault_detail(self) -> tuple[str, int | None]:
        """The newest EMCY as text for a fault-bit message, and its code."""
        emcy = self.last_emcy
        self._pending = None  # the fault bit reports it
        return ("", None) if emcy is None else (f"; {describe_emcy(emcy)}", emcy.code)
