"""``bus.asc``: every CAN frame a run sent or received, in Vector's ASCII log format, beside its record.

Received means through the handle's receive filters, once the cycle reads the bus itself: the drives'
TPDOs, EMCY and heartbeats, SDO and NMT (:meth:`drives.canopen.link.NetworkLink.read_directly`); other
traffic on the bus (another node's PDOs, an extended frame of the same number) is not the run's and is
not in it: a logger of its own on the bus (``python -m can.logger``) sees that.

The control process logs on its one bus handle: the drive link's tap
(:attr:`drives.canopen.link.NetworkLink.tap`) is :class:`FrameTap`, which copies each frame
received or sent into a ring in shared memory (:data:`FRAME`: one ``struct.pack_into`` and a
counter store, :class:`~haptic_bus.control.ring.Ring`).  The run's writer process
(:mod:`~haptic_bus.app.writer_process`) drains the ring with :class:`BusLogFile`: python-can's
own :class:`can.ASCWriter` formats each frame, and the lines go to the file, whole lines only,
at every drain (every :data:`~haptic_bus.app.record_stream.FLUSH_INTERVAL` s), so a process
killed at any moment leaves a log that ``can.LogReader`` reads up to the last drain (the
header's ``date`` and ``Begin Triggerblock`` lines come with the first frames; only ``End
TriggerBlock`` is missing, which the reader does not need).  ``python -m can.player`` replays
it, ``python -m can.logconvert bus.asc bus.log`` turns it into the candump format that cantools
reads.  Frames the heartbeat producer's thread sends pass the tap by (the link's docstring).

A writer more than a ring behind loses the oldest frames; :attr:`BusLogFile.lost` counts them.
Modbus has no frames to log: a Modbus run's record holds each poll's registers (and its writer
process never imports python-can: this module imports it where frames are made and formatted).
"""

from __future__ import annotations

import io
import pathlib
import struct
import threading
import time
from operator import attrgetter
from typing import TYPE_CHECKING

from haptic_bus.app.record_stream import write_whole
from haptic_bus.control.ring import Ring

if TYPE_CHECKING:
    import can

LOG_NAME = "bus.asc"
FRAME = struct.Struct("=dIBB64s")
"""One frame in the ring: Unix time (s), identifier, flags (:data:`_FLAGS`), data length (bytes), data."""
FRAME_CAPACITY = 1 << 16  # frames: 16 s of a 3-axis cycle at T = 1 ms (4 frames a cycle) if the writer stalls
_EXTENDED, _REMOTE, _ERROR, _FD, _SENT = 1, 2, 4, 8, 16


class FrameTap:
    """A link tap that copies each frame into ``ring`` (:data:`FRAME`) with its ``timestamp``: a
    received frame's from the bus, a sent one's the time the link handed it to the bus
    (:meth:`~drives.canopen.link.NetworkLink.send`), so a SYNC is stamped before the TPDOs that
    answer it; a frame without a time of its own (0) is stamped when tapped.  The control thread's
    receive hands it the cycle's TPDOs as their parts (:meth:`received`, a
    :class:`~drives.canopen.link.PartsTap`), without a message built for each.  Several threads tap
    while canopen's notifier reads the bus (its frames, and the caller's SDO requests): a lock
    keeps the ring's writer one at a time (uncontended while the cycle alone reads and sends); an
    answer the notifier taps before its request's sender does is put back in time order by
    :meth:`BusLogFile.drain`.  Not after a stall of this process (stopped, starved of CPU): the frames
    that arrived meanwhile are read, and tapped, after those it sent on resuming, often in a later
    drain; ``bus.asc`` then steps back in time there (21 lines after a SIGSTOP, measured), each frame
    with its own time."""

    def __init__(self, ring: Ring) -> None:
        self._put = ring.put
        self._lock = threading.Lock()

    def __call__(self, msg: can.Message, sent: bool, /) -> None:
        """Copy ``msg`` (``sent``: by this process) into the ring."""
        flags = (msg.is_extended_id | msg.is_remote_frame << 1 | msg.is_error_frame << 2 | msg.is_fd << 3
                 | sent << 4)
        data = msg.data
        length = msg.dlc if msg.is_remote_frame else len(data)  # a remote frame asks for dlc bytes and carries none
        with self._lock:
            self._put(msg.timestamp or time.time(), msg.arbitration_id, flags, length, data)

    def received(self, stamp: float, can_id: int, data: bytes, /) -> None:
        """Copy a received standard data frame, given as its Unix time (s), identifier and data, into the ring."""
        with self._lock:
            self._put(stamp, can_id, 0, len(data), data)


def frames(chunk: bytes) -> list[can.Message]:
    """The frames of a ring's raw records ``chunk``, as python-can messages (``is_rx`` False: sent here)."""
    import can

    return [can.Message(timestamp=stamp, arbitration_id=can_id, is_extended_id=bool(flags & _EXTENDED),
                        is_remote_frame=bool(flags & _REMOTE), is_error_frame=bool(flags & _ERROR),
                        is_fd=bool(flags & _FD), is_rx=not flags & _SENT, dlc=length,
                        data=b"" if flags & _REMOTE else data[:length])
            for stamp, can_id, flags, length, data in FRAME.iter_unpack(chunk)]


class _Staged(io.StringIO):
    """What the writer formatted since the last drain; the writer's ``stop()`` does not discard it."""

    def close(self) -> None:
        """Kept open: the bus log drains it once more after the writer's last line."""

    def take(self) -> str:
        """Everything staged so far, removed from the stage."""
        text = self.getvalue()
        self.seek(0)
        self.truncate()
        return text


def _asc_writer() -> type[can.ASCWriter]:
    """python-can's :class:`can.ASCWriter` with the header's milliseconds in three digits: python-can 4.6.1 writes
    them unpadded (a first frame at 17:19:10.005 gives ``17:19:10.5``), which its own ASCReader and CANoe read as
    10.500 s, every frame of such a log then 0.5-0.9 s late against ``record.csv`` (break15b: +495 ms).  The writer
    formats its ``FORMAT_DATE`` with the milliseconds as an int, so a format spec in the field pads them (the
    constant python-can made a class attribute for a header of another form, PR 955)."""
    import can

    class AscWriter(can.ASCWriter):
        FORMAT_DATE = "%a %b %d %H:%M:%S.{:03d} %Y"

    return AscWriter


class BusLogFile:
    """The frames of ``ring`` (:data:`FRAME`) into ``path`` (ASC), at each :meth:`drain`."""

    def __init__(self, path: pathlib.Path, ring: Ring) -> None:
        self.path = path
        self.ring = ring
        self.frames = 0  # frames written
        self.lost = 0  # frames overwritten in the ring before they could be written
        self._next = 0
        self._staged = _Staged()
        self._writer = _asc_writer()(self._staged)
        self._file = io.FileIO(path, "w")

    def drain(self) -> int:
        """Write every frame the ring holds since the last drain, in time order (two threads' taps can
        reach the ring out of it: :class:`FrameTap`), whole lines; the count written now."""
        first, chunk = self.ring.read_from(self._next)
        self.lost += first - self._next
        found = frames(chunk)
        self._next = first + len(found)
        for message in sorted(found, key=attrgetter("timestamp")):  # stable: frames of one time keep the ring's order
            self._writer.on_message_received(message)
        write_whole(self._file, self._staged.take())
        self.frames += len(found)
        return len(found)

    def close(self, drain: bool = True) -> None:
        """A last drain and ``End TriggerBlock`` (unless not ``drain``: the folder can no longer be
        written), the file closed and the ring let go."""
        if drain:
            self.drain()
        self._writer.stop()
        if drain:
            write_whole(self._file, self._staged.take())
        self._file.close()
        self.ring.close()
