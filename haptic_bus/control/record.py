"""A run's record: one row a cycle in a preallocated ring, and the run's events.

``record.csv`` has one row a cycle (:data:`COLUMNS`, SI units and the drive's raw units); the
events (uploads accepted and refused, alarms, derates, faults, the end) go to ``run.json``
through :class:`EventLog`.  The control thread's part is O(1) a cycle: :meth:`RunRecord.append`
packs the row into the ring with one precompiled ``struct.pack_into`` (no allocation), and a
writer in another thread (:mod:`haptic_bus.app.record_stream`) drains the ring into the file
with :meth:`RunRecord.rows_from` and :func:`format_rows`.  :func:`read_record` reads a file
back, a torn last line (a process killed mid-write) included.
"""

from __future__ import annotations

import pathlib
import struct
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from haptic_bus.errors import ParameterError

COLUMNS = ("time_s", "wall_clock_s", "monotonic_s", "lateness_s", "statusword", "velocity_counts", "input_age",
           "position_m", "velocity_m_per_s", "force_n", "torque_permille", "energy_j", "scene_id", "scale", "late",
           "compute_s", "layer_n")
"""``time_s``: the run's clock, ``k T``; ``wall_clock_s``: Unix time (``time.time()``) and
``monotonic_s``: ``time.perf_counter()`` (CLOCK_MONOTONIC on Linux), both when the cycle's inputs
were in hand; ``lateness_s``: how late the cycle started after its deadline (the clock's; 0 in
virtual time); ``statusword``: 0x6041 as received; ``velocity_counts``: 0x606C in the drive's
units; ``input_age``: how many samples older than the cycle its input was (0: fresh);
``position_m`` .. ``force_n``: the handle and the wall force (SI); ``torque_permille``: the target
torque sent (0x6071, after the passivity layer); ``energy_j``: the port observer's energy ``E``
up to the cycle's sample; ``scene_id``: the scene in
effect (see the run's ``scenes``); ``scale``: the factor on its force (the start ramp, 1
otherwise); ``late``: 1 when the supervisor found the cycle late; ``compute_s``: from the drive's
inputs in hand to the outputs handed to the drive (position, scene, saturation, conversion,
encode and send); ``layer_n``: the force the passivity layer took off the target (N, 0 when it
did not act)."""

INTEGRAL_COLUMNS = frozenset(("statusword", "velocity_counts", "input_age", "torque_permille", "scene_id", "late"))
"""Columns written as integers (they hold whole numbers)."""

HEADER = ",".join(COLUMNS) + "\n"
_ROW_FORMAT = ",".join("%d" if name in INTEGRAL_COLUMNS else "%r" for name in COLUMNS) + "\n"
_ROW = struct.Struct(f"={len(COLUMNS)}d")


class RunRecord:
    """A ring of per-cycle rows (:data:`COLUMNS`, float64); memory fixed at start (``capacity``
    rows), so a fault after an hour still leaves the last ``capacity`` cycles in memory.

    One writer (the control thread) appends; readers in other threads take rows with
    :meth:`rows_from`, which says which rows it could still return (a reader more than
    ``capacity`` rows behind has lost the oldest).
    """

    def __init__(self, capacity: int = 200_000) -> None:
        if isinstance(capacity, bool) or not isinstance(capacity, int) or capacity < 1:
            raise ValueError(f"capacity = {capacity!r} is invalid; allowed: an integer >= 1")
        self._rows = np.zeros((capacity, len(COLUMNS)))
        self._bytes = self._rows.data.cast("B")
        self._pack = _ROW.pack_into
        self._width = _ROW.size
        self._next = 0
        self.total = 0

    @property
    def capacity(self) -> int:
        """Rows kept in memory."""
        return self._rows.shape[0]

    def append(self, t: float, wall_clock: float, monotonic: float, lateness: float, statusword: int,
               velocity_counts: int, input_age: int, x: float, v: float, force: float, torque: int, energy: float,
               scene_id: int, scale: float, late: bool, compute: float, removed: float) -> None:
        """Store one cycle, in :data:`COLUMNS` order (s, s, s, s, raw, counts, samples, m, m/s, N,
        per mille, J, id, factor, flag, s, N): one ``struct.pack_into`` into the ring."""
        slot = self._next
        self._pack(self._bytes, slot * self._width, t, wall_clock, monotonic, lateness, statusword, velocity_counts,
                   input_age, x, v, force, torque, energy, scene_id, scale, late, compute, removed)
        self._next = slot + 1 if slot + 1 < self._rows.shape[0] else 0
        self.total += 1  # last: a reader in another thread sees the row complete

    def rows_from(self, first: int) -> tuple[int, np.ndarray]:
        """Rows ``first`` .. ``total - 1`` (a copy, oldest first) as ``(index of the first row
        returned, rows)``; the index exceeds ``first`` when older rows were already overwritten."""
        total = self.total
        capacity = self._rows.shape[0]
        start = max(first, total - capacity)
        if start >= total:
            return total, self._rows[:0].copy()
        lo, hi = start % capacity, total % capacity
        rows = self._rows[lo:hi].copy() if lo < hi else np.concatenate((self._rows[lo:], self._rows[:hi]))
        overwritten = self.total - capacity - start  # rows the writer replaced while they were copied
        if overwritten > 0:
            return start + overwritten, rows[overwritten:]
        return start, rows

    def array(self) -> np.ndarray:
        """The stored rows, oldest first (a copy)."""
        return self.rows_from(0)[1]

    def latest(self) -> dict[str, float] | None:
        """The newest row by column name (a copy), or None before the first cycle."""
        if not self.total:
            return None
        return dict(zip(COLUMNS, self._rows[self._next - 1].tolist()))

    def column(self, name: str) -> np.ndarray:
        """One column by its :data:`COLUMNS` name, oldest first."""
        return self.array()[:, COLUMNS.index(name)]

    def write_csv(self, path: str | pathlib.Path) -> pathlib.Path:
        """Write the stored rows with a header line (what the streamed ``record.csv`` holds); returns the path."""
        path = pathlib.Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(HEADER + format_rows(self.array()))
        return path


def format_rows(rows: np.ndarray) -> str:
    """CSV lines of ``rows`` (:data:`COLUMNS` order): integers where whole, floats with ``repr``
    (every bit kept), each line ending in a newline."""
    return "".join(_ROW_FORMAT % tuple(row) for row in rows.tolist())


@dataclass(frozen=True)
class RecordTable:
    """``record.csv`` read back: each column (floats, :data:`COLUMNS` names), and whether its
    last line was torn (a process killed while writing it: that line is left out)."""

    columns: dict[str, np.ndarray]
    torn_line: bool

    @property
    def cycles(self) -> int:
        """Rows read."""
        return int(self.columns["time_s"].size) if "time_s" in self.columns else 0

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]


def read_record(path: str | pathlib.Path) -> RecordTable:
    """Read ``record.csv``; a last line without its newline is torn and left out.

    Columns are taken by the header's names (a record from another version reads as it was
    written).  ParameterError (exit 2) naming the file and the line for anything else that does not
    parse: a header or a line (not the last) that is not a record's.
    """
    text = pathlib.Path(path).read_text()
    header, _, body = text.partition("\n")
    names = header.strip().split(",")
    if not header or not all(names):
        raise ParameterError("line 1", header, "a header of column names", context=str(path))
    torn = bool(body) and not body.endswith("\n")
    if torn:
        body = body[: body.rfind("\n") + 1]
    fields = body.replace("\n", ",").split(",")[:-1] if body else []
    lines = body.count("\n")
    if len(fields) != lines * len(names):
        number, line = next((n, line) for n, line in enumerate(body.splitlines(), start=2)
                            if len(line.split(",")) != len(names))
        raise ParameterError(f"line {number}", f"{len(line.split(','))} fields", f"{len(names)} fields, as the header",
                             context=str(path))
    try:
        values = np.array(fields, dtype=float)  # parsed in C
    except ValueError as exc:
        raise ParameterError("a field", str(exc), "numbers in every field", context=str(path)) from None
    table = values.reshape(lines, len(names))
    return RecordTable({name: table[:, i] for i, name in enumerate(names)}, torn)


@dataclass(frozen=True)
class Event:
    """One thing that happened in a run: at ``time_s`` (the run's clock), of a ``kind`` ("upload",
    "refused", "alarm", "derate", "fault", "stop", ...), a one-line ``message`` and ``data``."""

    time_s: float
    kind: str
    message: str
    data: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {"time_s": self.time_s, "kind": self.kind, "message": self.message, **({"data": self.data} if self.data else {})}


class EventLog:
    """The run's events in order; at most ``capacity`` kept (the count of dropped ones is kept too).
    Appended from the control thread and the upload server's thread (list appends are atomic)."""

    def __init__(self, capacity: int = 10_000) -> None:
        self.capacity = capacity
        self.events: list[Event] = []
        self.dropped = 0

    def add(self, time_s: float, kind: str, message: str, **data: Any) -> Event:
        """Record an event; returns it."""
        event = Event(time_s, kind, message, data)
        if len(self.events) < self.capacity:
            self.events.append(event)
        else:
            self.dropped += 1
        return event

    def last(self) -> Event | None:
        """The newest event, or None."""
        return self.events[-1] if self.events else None

    def to_list(self) -> list[dict[str, Any]]:
        """JSON-ready, in order."""
        return [event.to_dict() for event in self.events]
