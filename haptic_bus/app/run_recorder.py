"""What a run writes, in one place, for one axis or several: its writer process (a thread for a
drive on an in-process bus; :mod:`~haptic_bus.app.run_writer`: each axis' streamed record, the bus
log, ``run.json`` kept current, the live view) and, at the end, the journal completed and the pictures drawn
(:func:`~haptic_bus.app.run_pictures.render_run`, what ``haptic-bus plot`` does).  ``haptic-bus
run`` and ``haptic-bus demo`` record through it, for one axis and for several.
"""

from __future__ import annotations

import pathlib
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from typing import Any

from haptic_bus.app.bus_log import LOG_NAME
from haptic_bus.app.run_folder import RUN_JSON, RunJournal, read_run_folder
from haptic_bus.app.run_writer import RunWriter, writer_for
from haptic_bus.control.cycle_loop import RunSummary
from haptic_bus.control.record import EventLog, RunRecord


class RunRecorder:
    """The files of one run in ``folder``, with ``journal`` its ``run.json``."""

    def __init__(self, folder: pathlib.Path, journal: RunJournal) -> None:
        self.folder = folder
        self.journal = journal
        self.writer: RunWriter | None = None
        self.stats: dict[str, Any] = {}
        self.files: list[str] = []  # the records streamed, file names
        self._failure: str | None = None  # run.json could not be completed (the writer's own: RunWriter.failure)

    def start(self, stack: ExitStack, bus_log: bool, on_failure: Callable[[], None] | None = None) -> RunWriter:
        """Start the writer process (with ``bus_log`` its frame ring and ``bus.asc``), stopped when
        ``stack`` closes; before the drive is reached, so that commissioning's frames are logged.  A
        thread of this process instead when the journal's link is an in-process bus
        (:func:`~haptic_bus.app.run_writer.writer_for`).  ``on_failure`` is called (from another
        thread) if the writer cannot write the folder (:attr:`failure`)."""
        self.writer = writer = RunWriter(self.folder, bus_log, in_process=writer_for(self.journal.link),
                                         on_failure=on_failure)
        stack.callback(self._stop)
        return writer

    @property
    def failure(self) -> str | None:
        """Why the folder could not be written (one line naming it, the file and the reason), or None."""
        return self._failure or (self.writer.failure if self.writer is not None else None)

    def stream(self, writer: RunWriter, records: Sequence[tuple[str, str, RunRecord]], events: EventLog,
               scenes: Callable[[], list[dict[str, Any]]], period: float, live: str | None = None,
               duration: float | None = None) -> None:
        """Stream each ``(file name, axis name, record)`` (records made in shared memory), keep
        ``run.json`` current with ``events`` (and ``scenes()`` when one brought a new scene), and
        show the live view titled ``live`` (None: none) of a run of ``duration`` s at ``T = period`` s."""
        writer.stream(records)
        self.files = [name for name, _, _ in records]
        writer.follow(events, scenes)
        self.publish()
        if live is not None:
            writer.live(live, period, duration)

    def publish(self) -> None:
        """Hand ``run.json``'s document as it stands now to the writer (which then adds each event)."""
        if self.writer is not None:
            self.writer.journal(self.journal.document())

    def _stop(self) -> None:
        if self.writer is not None:
            self.stats = self.writer.close()

    def finish(self, summary: RunSummary | None, pictures: bool = True) -> list[pathlib.Path]:
        """After the writer is stopped: ``run.json`` completed, the pictures (unless not ``pictures``);
        the files written.  A folder that can no longer be written (:attr:`failure`) gets neither:
        the files as they are (``run.json`` its last whole version), nothing raised."""
        try:
            return self._finish(summary, pictures and self.failure is None)
        except OSError as exc:
            self._failure = self.failure or f"run folder {self.folder}: {exc.strerror or exc} writing {RUN_JSON}"
            return [path for path in (*(self.folder / name for name in self.files), self.folder / LOG_NAME,
                                      self.journal.path) if path.is_file()]

    def _finish(self, summary: RunSummary | None, pictures: bool) -> list[pathlib.Path]:
        written = [self.folder / name for name in self.files]
        counts = self.stats.get("records", {})
        if len(self.files) == 1:
            self.journal.extra["record"] = counts.get(self.files[0], {"rows_written": 0, "rows_lost": 0})
        elif self.files:
            self.journal.extra["records"] = counts
        if "bus_log" in self.stats:
            self.journal.extra["bus_log"] = self.stats["bus_log"]
            written.append(self.folder / LOG_NAME)
        if "writer" in self.stats:
            self.journal.extra["writer"] = self.stats["writer"]
        self.journal.finish(summary, written)  # ended, before the pictures (which read it)
        run = read_run_folder(self.folder) if self.files and pictures else None
        if run is not None and run.drawable:
            from haptic_bus.app.run_pictures import render_run

            written += render_run(run)
        return self.journal.finish(summary, written)
