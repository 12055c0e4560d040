"""``haptic-bus plot`` of an ended run whose record holds fewer cycles than its ``run.json`` says
were written (the file cut short or removed after the run) says so, before the pictures that
show only what is left (breaker11b: a run folder without its record.csv drew the K-B plane
alone, exit 0, with no word of the 1000 cycles gone)."""

from __future__ import annotations

import json
import pathlib

import pytest

from haptic_bus.app.run_folder import RECORD_CSV, RUN_JSON, read_run_folder
from haptic_bus.control.record import COLUMNS


def _folder(tmp_path: pathlib.Path, rows_written: int, rows_held: int | None) -> pathlib.Path:
    """An ended run's folder: run.json saying ``rows_written`` rows, record.csv with ``rows_held``
    rows of zeros (None: no record.csv)."""
    document = {"status": "completed", "ended": True, "record": {"rows_written": rows_written, "rows_lost": 0}}
    (tmp_path / RUN_JSON).write_text(json.dumps(document))
    if rows_held is not None:
        row = ",".join("0" for _ in COLUMNS)
        (tmp_path / RECORD_CSV).write_text(",".join(COLUMNS) + "\n" + f"{row}\n" * rows_held)
    return tmp_path


@pytest.mark.parametrize(("held", "said"), [(None, 0), (0, 0), (3, 3)])
def test_a_record_short_of_run_json_is_named(tmp_path: pathlib.Path, held: int | None, said: int) -> None:
    run = read_run_folder(_folder(tmp_path, 5, held))
    assert run.notes() == [f"{tmp_path / RECORD_CSV}: holds {said} of the 5 cycles run.json says the run wrote "
                           "(cut short or removed since): the pictures show only what it holds"]


def test_a_whole_record_has_no_note(tmp_path: pathlib.Path) -> None:
    assert read_run_folder(_folder(tmp_path, 5, 5)).notes() == []
