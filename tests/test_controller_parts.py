"""The controller's arithmetic without a bus: exact position, record (the observer: test_port_energy.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from haptic_bus.control.joints import PositionIntegrator
from haptic_bus.control.record import COLUMNS, RunRecord, read_record
from haptic_bus.errors import ParameterError


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
        # a naive loop's ``naive += 1e-3 * 1e-6 * c`` a cycle, bit for bit: np.add.accumulate adds in order,
        # one rounding a term (not pairwise as np.sum), the sum so far carried into the chunk's first term
        terms = (1e-3 * 1e-6) * chunk.astype(float)
        terms[0] += naive
        naive = float(np.add.accumulate(terms)[-1])
    exact_sum = int(counts.sum())
    assert integrator.counts == exact_sum
    assert x == 1e-9 * exact_sum  # one rounding, not ten million
    # the float accumulation a naive loop does drifts measurably from it
    assert abs(naive - x) > 100 * math.ulp(abs(x))  # 420 ulp (33 after 1e6 cycles: 1e7 are needed)


def test_record_is_bounded_and_keeps_the_latest_rows(tmp_path) -> None:
    record = RunRecord(capacity=5)
    for k in range(12):
        record.append(k * 1e-3, 1.7e9 + k * 1e-3, 50.0 + k * 1e-3, 2e-5, 0x1237, -k, k % 3, 0.1, 0.2, float(k), k, 0.0, 3,
                      0.5, k % 2 == 1, 1e-6, 0.25)
    data = record.array()
    assert data.shape == (5, len(COLUMNS)) and record.total == 12
    assert list(data[:, COLUMNS.index("force_n")]) == [7.0, 8.0, 9.0, 10.0, 11.0]
    first, rows = record.rows_from(3)  # rows 3..6 were overwritten: the reader is told where its rows start
    assert first == 7 and rows.shape == (5, len(COLUMNS)) and record.rows_from(12)[1].shape == (0, len(COLUMNS))
    path = record.write_csv(tmp_path / "run.csv")
    lines = path.read_text().splitlines()
    assert lines[0] == ",".join(COLUMNS) and len(lines) == 6
    first_row = dict(zip(COLUMNS, lines[1].split(",")))
    assert (first_row["torque_permille"], first_row["scene_id"], first_row["late"], first_row["scale"]) == ("7", "3", "1", "0.5")
    assert (first_row["statusword"], first_row["velocity_counts"], first_row["input_age"]) == (str(0x1237), "-7", "1")
    assert float(first_row["time_s"]) == 7e-3 and float(first_row["wall_clock_s"]) == 1.7e9 + 7e-3  # repr: every bit


def test_a_torn_last_line_is_left_out_and_a_bad_line_named(tmp_path) -> None:
    record = RunRecord(capacity=10)
    for k in range(4):
        record.append(k * 1e-3, 1.7e9, 50.0, 0.0, 0x1237, k, 0, 0.1, 0.2, float(k), k, 0.0, 0, 1.0, False, 1e-6, 0.0)
    path = record.write_csv(tmp_path / "record.csv")
    whole = read_record(path)
    assert whole.cycles == 4 and not whole.torn_line and list(whole["velocity_counts"]) == [0, 1, 2, 3]
    text = path.read_text()
    path.write_text(text[:-7])  # killed while writing the last line
    torn = read_record(path)
    assert torn.cycles == 3 and torn.torn_line and list(torn["force_n"]) == [0.0, 1.0, 2.0]
    lines = text.splitlines(keepends=True)
    path.write_text("".join([*lines[:2], "1,2\n", *lines[2:]]))
    with pytest.raises(ParameterError, match=r"record.csv: line 3 = '2 fields' is invalid; allowed: 17 fields, as the header"):
        read_record(path)
