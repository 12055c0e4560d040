"""A run's bounded record: the last ``capacity`` cycles, and the run's events, written on request.

``record.csv`` has one row a cycle (:data:`COLUMNS`, SI units); the events (uploads accepted
and refused, alarms, faults, the end) go to ``run.json`` through :class:`EventLog`.
"""

from __future__ import annotations

import csv
import pathlib
from dataclasses import dataclass, field
from typing import Any

import numpy as np

COLUMNS = ("time_s", "position_m", "velocity_m_per_s", "force_n", "torque_permille", "energy_j",
           "scene_id", "scale", "late", "compute_s", "layer_n")
"""``force_n``: the wall force the scene asked (saturated at the force limit); ``torque_permille``:
the target sent (after the passivity layer); ``energy_j``: the port observer's energy ``E`` up to
the cycle's sample; ``layer_n``: the force the passivity layer took off the target (N, 0 when it
did not act); ``scene_id``: the scene in effect (see the run's
``scenes``); ``scale``: the factor on its force (the start ramp, 1 otherwise); ``late``: 1 when
the supervisor found the cycle late; ``compute_s``: from the drive's inputs in hand to the
outputs handed to the drive (position, scene, saturation, conversion, encode and send)."""


class RunRecord:
    """A ring buffer of per-cycle rows (:data:`COLUMNS`); memory fixed at start (``capacity`` rows),
    so a fault after an hour still leaves the last ``capacity`` cycles to look at."""

    def __init__(self, capacity: int = 200_000) -> None:
        if isinstance(capacity, bool) or not isinstance(capacity, int) or capacity < 1:
            raise ValueError(f"capacity = {capacity!r} is invalid; allowed: an integer >= 1")
        self._rows = np.zeros((capacity, len(COLUMNS)))
        self._next = 0
        self.total = 0

    def append(self, t: float, x: float, v: float, force: float, torque: int, energy: float,
               scene_id: int, scale: float, late: bool, compute: float, removed: float) -> None:
        """Store one cycle (s, m, m/s, N, per mille, J, id, factor, flag, s, N)."""
        row = self._rows[self._next]
        row[0], row[1], row[2], row[3], row[4] = t, x, v, force, torque
        row[5], row[6], row[7], row[8], row[9], row[10] = energy, scene_id, scale, late, compute, removed
        self._next = (self._next + 1) % self._rows.shape[0]
        self.total += 1

    def array(self) -> np.ndarray:
        """The stored rows, oldest first (a copy)."""
        capacity = self._rows.shape[0]
        if self.total < capacity:
            return self._rows[: self.total].copy()
        return np.roll(self._rows, -self._next, axis=0)

    def latest(self) -> dict[str, float] | None:
        """The newest row by column name (a copy), or None before the first cycle."""
        if not self.total:
            return None
        return dict(zip(COLUMNS, self._rows[self._next - 1].tolist()))

    def column(self, name: str) -> np.ndarray:
        """One column by its :data:`COLUMNS` name, oldest first."""
        return self.array()[:, COLUMNS.index(name)]

    def write_csv(self, path: str | pathlib.Path) -> pathlib.Path:
        """Write the stored rows with a header line; returns the path."""
        path = pathlib.Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        integral = {COLUMNS.index(name) for name in ("torque_permille", "scene_id", "late")}
        with path.open("w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(COLUMNS)
            for row in self.array().tolist():
                writer.writerow([int(v) if i in integral else repr(v) for i, v in enumerate(row)])
        return path


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
