"""What nodes say on their own, as a listener that sends nothing hears it: heartbeats, EMCYs, SYNCs.

Each log is a canopen subscriber callback (it runs in canopen's dispatcher thread) and keeps
its own lock.  A frame on the COB-ID that is not what CiA 301 allows there (a heartbeat of
other than 1 byte, an EMCY of other than 8) is counted, never decoded: nothing a node sends
can raise in the receive thread.
"""

from __future__ import annotations

import struct
import threading
import time
from collections import deque

from canopen.emcy import EmcyError

from drives.cia301 import EMCY_BASE, EMCY_LENGTH, HEARTBEAT_BASE, NmtState, nmt_state_name

EMCY_KEPT = 16  # the newest EMCYs an EmcyLog keeps
_EMCY = struct.Struct("<HB5s")


class HeartbeatLog:
    """The NMT state of the last boot-up or heartbeat of each node (fed by canopen's dispatcher thread).

    A boot-up (state byte 0) means the node is now PRE-OPERATIONAL (CiA 301 7.3.2.2.1).  A frame
    on a heartbeat COB-ID that is not exactly one byte is no heartbeat: it is counted, not used.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._states: dict[int, int] = {}
        self._counts: dict[int, int] = {}
        self._booted: set[int] = set()
        self._malformed: dict[int, int] = {}

    def on_heartbeat(self, can_id: int, data: bytes | bytearray, timestamp: float) -> None:
        """canopen subscriber callback for COB-ID 0x700 + node id."""
        node_id = can_id - HEARTBEAT_BASE
        with self._lock:
            if len(data) != 1:
                self._malformed[node_id] = self._malformed.get(node_id, 0) + 1
                return
            state = data[0] & 0x7F
            if state == NmtState.BOOT_UP:
                self._booted.add(node_id)
                state = NmtState.PRE_OPERATIONAL
            self._states[node_id] = state
            self._counts[node_id] = self._counts.get(node_id, 0) + 1

    def heard(self) -> set[int]:
        """Node ids with at least one heartbeat-COB-ID frame (valid or not)."""
        with self._lock:
            return set(self._states) | set(self._malformed)

    def state(self, node_id: int) -> tuple[str | None, bool, int]:
        """(NMT state name or None, boot-up heard, malformed frames) of ``node_id``."""
        with self._lock:
            code = self._states.get(node_id)
            return (None if code is None else nmt_state_name(code)), node_id in self._booted, self._malformed.get(node_id, 0)

    def count(self, node_id: int) -> int:
        """How many valid heartbeats (boot-up included) of ``node_id`` were heard."""
        with self._lock:
            return self._counts.get(node_id, 0)


class EmcyLog:
    """The newest :data:`EMCY_KEPT` EMCYs of one node (error resets included), as canopen's
    :class:`~canopen.emcy.EmcyError` with the time they arrived (``time.monotonic()``)."""

    def __init__(self, node_id: int) -> None:
        self.cob_id = EMCY_BASE + node_id
        self._lock = threading.Lock()
        self._entries: deque[tuple[EmcyError, float]] = deque(maxlen=EMCY_KEPT)
        self.malformed = 0

    def on_emcy(self, can_id: int, data: bytes | bytearray, timestamp: float) -> None:
        """canopen subscriber callback for COB-ID 0x080 + node id."""
        with self._lock:
            if len(data) != EMCY_LENGTH:
                self.malformed += 1
                return
            code, register, extra = _EMCY.unpack(bytes(data))
            self._entries.append((EmcyError(code, register, extra, timestamp), time.monotonic()))

    def entries(self) -> list[tuple[EmcyError, float]]:
        """The kept EMCYs, oldest first, each with its arrival time (``time.monotonic()``)."""
        with self._lock:
            return list(self._entries)


class FrameCounter:
    """How many frames arrived on one COB-ID (a SYNC producer at work, for instance)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.count = 0

    def on_frame(self, can_id: int, data: bytes | bytearray, timestamp: float) -> None:
        """canopen subscriber callback."""
        with self._lock:
            self.count += 1
