"""The writer process' end with a live view on a terminal: the view's last panel reads the rings, so
it must be drawn before the records let their rings go.  Drawn after (as it was), every run on a
terminal ended with "ValueError: operation forbidden on released memoryview object" in the writer,
an ERROR line, ``run.json`` saying 0 rows written and no ``bus.asc`` among its files."""

from __future__ import annotations

import io
import multiprocessing
import os
import pathlib
import pty
import sys
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from haptic_bus.app.writer_process import Writer
from haptic_bus.control.record import COLUMNS, RunRecord

ROWS = 3


@contextmanager
def _writer_of_one_record(folder: pathlib.Path) -> Iterator[tuple[Writer, RunRecord]]:
    """A writer in this process with one shared record (``record.csv``) attached, and that record; the
    record's ring and the pipe let go at the end."""
    ours, theirs = multiprocessing.get_context("spawn").Pipe()
    record = RunRecord(16, shared=True)
    try:
        writer = Writer(folder, theirs)
        writer.handle(("record", "record.csv", record.spec, "x"))
        assert ours.recv() == ("attached", "record.csv")
        yield writer, record
    finally:
        record.unlink()
        record.close()
        ours.close()
        theirs.close()


def _row(k: int) -> list[float]:
    """Row ``k`` of a record: its time, every other column 0."""
    return [k * 1e-3] + [0.0] * (len(COLUMNS) - 1)


def test_a_writer_with_a_terminal_view_closes_with_every_row_counted(tmp_path: pathlib.Path,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    master, slave = pty.openpty()  # a real terminal: the view takes rich's Live panel
    terminal = io.TextIOWrapper(io.FileIO(slave, "w", closefd=False), write_through=True)
    monkeypatch.setattr(sys, "stderr", terminal)
    try:
        with _writer_of_one_record(tmp_path) as (writer, record):
            for k in range(ROWS):
                record.append(*_row(k))
            writer.handle(("live", "run", 1e-3, 1.0))
            writer.handle(("stop",))
            stats = writer.close()
    finally:
        terminal.close()
        os.close(slave)
        os.close(master)
    assert stats == {"records": {"record.csv": {"rows_written": ROWS, "rows_lost": 0}}}
    assert len((tmp_path / "record.csv").read_text().splitlines()) == 1 + ROWS  # the header and each row


def test_run_writer_process_outlives_a_sigterm_to_the_process_group(tmp_path) -> None:
    """timeout(1) and a service manager's stop send SIGTERM to every process of the run's group: the run
    stops at a cycle boundary (exit 0, 'stopped'), and its writer must live to write the last rows; it died at
    once (run.json's record 'rows_written': 0, record.csv short by its last drain and cut mid-row, two ERROR lines)."""
    import os
    import signal

    from haptic_bus.app.run_writer import RunWriter

    writer = RunWriter(tmp_path, bus_log=False)
    pid = writer.process.pid
    assert pid is not None
    os.kill(pid, signal.SIGTERM)  # pending at once: a default action would end it before it reads 'stop'
    stats = writer.close()
    assert stats.get("records") == {} and "failure" not in stats
    assert writer.process.exitcode == 0


class _ClosedPipe(io.StringIO):
    """stdout whose reader is gone (``haptic-bus run ... | head -3``): every write fails."""

    def write(self, text: str) -> int:
        raise BrokenPipeError(32, "Broken pipe")


def test_a_view_whose_reader_is_gone_ends_and_the_records_are_written_in_full(tmp_path: pathlib.Path,
                                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """``haptic-bus run ... | head`` (break18): the view's print raised BrokenPipeError in the writer, which
    ended its loop ("run writer: [Errno 32] Broken pipe"), and the record held 1547 of the run's 5000 cycles
    in a run that said "completed".  Now the view ends; every row is written."""
    monkeypatch.setattr(sys, "stderr", io.StringIO())  # no terminal: the view prints plain lines on stdout
    monkeypatch.setattr(sys, "stdout", _ClosedPipe())
    with _writer_of_one_record(tmp_path) as (writer, record):
        writer.handle(("live", "run", 1e-3, 1.0))
        for k in range(ROWS):
            record.append(*_row(k))
            writer.show(writer.view_due)  # the redraw due now: the first one meets the closed pipe
            writer.flush()
        assert writer.view is None and writer.failure is None
        writer.handle(("stop",))
        stats = writer.close()
    assert stats == {"records": {"record.csv": {"rows_written": ROWS, "rows_lost": 0}}}
    assert len((tmp_path / "record.csv").read_text().splitlines()) == 1 + ROWS
