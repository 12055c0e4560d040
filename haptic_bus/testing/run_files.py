"""A run folder read back: ``record.csv`` (a multi-axis run: ``record-<axis>.csv`` per axis) as
numpy columns, ``run.json`` as a dict.

Every run (``haptic-bus run``, ``haptic-bus demo``, :func:`haptic_bus.run`) writes both into its
folder (:mod:`haptic_bus.app.run_folder`); the records only once it has cycled (a run refused
before its first cycle has ``run.json`` alone).
"""

from __future__ import annotations

import csv
import json
import os
import pathlib
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

RECORD = "record.csv"
AXIS_RECORDS = "record-*.csv"  # a multi-axis run's, one per axis (haptic_bus.app.run_folder.record_name)
DOCUMENT = "run.json"


def read_record_csv(path: str | os.PathLike[str]) -> tuple[list[str], dict[str, np.ndarray]]:
    """A ``record.csv``: its header, and each column as float64 (exact: the file is written with ``repr``)."""
    import numpy as np

    with pathlib.Path(path).open(newline="") as file:
        rows = list(csv.reader(file))
    header = rows[0]
    body = np.array(rows[1:], dtype=float).reshape(len(rows) - 1, len(header))
    return header, {name: body[:, i] for i, name in enumerate(header)}


@dataclass(frozen=True)
class RecordedRun:
    """What a run folder holds.  ``record``: one float64 array per ``record.csv`` column
    (``time_s`` s, ``position_m`` m, ``velocity_m_per_s`` m/s, ``force_n`` N, ``torque_permille``,
    ``energy_j`` J, ... see :data:`haptic_bus.control.record.COLUMNS`), one entry per cycle, empty
    when the run never cycled or had several axes; ``records``: a multi-axis run's, axis name ->
    its columns the same way; ``document``: ``run.json``."""

    folder: pathlib.Path
    record: dict[str, np.ndarray]
    document: dict[str, Any]
    records: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)

    @property
    def exit_reason(self) -> str:
        """How the run ended: "completed", "stopped", "refused", "drive error", "write error", "assumption broken"
        or "interrupted"."""
        return str(self.document["exit_reason"])

    @property
    def error(self) -> str | None:
        """The run's one-line error, None when it completed or was stopped."""
        error = self.document.get("error")
        return None if error is None else str(error)

    @property
    def summary(self) -> dict[str, Any]:
        """The run's summary (cycles, late cycles, alarms, ...; empty if it never cycled)."""
        return dict(self.document.get("summary") or {})

    def events(self, kind: str | None = None) -> list[dict[str, Any]]:
        """The run's events in order (``time_s`` s, ``kind``, ``message``, ``data``), or those of ``kind``."""
        events = list(self.document.get("events", []))
        return events if kind is None else [event for event in events if event["kind"] == kind]


def read_run_folder(folder: str | os.PathLike[str]) -> RecordedRun:
    """The run folder ``folder`` read back (``run.json`` must exist: every run writes it)."""
    folder = pathlib.Path(folder)
    if not (folder / DOCUMENT).is_file():  # FileNotFoundError's line named run.json, not what the caller gave
        from haptic_bus.errors import ParameterError

        raise ParameterError("folder", str(folder), f"a run folder, one holding {DOCUMENT} (haptic-bus run --out, "
                             "haptic-bus demo, hb.run's folder)", "recorded_run")
    document = json.loads((folder / DOCUMENT).read_text())
    record = read_record_csv(folder / RECORD)[1] if (folder / RECORD).is_file() else {}
    records = {path.stem.removeprefix("record-"): read_record_csv(path)[1] for path in sorted(folder.glob(AXIS_RECORDS))}
    return RecordedRun(folder, record, document, records)
