"""A run's record: one row a cycle in a preallocated ring, and the run's events.

``record.csv`` has one row a cycle (:data:`COLUMNS`, SI units and the drive's raw units); the
events (uploads accepted and refused, alarms, derates, faults, the end) go to ``run.json``
through :class:`EventLog`.  The control thread's part is O(1) a cycle: :meth:`RunRecord.append`
packs the row into the ring with one precompiled ``struct.pack_into`` (no allocation), and a
writer process (:mod:`haptic_bus.app.writer_process`) drains the ring, in shared memory, into
the file with :func:`format_rows` (struct records to CSV lines: no numpy, which that process
need not import).  :func:`read_record` reads a file back, a torn last line (a process killed
mid-write) included.  numpy is imported by the functions that make arrays, not by this module.
"""

from __future__ import annotations

import pathlib
import struct
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from haptic_bus.control.ring import Ring, segment
from haptic_bus.errors import ParameterError

if TYPE_CHECKING:
    import numpy as np

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
ROW = struct.Struct(f"={len(COLUMNS)}d")
"""One row of :data:`COLUMNS` as a ring's record."""


class RunRecord(Ring):
    """A ring of per-cycle rows (:data:`COLUMNS`, float64) with memory fixed at start (``capacity``
    rows), so a fault after an hour still leaves the last ``capacity - 1`` cycles in memory: in
    private memory, or with ``shared`` in shared memory, where a writer process reads it
    (:mod:`~haptic_bus.control.ring`).

    :meth:`append` stores one cycle, in :data:`COLUMNS` order (s, s, s, s, raw, counts, samples,
    m, m/s, N, per mille, J, id, factor, flag, s, N): it is :meth:`Ring.put`, one
    ``struct.pack_into`` and one counter store.  Readers take rows with :meth:`rows_from`, which
    says which rows it could still return (a reader more than ``capacity - 1`` rows behind has
    lost the oldest).
    """

    def __init__(self, capacity: int = 200_000, shared: bool = False) -> None:
        if isinstance(capacity, bool) or not isinstance(capacity, int) or capacity < 1:
            raise ValueError(f"capacity = {capacity!r} is invalid; allowed: an integer >= 1")
        size = capacity + 1  # one slot more than kept: the slot the writer fills next (ring module)
        super().__init__(ROW, size, segment(ROW, size) if shared else None)

    append = Ring.put

    def rows_from(self, first: int) -> tuple[int, np.ndarray]:
        """Rows ``first`` .. ``total - 1`` (a copy, oldest first) as ``(index of the first row
        returned, rows)``; the index exceeds ``first`` when older rows were already overwritten."""
        start, chunk = self.read_from(first)
        return start, rows_of(chunk)

    def array(self) -> np.ndarray:
        """The stored rows, oldest first (a copy)."""
        return self.rows_from(0)[1]

    def latest(self) -> dict[str, float] | None:
        """The newest row by column name (a copy), or None before the first cycle."""
        values = self.last()
        return None if values is None else dict(zip(COLUMNS, values))

    def column(self, name: str) -> np.ndarray:
        """One column by its :data:`COLUMNS` name, oldest first."""
        return self.array()[:, COLUMNS.index(name)]

    def write_csv(self, path: str | pathlib.Path) -> pathlib.Path:
        """Write the stored rows with a header line (what the streamed ``record.csv`` holds); returns the path."""
        path = pathlib.Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(HEADER + format_rows(ROW.iter_unpack(self.read_from(0)[1])))
        return path


def rows_of(chunk: bytes) -> np.ndarray:
    """The rows (:data:`COLUMNS`) of a ring's raw records ``chunk``, one row each (a copy)."""
    import numpy as np

    return np.frombuffer(chunk, dtype=np.float64).reshape(-1, len(COLUMNS)).copy()


def format_rows(rows: Iterable[Sequence[float]]) -> str:
    """CSV lines of ``rows`` (:data:`COLUMNS` order, floats: a ring's records as
    ``ROW.iter_unpack`` gives them): integers where whole, floats with ``repr`` (every bit kept),
    each line ending in a newline."""
    return "".join(_ROW_FORMAT % tuple(row) for row in rows)


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
    import numpy as np

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
    Appended from the control thread and the upload server's thread (list appends are atomic).
    ``listener`` (None: none) is called with each event kept, in the thread that added it (a run
    hands it to its writer process, which keeps ``run.json`` current)."""

    def __init__(self, capacity: int = 10_000) -> None:
        self.capacity = capacity
        self.events: list[Event] = []
        self.dropped = 0
        self.listener: Callable[[Event], None] | None = None

    def add(self, time_s: float, kind: str, message: str, **data: Any) -> Event:
        """Record an event; returns it."""
        event = Event(time_s, kind, message, data)
        if len(self.events) < self.capacity:
            self.events.append(event)
            if self.listener is not None:
                self.listener(event)
        else:
            self.dropped += 1
        return event

    def last(self) -> Event | None:
        """The newest event, or None."""
        return self.events[-1] if self.events else None

    def to_list(self) -> list[dict[str, Any]]:
        """JSON-ready, in order."""
        return [event.to_dict() for event in self.events]
