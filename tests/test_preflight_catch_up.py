"""Pre-flight's catch-up rule at its edges: the period it names for a stall of a minute, found without
replaying every grid point up to it, and one the same measurement holds."""

from __future__ import annotations

import numpy as np
import pytest

from haptic_bus.app import preflight
from haptic_bus.app.preflight import PERIOD_GRID, Timing, allowed_overruns, catch_up_overruns, held_period

T = 1e-3


def _stalled(stall: float, cycles: int = 500, exchange: float = 100e-6) -> Timing:
    """``cycles`` cycles due every T, 20 us late, 0.1 ms exchanges; cycle 250 starts ``stall`` s late."""
    late = np.full(cycles, 20e-6)
    starts = np.arange(cycles) * T + late
    starts[250:] += stall
    late[250] += stall
    return Timing(T, late, starts, np.full(cycles, exchange), int(np.sum(late > T)))


def test_a_stall_of_a_minute_names_the_shortest_period_replaying_few_of_the_grid(monkeypatch: pytest.MonkeyPatch) -> None:
    """A 60 s stall puts 240 000 grid points between the busy rule's period and the stall's: replaying them
    all at once took 0.8 s of CPU (500 cycles of 240 000-wide arrays) in the run's pre-flight.  Narrowed down
    32 at a time, 4 rounds of them.  The period named is the shortest on the grid at which at most 5 of the 500
    cycles start more than a period late: 10.00025 s (the stall, 60 s, less 0.1 ms an exchange, takes 6
    periods of 10 s to work off, the sixth cycle starting 10.0001 s late; 5 at 10.00025 s)."""
    timing = _stalled(60.0)
    allowed = allowed_overruns(500)
    replayed: list[int] = []

    def counted(timing: Timing, periods: np.ndarray) -> np.ndarray:
        replayed.append(periods.size)
        return catch_up_overruns(timing, periods)

    monkeypatch.setattr(preflight, "catch_up_overruns", counted)
    named = held_period(timing, 0.25e-3, 60.0 + 120e-6, allowed)
    assert sum(replayed) <= 32 * 5
    assert named == pytest.approx(10.00025, abs=1e-9)
    at, below = catch_up_overruns(timing, np.array([named, named - PERIOD_GRID]))
    assert at <= allowed < below
