"""The master's own heartbeat (CiA 301 7.2.8.3.2.2): boot-up once, then OPERATIONAL every period.

The drive watches it (its consumer entry 0x1016) and stops on its own when it stops.  It is
sent by this process, never by a kernel timer (SocketCAN's broadcast manager would keep sending
for a process that is stopped), so a killed or stopped controller stops saying it is alive.
The boot-up message counts as the first heartbeat.

Two senders take turns, never both at once:

- outside the cyclic phase (commissioning, SDO set-up, enabling) a thread of its own,
  ``heartbeat-<node id>``, sends it every period;
- inside it (:meth:`HeartbeatProducer.from_cycle`) that thread is silenced and the control thread
  sends it itself, every ``round(period / T)`` cycles (every cycle if that rounds to 0), and
  sooner if a period has passed since the last one (cycles slower than ``T`` on a loaded
  machine), right after the cycle's RPDOs (:meth:`HeartbeatProducer.tick`): a cycle that stops,
  stalls or dies stops the heartbeat with it, and the drive's consumer faults the drive.

At each hand-over the next heartbeat is due at most one period after the last one: the cycle
sends its first at its first tick, and the thread, restarted, one period after the cycle's last.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable, Iterator

import can

from drives.cia301 import HEARTBEAT_BASE, NmtState
from drives.errors import DriveError
from drives.os_threads import show_own_name

logger = logging.getLogger(__name__)

Send = Callable[[can.Message], None]


class HeartbeatProducer:
    """Node ``node_id``'s heartbeat every ``period`` s (0: none).  ``shared``: several drives' masters
    use it (one controller node): only its owner stops it."""

    def __init__(self, node_id: int, period: float, shared: bool = False) -> None:
        self.node_id = node_id
        self.period = period
        self.shared = shared
        self.sent = 0
        cob_id = HEARTBEAT_BASE + node_id
        self._boot = can.Message(arbitration_id=cob_id, data=bytes([NmtState.BOOT_UP]), is_extended_id=False)
        self._beat = can.Message(arbitration_id=cob_id, data=bytes([NmtState.OPERATIONAL]), is_extended_id=False)
        self._send: Send | None = None
        self._halt = threading.Event()  # set: the running heartbeat thread sends no more
        self._turn = threading.Lock()  # held by the thread around each beat, and to silence it
        self._thread: threading.Thread | None = None
        self._last = 0.0  # time.monotonic() of the last heartbeat sent
        self._every = 0  # cycles between the cycle's heartbeats (0: the cycle sends none)
        self._countdown = 0

    def start(self, send: Send) -> None:
        """Boot-up now through ``send`` (the link's: locked and tapped), then a heartbeat showing
        OPERATIONAL every period from the heartbeat thread (nothing if the period is 0)."""
        if self._send is not None or self.period <= 0:
            return
        self._send = send
        send(self._boot)
        self._last = time.monotonic()
        self._start_thread()

    def _start_thread(self) -> None:
        halt = self._halt = threading.Event()  # one per thread: a restart never revives an old one
        self._thread = threading.Thread(target=self._run, args=(halt,), daemon=True, name=f"heartbeat-{self.node_id}")
        self._thread.start()

    def _silence_thread(self) -> threading.Thread | None:
        """The heartbeat thread sends nothing from now on (it checks under the same lock before each
        beat), without waiting for it to end; the thread, to join later (None: there was none)."""
        thread, self._thread = self._thread, None
        with self._turn:
            self._halt.set()
        return thread

    def _join(self, thread: threading.Thread | None) -> None:
        if thread is not None:
            thread.join(timeout=max(1.0, 2 * self.period))

    def _run(self, halt: threading.Event) -> None:
        show_own_name()
        due = self._last + self.period
        while not halt.wait(max(due - time.monotonic(), 0.0)):
            with self._turn:
                if halt.is_set() or not self._beat_now():
                    return
            due += self.period
            now = time.monotonic()
            if due < now:  # late (a stalled machine): the next one a period from now, no burst
                due = now + self.period

    def _beat_now(self) -> bool:
        """One heartbeat; False (logged) if the bus is gone: the drive will notice the silence."""
        send = self._send
        if send is None:
            return False
        try:
            send(self._beat)
        except (can.CanError, OSError, DriveError) as exc:  # the bus failed, or the link closed under it
            logger.error("heartbeat of node %d stopped: %s", self.node_id, exc)
            return False
        self.sent += 1
        self._last = time.monotonic()
        return True

    @contextlib.contextmanager
    def from_cycle(self, cycle_period: float) -> Iterator[None]:
        """The cyclic phase (cycles of ``cycle_period`` s): the heartbeat thread stopped, the
        heartbeat sent by :meth:`tick` every ``round(period / cycle_period)`` cycles (at least
        every cycle), or sooner when a period has passed; the thread back afterwards, its first
        beat a period after the cycle's last."""
        if self._thread is None:  # not started (no heartbeat), or the cycle sends it already
            yield
            return
        # silenced, not joined: joining would wait for the GIL (measured up to 29 ms beside one
        # busy thread), while the drive's RPDO deadline runs from the enabling just before
        thread = self._silence_thread()
        self._every = max(1, round(self.period / cycle_period))
        self._countdown = 0  # the first cycle sends one: no gap longer than a period at the hand-over
        try:
            yield
        finally:
            self._every = 0
            self._join(thread)  # ended long ago
            if self._send is not None:
                self._start_thread()

    def tick(self) -> None:
        """One cycle of the cyclic phase: the heartbeat if one is due, by the cycle count or by a
        period past since the last (the control thread sends it)."""
        if self._every:
            self._countdown -= 1
            if self._countdown < 0 or time.monotonic() - self._last >= self.period:
                self._countdown = self._every - 1
                self._beat_now()

    def stop(self) -> None:
        """No more heartbeats (the drive's consumer will see the silence unless it was switched off)."""
        self._every = 0
        self._join(self._silence_thread())
        self._send = None
