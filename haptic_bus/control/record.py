"""A run's bounded record: the last ``capacity`` cycles, written to CSV on request."""

from __future__ import annotations

import csv
import pathlib

import numpy as np

COLUMNS = ("time_s", "velocity_m_per_s", "position_m", "force_n", "torque_permille", "energy_j", "compute_s")


class RunRecord:
    """A ring buffer of per-cycle rows (columns: :data:`COLUMNS`, SI units).

    ``compute_s`` runs from the drive's inputs in hand to the outputs handed to the drive
    (position, scene, saturation, conversion, and the drive's encode and send).

    Memory is fixed at start (``capacity`` rows of 7 floats); once full, the oldest rows give
    way, so a fault after an hour still leaves the last ``capacity`` cycles to look at.
    """

    def __init__(self, capacity: int = 200_000) -> None:
        if capacity < 1:
            raise ValueError(f"capacity = {capacity!r} is invalid; allowed: >= 1")
        self._rows = np.zeros((capacity, len(COLUMNS)))
        self._next = 0
        self.total = 0

    def append(self, t: float, v: float, x: float, force: float, torque: int, energy: float, compute: float) -> None:
        """Store one cycle's values (s, m/s, m, N, per mille, J, s)."""
        row = self._rows[self._next]
        row[0], row[1], row[2], row[3], row[4], row[5], row[6] = t, v, x, force, torque, energy, compute
        self._next = (self._next + 1) % self._rows.shape[0]
        self.total += 1

    def array(self) -> np.ndarray:
        """The stored rows, oldest first (a copy)."""
        capacity = self._rows.shape[0]
        if self.total < capacity:
            return self._rows[: self.total].copy()
        return np.roll(self._rows, -self._next, axis=0)

    def column(self, name: str) -> np.ndarray:
        """One column by its :data:`COLUMNS` name, oldest first."""
        return self.array()[:, COLUMNS.index(name)]

    def write_csv(self, path: str | pathlib.Path) -> pathlib.Path:
        """Write the stored rows with a header line; returns the path."""
        path = pathlib.Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(COLUMNS)
            writer.writerows(self.array().tolist())
        return path
