"""``bus.asc``: every frame on a run's CAN bus, in Vector's ASCII log format, beside its record.

A second handle on the run's bus (a listener, as ``candump`` is: the virtual bus, udp_multicast
and SocketCAN hand every frame to every handle) is read by a thread of its own; python-can's
own :class:`can.ASCWriter` formats each frame.  Its lines are staged in memory and written to
the file, whole lines only, every :data:`~haptic_bus.app.record_stream.FLUSH_INTERVAL` s, so a
process killed at any moment leaves a log that ``can.LogReader`` reads up to the last flush
(the header's ``date`` and ``Begin Triggerblock`` lines come with the first frames; only
``End TriggerBlock`` is missing, which the reader does not need).  ``python -m can.player``
replays it, ``python -m can.logconvert bus.asc bus.log`` turns it into the candump format that
cantools reads.

The control thread does nothing for the log; the listener costs the process one receive and
one formatted line a frame in its own thread.  An interface that cannot be opened twice (some
vendors' adapters) gives no bus log and a warning, never a failed run.  Modbus has no frames
to log: a Modbus run's record holds each poll's registers (statusword, velocity, torque).
"""

from __future__ import annotations

import io
import logging
import pathlib
import threading
import time
from typing import Any

import can

from drives.bus_config import open_bus
from haptic_bus.app.record_stream import FLUSH_INTERVAL, write_whole
from haptic_bus.errors import DriveError

logger = logging.getLogger(__name__)

LOG_NAME = "bus.asc"


class _Staged(io.StringIO):
    """What the writer formatted since the last drain; the writer's ``stop()`` does not discard it."""

    def close(self) -> None:
        """Kept open: the bus log drains it once more after the writer's last line."""

    def drain(self) -> str:
        """Everything staged so far, removed from the stage."""
        text = self.getvalue()
        self.seek(0)
        self.truncate()
        return text


class BusLog:
    """Every frame ``bus`` receives, into ``path`` (ASC), from a thread of its own (module docstring)."""

    def __init__(self, path: pathlib.Path, bus: can.BusABC, interval: float = FLUSH_INTERVAL) -> None:
        self.path = path
        self.interval = interval
        self.frames = 0
        self._bus = bus
        self._staged = _Staged()
        self._writer = can.ASCWriter(self._staged)
        self._file = io.FileIO(path, "w")
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="bus-log", daemon=True)

    @classmethod
    def open(cls, path: pathlib.Path, bus_config: dict[str, Any]) -> BusLog | None:
        """A started bus log on a new handle of the bus ``bus_config`` names; None (and a warning)
        if the interface refuses a second handle."""
        try:
            bus = open_bus(**bus_config)
        except DriveError as exc:
            logger.warning("no bus log: %s (a second handle on the bus is needed)", exc)
            return None
        log = cls(path, bus)
        log._thread.start()
        return log

    def close(self) -> None:
        """Stop listening, write what is staged and ``End TriggerBlock``, close the file and the handle."""
        self._stop.set()
        self._thread.join(timeout=10 * self.interval + 5.0)
        self._writer.stop()
        write_whole(self._file, self._staged.drain())
        self._file.close()
        self._bus.shutdown()

    def _loop(self) -> None:
        due = time.monotonic() + self.interval
        try:
            while not self._stop.is_set():
                message = self._bus.recv(timeout=max(0.0, due - time.monotonic()))
                if message is not None:
                    self._writer.on_message_received(message)
                    self.frames += 1
                if time.monotonic() >= due:
                    write_whole(self._file, self._staged.drain())
                    due = time.monotonic() + self.interval
        except (can.CanError, OSError) as exc:
            logger.warning("bus log %s: stopped: %s", self.path, exc)
