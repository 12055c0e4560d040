"""``record.csv`` written while the run goes on: a thread drains the controller's ring every
:data:`FLUSH_INTERVAL` s, so a process killed at any moment leaves every cycle but the last
interval's on disk.

The control thread's part stays what :meth:`~haptic_bus.control.record.RunRecord.append` costs
(one ``struct.pack_into`` into a preallocated ring); formatting and writing happen here, in
another thread.  Each drain is written with unbuffered ``write`` calls of whole lines, so the
file holds complete lines only, except when the process dies inside such a call (then the last
line may be torn; :func:`~haptic_bus.control.record.read_record` leaves it out).  Data written
reaches the kernel at once, so it survives the process (``kill -9``), not a power cut (no
``fsync``).  A writer that falls more than the ring's capacity behind loses the oldest rows;
:attr:`RecordStream.lost` counts them (``run.json`` reports it).

``on_flush`` is called in the writer's thread after each drain (the run keeps ``run.json``
current with it).
"""

from __future__ import annotations

import io
import logging
import pathlib
import threading
from collections.abc import Callable

from haptic_bus.control.record import HEADER, RunRecord, format_rows

logger = logging.getLogger(__name__)

FLUSH_INTERVAL = 0.05  # s: the longest a cycle waits in memory before it is written (the issue allows 0.1)
_CHUNK_ROWS = 2000  # rows formatted at a time (the writer gives the interpreter back between chunks)


class RecordStream:
    """Streams ``record``'s rows into ``path`` (created now, header first) from a thread of its own."""

    def __init__(self, path: pathlib.Path, record: RunRecord, on_flush: Callable[[], None] | None = None,
                 interval: float = FLUSH_INTERVAL) -> None:
        self.path = path
        self.record = record
        self.interval = interval
        self.written = 0  # rows written
        self.lost = 0  # rows overwritten in the ring before they could be written
        self._on_flush = on_flush
        self._next = 0  # index of the next row to write
        self._file = io.FileIO(path, "w")
        write_whole(self._file, HEADER)
        self._stop = threading.Event()
        self._lock = threading.Lock()  # one drain at a time: the thread's, or close()'s last one
        self._thread = threading.Thread(target=self._loop, name="record-stream", daemon=True)

    def start(self) -> RecordStream:
        """Start draining; returns self."""
        self._thread.start()
        return self

    def flush(self) -> int:
        """Write every row appended so far; the count written now."""
        with self._lock:
            if self._file.closed:
                return 0
            count = 0
            while True:
                first, rows = self.record.rows_from(self._next)
                if not rows.shape[0]:
                    break
                rows = rows[:_CHUNK_ROWS]
                self.lost += first - self._next
                write_whole(self._file, format_rows(rows))
                self._next = first + rows.shape[0]
                count += rows.shape[0]
            self.written += count
            return count

    def close(self) -> None:
        """Stop the thread, write what is left, close the file (idempotent)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=10 * self.interval + 5.0)
        self.flush()
        self._call_on_flush()
        with self._lock:
            self._file.close()

    def __enter__(self) -> RecordStream:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _loop(self) -> None:
        while not self._stop.wait(self.interval):
            try:
                self.flush()
            except OSError as exc:  # a full disk: the run goes on (its drive is what matters), the record stops
                logger.error("record.csv: cannot write %s (%s); the run goes on without its record", self.path, exc)
                return
            self._call_on_flush()

    def _call_on_flush(self) -> None:
        if self._on_flush is not None:
            try:
                self._on_flush()
            except OSError as exc:
                logger.error("run.json: cannot write it (%s)", exc)


def write_whole(file: io.FileIO, text: str) -> None:
    """Write ``text`` to the unbuffered ``file``, looping over short writes: nothing is held back
    in a buffer, so what the call wrote is in the kernel's hands (and survives the process)."""
    data = memoryview(text.encode())
    while data:
        done = file.write(data)
        data = data[done if done is not None else 0:]
