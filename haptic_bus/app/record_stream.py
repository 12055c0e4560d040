"""``record.csv`` written while the run goes on, by the run's writer process: every
:data:`FLUSH_INTERVAL` s it drains the controller's ring (:class:`~haptic_bus.control.record.RunRecord`
in shared memory) into the file, so a control process killed at any moment leaves every cycle
but the last interval's on disk.

The control thread's part stays what :meth:`~haptic_bus.control.record.RunRecord.append` costs
(one ``struct.pack_into`` into a preallocated ring and a counter store); formatting and writing
happen here, in another process.  Each drain is written with unbuffered ``write`` calls of
whole lines, so the file holds complete lines only, except when the writer dies inside such a
call (then the last line may be torn; :func:`~haptic_bus.control.record.read_record` leaves it
out).  Data written reaches the kernel at once, so it survives the processes (``kill -9``), not
a power cut (no ``fsync``).  A writer that falls more than the ring's capacity behind loses the
oldest rows; :attr:`RecordFile.lost` counts them (``run.json`` reports it).
"""

from __future__ import annotations

import io
import pathlib

from haptic_bus.control.record import HEADER, ROW, format_rows
from haptic_bus.control.ring import Ring

FLUSH_INTERVAL = 0.05  # s: the longest a cycle waits in memory before it is written (the issue allows 0.1)
_CHUNK_ROWS = 2000  # rows formatted at a time (bounds the memory a drain after a stall takes)


class RecordFile:
    """Streams the rows of ``ring`` (a :class:`~haptic_bus.control.record.RunRecord`'s, attached
    in the writer process) into ``path`` (created now, header first), at each :meth:`drain`."""

    def __init__(self, path: pathlib.Path, ring: Ring) -> None:
        self.path = path
        self.ring = ring
        self.written = 0  # rows written
        self.lost = 0  # rows overwritten in the ring before they could be written
        self._next = 0  # index of the next row to write
        self._file = io.FileIO(path, "w")
        write_whole(self._file, HEADER)

    def drain(self) -> int:
        """Write every row appended since the last drain; the count written now."""
        count = 0
        while True:
            first, chunk = self.ring.read_from(self._next, _CHUNK_ROWS)
            rows = len(chunk) // ROW.size
            if not rows:
                break
            self.lost += first - self._next
            write_whole(self._file, format_rows(ROW.iter_unpack(chunk)))
            self._next = first + rows
            count += rows
        self.written += count
        return count

    def close(self, drain: bool = True) -> None:
        """A last drain (unless not ``drain``: the folder can no longer be written), the file closed
        and the ring let go (idempotent)."""
        if not self._file.closed:
            if drain:
                self.drain()
            self._file.close()
            self.ring.close()


def write_whole(file: io.FileIO, text: str) -> None:
    """Write ``text`` to the unbuffered ``file``, looping over short writes: nothing is held back
    in a buffer, so what the call wrote is in the kernel's hands (and survives the process)."""
    data = memoryview(text.encode())
    while data:
        done = file.write(data)
        data = data[done if done is not None else 0:]
