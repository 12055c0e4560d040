"""The run's writer process as the control process sees it: rings to fill, a few messages, a stop.

:class:`RunWriter` starts :mod:`~haptic_bus.app.writer_process` (before commissioning, so that
commissioning's frames are logged, and long before pre-flight) and hands it:

- the frame ring (with ``bus_log``): :attr:`RunWriter.tap` is the drive link's tap
  (:class:`~haptic_bus.app.bus_log.FrameTap`);
- each axis' record (:meth:`RunWriter.stream`: a :class:`~haptic_bus.control.record.RunRecord`
  made in shared memory, ``shared_record`` / ``shared_records`` of the controllers);
- ``run.json``'s document once, then each event (:meth:`RunWriter.follow`: the event log's
  listener; the scenes too when an event changed them);
- the live view's title (:meth:`RunWriter.live`).

What crosses while the cycles run is the rings (no system call, no lock) and, for each event,
one pickled message on a pipe (events are rare: uploads, alarms, the end).  A write the writer
cannot make (a full disk, the folder deleted) comes back on a pipe of its own, which a thread
named ``hb-write-watch`` waits on, blocked in ``read`` (never scheduled until then, so it costs
the cycle nothing): it keeps the line (:attr:`RunWriter.failure`) and calls ``on_failure``, which
for ``haptic-bus run`` asks the run to stop at the next cycle boundary.  A shared segment's
name is removed as soon as the writer has attached to it, so nothing is left in ``/dev/shm``
whatever kills the processes.  :meth:`RunWriter.close` stops the writer after its last drain and
returns what it wrote and lost (``run.json``'s ``record`` and ``bus_log``).

A run whose drive is in the control process -- on an in-process bus
(:data:`drives.bus_config.IN_PROCESS_INTERFACES`: the demos, the pytest plugin's and the tests'
simulated drive), or over Modbus TCP to servers all served by this process
(:mod:`drives.modbus.in_process`) -- gets the same writer, :func:`~haptic_bus.app.writer_process.serve` over the
same pipe and rings, in a thread named ``hb-writer`` instead of a process (:func:`writer_for`).
Such a run's cycle already shares the interpreter lock with its drive, whose code runs in the
control process, so a writer process would not give the cycle the lock to itself; a kill of the
process ends its drive with it; and a spawn costs an interpreter and its imports (about 0.25 s of
CPU), a large part of a demo's or a test's whole run.  The one thing the thread gives up: after a ``kill -9`` the rows
not yet drained (at most one drain interval, 50 ms) are not written.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import pathlib
import sys
import threading
import types
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from multiprocessing.connection import Connection
from typing import Any

from drives.bus_config import IN_PROCESS_INTERFACES
from drives.modbus.in_process import served_here
from haptic_bus.app import writer_process
from haptic_bus.app.bus_log import FRAME, FRAME_CAPACITY, FrameTap
from haptic_bus.control.record import Event, EventLog, RunRecord
from haptic_bus.control.ring import Ring

logger = logging.getLogger(__name__)

PROCESS_NAME = "haptic-bus-writer"
START_TIMEOUT = 60.0  # s: the writer starts an interpreter before it answers (long only on a stalled machine)
STOP_TIMEOUT = 30.0  # s: its last drain of up to a ring of rows per axis
WATCH_THREAD = "hb-write-watch"  # the thread that waits for the writer's alarm (a failed write)
SCENE_EVENTS = frozenset(("upload", "derate"))  # events that come with a new scene


@contextmanager
def _main_module_hidden() -> Iterator[None]:
    """While a process starts: no ``__main__`` for "spawn" to import again in it.  The writer needs
    only this package; a caller's script without an ``if __name__ == "__main__"`` guard would
    otherwise run again, whole, inside the writer."""
    main = sys.modules["__main__"]
    sys.modules["__main__"] = types.ModuleType("__main__")
    try:
        yield
    finally:
        sys.modules["__main__"] = main


def writer_for(link: dict[str, Any]) -> bool:
    """Whether a run on ``link`` (``run.json``'s ``link``) gets a writer thread rather than a
    process: its CAN bus is in-process, or every Modbus server it reaches serves in this process
    (module docstring)."""
    if link.get("kind") == "modbus":
        return all(served_here(url) for url in link.get("urls", [link.get("url")]))
    return link.get("kind") == "canopen" and link.get("bus", {}).get("interface") in IN_PROCESS_INTERFACES


class RunWriter:
    """The writer of a run writing into ``folder`` (module docstring): a process, or with
    ``in_process`` a thread of this process; ``bus_log``: a frame ring and ``bus.asc`` too."""

    def __init__(self, folder: pathlib.Path, bus_log: bool, in_process: bool = False,
                 on_failure: Callable[[], None] | None = None) -> None:
        context = multiprocessing.get_context("spawn")
        self._conn, child = context.Pipe()
        alarms, alarm = context.Pipe(duplex=False)
        self._lock = threading.Lock()  # one message at a time: the control thread's and the upload server's
        self._broken = False
        self.failure: str | None = None  # why the folder could not be written (the writer's one line), if so
        self.frames = Ring.shared(FRAME, FRAME_CAPACITY) if bus_log else None
        frames = None if self.frames is None else self.frames.spec
        self.process: multiprocessing.process.BaseProcess | threading.Thread
        if in_process:
            self.process = threading.Thread(target=writer_process.serve, name=writer_process.COMM, daemon=True,
                                            args=(str(folder), frames, child, None, alarm))
            self.process.start()
            self._child: Connection | None = child  # closed once the thread has ended
        else:
            self.process = context.Process(target=writer_process.main, name=PROCESS_NAME, daemon=True,
                                           args=(str(folder), frames, child, os.getpid(), alarm))
            with _main_module_hidden():
                self.process.start()
            child.close()  # the child's end is the process' now (a thread uses this one)
            alarm.close()
            self._child = None
        self._watch = threading.Thread(target=self._watch_alarms, name=WATCH_THREAD, daemon=True,
                                       args=(alarms, on_failure))
        self._watch.start()
        self._await("ready", START_TIMEOUT)
        if self.frames is not None:
            self.frames.unlink()
        self.tap = None if self.frames is None else FrameTap(self.frames)

    def stream(self, files: Sequence[tuple[str, str, RunRecord]]) -> None:
        """Stream each ``(file name, axis name, record)``'s rows into that file of the folder."""
        for name, axis, record in files:
            self._send(("record", name, record.spec, axis))
            self._await("attached", START_TIMEOUT)
            record.unlink()

    def journal(self, document: dict[str, Any]) -> None:
        """``run.json``'s document as it stands (written by the writer at its next drain)."""
        self._send(("journal", document))

    def follow(self, events: EventLog, scenes: Callable[[], list[dict[str, Any]]]) -> None:
        """From now on hand each event of ``events`` to the writer, with ``scenes()`` (the run's
        scenes, JSON-ready) when the event brought a new one."""
        def listener(event: Event) -> None:
            self._send(("event", len(events.events), event.to_dict(), scenes() if event.kind in SCENE_EVENTS else None))

        events.listener = listener

    def live(self, title: str, period: float, duration: float | None) -> None:
        """Show the live view of the streamed records (``period`` s the run's ``T``, ``duration`` s its length)."""
        self._send(("live", title, period, duration))

    def close(self) -> dict[str, Any]:
        """Stop the writer after its last drain and wait for it; what it wrote and lost (empty if it died)."""
        stats: dict[str, Any] = {}
        try:
            self._send(("stop",))
            stats = self._await("stats", STOP_TIMEOUT)[1]
        except OSError as exc:
            logger.error("run writer: %s", exc)
        self.failure = self.failure or stats.get("failure")
        self.process.join(STOP_TIMEOUT)
        if isinstance(self.process, multiprocessing.process.BaseProcess) and self.process.is_alive():
            self.process.kill()
            self.process.join()
        if self._child is not None and not self.process.is_alive():
            self._child.close()
        self._conn.close()
        self._watch.join(STOP_TIMEOUT)  # the writer has closed its alarm pipe: the thread is ending
        return stats

    def _watch_alarms(self, alarms: Connection, on_failure: Callable[[], None] | None) -> None:
        """The watch thread: wait for the writer's one alarm (a failed write), keep its line and call
        ``on_failure``; end when the writer closes the pipe."""
        with alarms:
            try:
                _, self.failure = alarms.recv()
            except (EOFError, OSError):
                return
        if on_failure is not None:
            on_failure()

    def _send(self, message: tuple[Any, ...]) -> None:
        """Send a message; a writer gone is logged once (the run goes on: its drive is what matters)."""
        with self._lock:
            if self._broken:
                return
            try:
                self._conn.send(message)
            except OSError as exc:
                self._broken = True
                logger.error("run writer: gone (%s); the run goes on without its files", exc)

    def _await(self, kind: str, timeout: float) -> tuple[Any, ...]:
        """The writer's next message, which must be of ``kind``; OSError if it does not come within ``timeout`` s."""
        try:
            if self._conn.poll(timeout):
                message: tuple[Any, ...] = self._conn.recv()
                if message[0] == kind:
                    return message
                raise OSError(f"the run's writer process answered {message[0]!r} where {kind!r} was due")
        except EOFError:
            pass
        ended = f"exit code {self.process.exitcode}" if isinstance(self.process, multiprocessing.process.BaseProcess) \
            else f"its thread {'runs' if self.process.is_alive() else 'ended'}"
        raise OSError(f"the run's writer ({PROCESS_NAME}) did not answer {kind!r} within {timeout:g} s ({ended})")
