"""The master's own heartbeat (CiA 301 7.2.8.3.2.2): boot-up once, then OPERATIONAL every period.

The drive watches it (its consumer entry 0x1016) and stops on its own when it stops.  It is
sent by a thread of this process, never by a kernel timer (SocketCAN's broadcast manager would
keep sending for a process that is stopped), so a killed or stopped controller stops saying
it is alive.  The boot-up message counts as the first heartbeat.
"""

from __future__ import annotations

import logging
import threading
import time

import can

from drives.cia301 import HEARTBEAT_BASE, NmtState

logger = logging.getLogger(__name__)


class HeartbeatProducer:
    """Node ``node_id``'s heartbeat on ``bus`` every ``period`` s, sends under ``lock``.  ``shared``:
    several drives' masters use it (one controller node): only its owner stops it."""

    def __init__(self, node_id: int, period: float, shared: bool = False) -> None:
        self.node_id = node_id
        self.period = period
        self.shared = shared
        self.sent = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self, bus: can.BusABC, lock: threading.Lock | threading.RLock) -> None:
        """Boot-up now, then a heartbeat showing OPERATIONAL every period (nothing if period is 0)."""
        if self._thread is not None or self.period <= 0:
            return
        cob_id = HEARTBEAT_BASE + self.node_id
        boot = can.Message(arbitration_id=cob_id, data=bytes([NmtState.BOOT_UP]), is_extended_id=False)
        beat = can.Message(arbitration_id=cob_id, data=bytes([NmtState.OPERATIONAL]), is_extended_id=False)
        with lock:
            bus.send(boot)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, args=(bus, lock, beat), daemon=True,
                                        name=f"heartbeat-{self.node_id}")
        self._thread.start()

    def _run(self, bus: can.BusABC, lock: threading.Lock | threading.RLock, beat: can.Message) -> None:
        due = time.monotonic() + self.period
        while not self._stop.wait(max(due - time.monotonic(), 0.0)):
            try:
                with lock:
                    bus.send(beat)
                self.sent += 1
            except (can.CanError, OSError) as exc:  # the bus is gone: the drive will notice the silence
                logger.error("heartbeat of node %d stopped: %s", self.node_id, exc)
                return
            due += self.period
            now = time.monotonic()
            if due < now:  # late (a stalled machine): the next one a period from now, no burst
                due = now + self.period

    def stop(self) -> None:
        """No more heartbeats (the drive's consumer will see the silence unless it was switched off)."""
        thread, self._thread = self._thread, None
        if thread is not None:
            self._stop.set()
            thread.join(timeout=max(1.0, 2 * self.period))
