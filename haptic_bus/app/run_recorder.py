"""What a run writes while it goes on, in one place: the streamed ``record.csv``, the bus log, and
``run.json`` kept current (:class:`~haptic_bus.app.run_folder.RunJournal`); at the end, the journal
completed and the pictures drawn (:func:`~haptic_bus.app.run_pictures.render_run`, what ``haptic-bus
plot`` does).  ``haptic-bus run`` and ``haptic-bus demo`` both record through it.
"""

from __future__ import annotations

import pathlib
from contextlib import ExitStack
from typing import Any

from haptic_bus.app.bus_log import LOG_NAME, BusLog
from haptic_bus.app.record_stream import RecordStream
from haptic_bus.app.run_folder import RECORD_CSV, RunJournal, read_run_folder
from haptic_bus.app.run_pictures import render_run
from haptic_bus.control.controller import RunSummary, WallController


class RunRecorder:
    """The files of one run in ``folder``, with ``journal`` its ``run.json``."""

    def __init__(self, folder: pathlib.Path, journal: RunJournal) -> None:
        self.folder = folder
        self.journal = journal
        self.record: RecordStream | None = None
        self.bus_log: BusLog | None = None

    def log_bus(self, stack: ExitStack, bus: dict[str, Any]) -> None:
        """Log every frame of the CAN bus ``bus`` (python-can configuration) into ``bus.asc``
        until ``stack`` closes (no log, and a warning, if the bus cannot be opened twice)."""
        self.bus_log = BusLog.open(self.folder / LOG_NAME, bus)
        if self.bus_log is not None:
            stack.callback(self.bus_log.close)

    def stream(self, stack: ExitStack, controller: WallController) -> None:
        """Stream ``controller``'s record into ``record.csv`` (and keep ``run.json`` current)
        until ``stack`` closes."""
        self.journal.controller = controller
        self.record = RecordStream(self.folder / RECORD_CSV, controller.record, self.journal.refresh).start()
        stack.callback(self.record.close)

    def finish(self, summary: RunSummary | None, pictures: bool = True) -> list[pathlib.Path]:
        """After the streams are closed: ``run.json`` completed, the pictures (unless not ``pictures``);
        the files written."""
        written = []
        if self.record is not None:
            self.journal.extra["record"] = {"rows_written": self.record.written, "rows_lost": self.record.lost}
            written.append(self.record.path)
        if self.bus_log is not None:
            self.journal.extra["bus_log"] = {"frames": self.bus_log.frames}
            written.append(self.bus_log.path)
        self.journal.finish(summary, written)  # ended, before the pictures (which read it)
        if self.record is not None and pictures:
            written += render_run(read_run_folder(self.folder))
        return self.journal.finish(summary, written)
