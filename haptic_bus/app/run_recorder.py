"""What a one-axis run writes, in one place: its writer process (:mod:`~haptic_bus.app.run_writer`:
the streamed ``record.csv``, the bus log, ``run.json`` kept current, the live view) and, at the
end, the journal completed and the pictures drawn (:func:`~haptic_bus.app.run_pictures.render_run`,
what ``haptic-bus plot`` does).  ``haptic-bus run`` and ``haptic-bus demo`` both record through it.
"""

from __future__ import annotations

import pathlib
from contextlib import ExitStack
from typing import Any

from haptic_bus.app.bus_log import LOG_NAME
from haptic_bus.app.run_folder import RECORD_CSV, RunJournal, read_run_folder
from haptic_bus.app.run_writer import RunWriter
from haptic_bus.control.controller import RunSummary, WallController


class RunRecorder:
    """The files of one run in ``folder``, with ``journal`` its ``run.json``."""

    def __init__(self, folder: pathlib.Path, journal: RunJournal) -> None:
        self.folder = folder
        self.journal = journal
        self.writer: RunWriter | None = None
        self.stats: dict[str, Any] = {}
        self._record = False

    def start(self, stack: ExitStack, bus_log: bool) -> RunWriter:
        """Start the writer process (with ``bus_log`` its frame ring and ``bus.asc``), stopped when
        ``stack`` closes; before the drive is reached, so that commissioning's frames are logged."""
        self.writer = writer = RunWriter(self.folder, bus_log)
        stack.callback(self._stop)
        return writer

    def stream(self, controller: WallController, live: str | None = None, duration: float | None = None) -> None:
        """Stream ``controller``'s record (made with ``shared_record``) into ``record.csv``, keep
        ``run.json`` current with its events, and show the live view titled ``live`` (None: none)."""
        writer = self.writer
        if writer is None:
            raise RuntimeError("RunRecorder.stream before start")  # a bug in the caller, not a run's state
        self.journal.controller = controller
        writer.stream([(RECORD_CSV, "", controller.record)])
        self._record = True
        writer.follow(controller.events, lambda: [entry.to_dict() for entry in list(controller.scenes.history)])
        self.publish()
        if live is not None:
            writer.live(live, controller.period, duration)

    def publish(self) -> None:
        """Hand ``run.json``'s document as it stands now to the writer (which then adds each event)."""
        if self.writer is not None:
            self.writer.journal(self.journal.document())

    def _stop(self) -> None:
        if self.writer is not None:
            self.stats = self.writer.close()

    def finish(self, summary: RunSummary | None, pictures: bool = True) -> list[pathlib.Path]:
        """After the writer is stopped: ``run.json`` completed, the pictures (unless not ``pictures``);
        the files written."""
        written = []
        if self._record:
            record = self.stats.get("records", {}).get(RECORD_CSV, {"rows_written": 0, "rows_lost": 0})
            self.journal.extra["record"] = record
            written.append(self.folder / RECORD_CSV)
        if "bus_log" in self.stats:
            self.journal.extra["bus_log"] = self.stats["bus_log"]
            written.append(self.folder / LOG_NAME)
        self.journal.finish(summary, written)  # ended, before the pictures (which read it)
        if self._record and pictures:
            from haptic_bus.app.run_pictures import render_run

            written += render_run(read_run_folder(self.folder))
        return self.journal.finish(summary, written)
