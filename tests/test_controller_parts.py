"""The controller's arithmetic without a bus: exact position, record (the observer: test_port_energy.py)."""

from __future__ import annotations

import math

import numpy as np

from haptic_bus.control.controller import PositionIntegrator
from haptic_bus.control.record import COLUMNS, RunRecord


def test_ten_million_cycles_add_no_rounding_drift() -> None:
    """The integrated position equals the drive's integer position exactly after 1e7 cycles.

    The drive's 0x6064 (increments of 1e-7 m) and 0x606C (1e-6 m/s) are tied by
    ``position = T * sum(velocity)``; with T = 1e-3 s one velocity count per cycle is 1e-9 m,
    so the integer identity is ``position_counts * 100 == sum(velocity_counts)``.
    """
    rng = np.random.default_rng(7)
    counts = rng.integers(-50_000, 50_001, size=10_000_000)
    integrator = PositionIntegrator(period=1e-3, velocity_per_count=1e-6)
    add = integrator.add
    naive = 0.0
    for chunk in np.array_split(counts, 100):  # the loop's own per-cycle additions, 1e7 of them
        for c in chunk.tolist():
            x = add(c)
            naive += 1e-3 * 1e-6 * c
    exact_sum = int(counts.sum())
    assert integrator.counts == exact_sum
    assert x == 1e-9 * exact_sum  # one rounding, not ten million
    # the float accumulation a naive loop does drifts measurably from it
    assert abs(naive - x) > 100 * math.ulp(abs(x))


def test_record_is_bounded_and_keeps_the_latest_rows(tmp_path) -> None:
    record = RunRecord(capacity=5)
    for k in range(12):
        record.append(k * 1e-3, 0.1, 0.2, float(k), k, 0.0, 3, 0.5, k % 2 == 1, 1e-6, 0.25)
    data = record.array()
    assert data.shape == (5, len(COLUMNS)) and record.total == 12
    assert list(data[:, 3]) == [7.0, 8.0, 9.0, 10.0, 11.0]
    path = record.write_csv(tmp_path / "run.csv")
    lines = path.read_text().splitlines()
    assert lines[0] == ",".join(COLUMNS) and len(lines) == 6
    first = dict(zip(COLUMNS, lines[1].split(",")))
    assert (first["torque_permille"], first["scene_id"], first["late"], first["scale"]) == ("7", "3", "1", "0.5")
    assert float(first["time_s"]) == 7e-3  # repr: every float written to the last bit
