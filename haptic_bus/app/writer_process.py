"""The run's writer process: everything a run writes while it cycles, away from the control process.

Started by :class:`~haptic_bus.app.run_writer.RunWriter` (``multiprocessing``'s "spawn"
context, named :data:`~haptic_bus.app.run_writer.PROCESS_NAME`, and :data:`COMM` where ``ps`` and
``top`` show it) before commissioning, it
attaches to the rings the control process fills (each axis' record, the bus' frames: shared
memory, :mod:`~haptic_bus.control.ring`) and every :data:`~haptic_bus.app.record_stream.FLUSH_INTERVAL` s

- drains each record ring into its ``record*.csv`` (:class:`~haptic_bus.app.record_stream.RecordFile`)
  and the frame ring into ``bus.asc`` (:class:`~haptic_bus.app.bus_log.BusLogFile`), whole lines;
- rewrites ``run.json`` (atomically: :func:`~haptic_bus.app.run_json.write_json`) when an event
  or a scene came since the last write (the control process sends the document once, before the
  cycles, then each event);
- once a second draws the live view (:mod:`~haptic_bus.app.live`), when asked for one.

It imports what writing needs: the rings, the standard library, and python-can's ASC writer for
a bus log; not numpy (records are formatted from the ring's struct records), not the profiles,
gates and analysis ``run.json``'s document is made from (:mod:`~haptic_bus.app.run_json`), and
the live view's numpy and rich only when a view is asked for.  A spawned process pays its
imports at each run's start (``tests/test_architecture.py`` pins the set).

A write that fails (a full disk, the folder deleted or replaced while the run goes on: checked
at each drain) ends the writing, not the writer: it says why once on its alarm pipe (``alarm``,
one line naming the folder, the file and the system's reason; the control process stops the run
on it, :class:`~haptic_bus.app.run_writer.RunWriter`), writes nothing more, and keeps serving the
control process until told to stop, whose counts then carry the same line (``failure``).  What
was written before stays.

Messages from the control process come over a pipe (:func:`main`'s ``conn``).  The writer ends
when told to (a last drain, then its counts sent back, and its own CPU time: ``run.json``'s
``writer.cpu_s``), or by itself when the control process
is gone: the pipe's end of file (a ``kill -9`` closes it) or a parent process id that changed,
noticed within one interval, again after a last drain.  Ctrl-C reaches the whole process group:
the writer ignores it and ends when the control process says so.  A run whose drive is in the
control process (an in-process bus: the demos, a test's simulated drive) runs the same loop,
:func:`serve`, in a thread instead (:mod:`~haptic_bus.app.run_writer` says why).
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import logging
import math
import os
import pathlib
import signal
import time
from multiprocessing.connection import Connection
from typing import TYPE_CHECKING, Any

from haptic_bus.app.bus_log import LOG_NAME, BusLogFile
from haptic_bus.app.record_stream import FLUSH_INTERVAL, RecordFile
from haptic_bus.app.run_json import RUN_JSON, write_json
from haptic_bus.control.ring import Ring, RingSpec

if TYPE_CHECKING:
    from haptic_bus.app.live import LiveView

logger = logging.getLogger(__name__)


COMM = "hb-writer"
"""The writer's name where ``ps``, ``top`` and ``/proc/PID/comm`` show it (15 bytes at most)."""
_PR_SET_NAME = 15  # prctl(2)


def name_this_process(name: str) -> None:
    """Give the calling thread ``name`` in ``/proc`` (a process' main thread: its ``/proc/PID/comm``;
    Linux' prctl; elsewhere nothing)."""
    with contextlib.suppress(OSError, AttributeError):  # not Linux: the process keeps its interpreter's name
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_NAME, name.encode()[:15], 0, 0, 0)


class Writer:
    """The writer's state: the files it streams into ``folder``, ``run.json``'s document, the view."""

    def __init__(self, folder: pathlib.Path, conn: Connection, alarm: Connection | None = None) -> None:
        self.folder = folder
        self.conn = conn
        self.alarm = alarm
        self.failure: str | None = None  # why the folder can no longer be written (then nothing more is)
        self._identity = os.stat(folder)  # the folder the run writes: one deleted or replaced is a failure
        self.records: list[tuple[str, RecordFile]] = []  # (axis name, file)
        self.bus_log: BusLogFile | None = None
        self.document: dict[str, Any] | None = None
        self.dirty = False  # the document changed since run.json was written
        self.last_event: dict[str, Any] | None = None
        self.view: LiveView | None = None
        self.view_due = math.inf  # when the view is next redrawn (time.monotonic(), s)
        self.stopped = False

    def handle(self, message: tuple[Any, ...]) -> None:
        """One message from the control process (:class:`~haptic_bus.app.run_writer.RunWriter` sends them)."""
        kind = message[0]
        if kind == "record":
            _, name, spec, axis = message
            ring = Ring.attach(spec)
            try:
                self.records.append((axis, RecordFile(self.folder / name, ring)))
            except OSError as exc:  # the folder is gone or full: attached all the same, written never
                ring.close()
                self.fail(exc, name)
            self.conn.send(("attached", name))
        elif kind == "journal":
            self.document = message[1]
            self.dirty = True
        elif kind == "event":
            _, count, event, scenes = message
            self.last_event = event
            if self.document is not None:
                events = self.document.setdefault("events", [])
                if count > len(events):  # an event already in the document is not added twice
                    events.append(event)
                if scenes is not None:
                    self.document["scenes"] = scenes
                self.dirty = True
        elif kind == "live":
            from haptic_bus.app.live import REFRESH, LiveView  # numpy and rich: only for a run that shows it

            _, title, period, duration = message
            self.view_due = time.monotonic() + REFRESH
            self.view = LiveView([(axis, record.ring) for axis, record in self.records], title, period,
                                 duration=duration, last_event=lambda: self.last_event).__enter__()
        elif kind == "stop":
            self.stopped = True

    def flush(self) -> None:
        """Drain every ring into its file, and rewrite ``run.json`` if its document changed; after a
        failed write nothing (:meth:`fail`)."""
        if self.failure is not None:
            return
        doing = "the folder"
        try:
            if not self._still_there():
                raise FileNotFoundError(errno.ENOENT, "deleted or replaced")
            for _, record in self.records:
                doing = record.path.name
                record.drain()
            if self.bus_log is not None:
                doing = self.bus_log.path.name
                self.bus_log.drain()
            if self.dirty and self.document is not None:
                doing, self.dirty = RUN_JSON, False
                write_json(self.folder / RUN_JSON, self.document)
        except OSError as exc:
            self.fail(exc, doing)

    def fail(self, exc: OSError, doing: str) -> None:
        """The folder cannot be written (``exc`` while writing ``doing``): say so once on the alarm pipe,
        write nothing more."""
        self.failure = (f"run folder {self.folder}: {exc.strerror or exc} writing {doing}" if self._still_there() else
                        f"run folder {self.folder}: deleted or replaced while the run wrote it")
        logger.info("run writer: %s", self.failure)  # the control process says it, in its one line
        if self.alarm is not None:
            with contextlib.suppress(OSError):  # a control process gone: nobody to tell
                self.alarm.send(("failed", self.failure))

    def _still_there(self) -> bool:
        """Whether the run's folder is still the one it began writing (not deleted, not replaced)."""
        try:
            return os.path.samestat(os.stat(self.folder), self._identity)
        except OSError:
            return False

    def show(self, now: float) -> None:
        """Redraw the live view if one is shown and its redraw is due at ``now`` (``time.monotonic()``, s)."""
        if self.view is not None and now >= self.view_due:
            from haptic_bus.app.live import REFRESH

            try:
                self.view.update()
            except OSError as exc:  # its reader gone (``run ... | head`` closed the pipe): the files go on
                self._drop_view(exc)
                return
            self.view_due = now + REFRESH

    def _drop_view(self, exc: OSError) -> None:
        """The view's stream can no longer be written (``exc``): no view from now on, and the stream's
        descriptor onto /dev/null, so that nothing flushed there later (this process' exit) fails again.
        The run's files are not the view's: they are written to the end."""
        assert self.view is not None
        logger.info("run writer: the live view's output is gone (%s); the run's files go on", exc)
        with contextlib.suppress(OSError, ValueError):  # a stream without a descriptor: nothing left to flush there
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self.view.stream.fileno())
            os.close(devnull)
        self.view, self.view_due = None, math.inf

    def close(self) -> dict[str, Any]:
        """A last drain, every file closed, the view left showing the end; what was written and lost
        (and the ``failure``, if the folder could not be written)."""
        self.flush()
        if self.view is not None:  # its last panel reads the rings: before the records let them go
            try:
                self.view.__exit__()
            except OSError as exc:
                self._drop_view(exc)
        writable = self.failure is None
        for _, record in self.records:
            record.close(drain=writable)
        if self.bus_log is not None:
            self.bus_log.close(drain=writable)
        stats: dict[str, Any] = {"records": {record.path.name: {"rows_written": record.written, "rows_lost": record.lost}
                                             for _, record in self.records}}
        if self.bus_log is not None:
            stats["bus_log"] = {"frames": self.bus_log.frames, "frames_lost": self.bus_log.lost}
        if self.failure is not None:
            stats["failure"] = self.failure
        return stats


def main(folder: str, frames: RingSpec | None, conn: Connection, parent: int, alarm: Connection | None = None) -> None:
    """The writer process' body (module docstring): ``frames`` the frame ring (None: no bus log),
    ``parent`` the control process' id, ``alarm`` where a failed write is said."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)  # as SIGINT: a SIGTERM to the run's process group (timeout, a
    # service manager's stop) is the control process' to act on; it ends the run, which stops this writer after its
    # last drain ('stop'); a parent gone (any kill) still ends it at its next interval
    serve(folder, frames, conn, parent, alarm)


def serve(folder: str, frames: RingSpec | None, conn: Connection, parent: int | None,
          alarm: Connection | None = None) -> None:
    """The writer's loop (module docstring), in the writer process or, for a run whose drive is in
    the control process, in a thread of it (:class:`~haptic_bus.app.run_writer.RunWriter`);
    ``parent``: the control process' id, watched every interval (None: the writer is a thread of
    it, which ends with it); ``alarm``: where a failed write is said (closed when the writer ends).
    Its thread shows :data:`COMM` in ``/proc``."""
    name_this_process(COMM)
    try:
        _serve(pathlib.Path(folder), frames, conn, parent, alarm)
    finally:
        if alarm is not None:
            alarm.close()


def _serve(folder: pathlib.Path, frames: RingSpec | None, conn: Connection, parent: int | None,
           alarm: Connection | None) -> None:
    writer = Writer(folder, conn, alarm)
    if frames is not None:
        ring = Ring.attach(frames)
        try:
            writer.bus_log = BusLogFile(writer.folder / LOG_NAME, ring)
        except OSError as exc:
            ring.close()
            writer.fail(exc, LOG_NAME)
    conn.send(("ready",))
    now = time.monotonic()
    flush_due = now + FLUSH_INTERVAL
    failed = False
    try:
        while not writer.stopped:
            due = min(flush_due, writer.view_due)
            if conn.poll(max(0.0, due - time.monotonic())):
                writer.handle(conn.recv())
            now = time.monotonic()
            if now >= flush_due:
                writer.flush()
                flush_due = now + FLUSH_INTERVAL
                if parent is not None and os.getppid() != parent:
                    break
            writer.show(now)
    except (EOFError, OSError) as exc:  # the control process is gone (EOF), or a write failed: keep what can be kept
        failed = not isinstance(exc, EOFError)
        if failed:
            logger.error("run writer: %s", exc)
    stats = writer.close()
    # its own CPU (s): a process's every thread, its start and imports included; a thread's, its own
    stats["writer"] = {"cpu_s": round(time.thread_time() if parent is None else time.process_time(), 4)}
    if writer.stopped or failed:  # after a failed write the control process still awaits them (else 30 s lost)
        conn.send(("stats", stats))
