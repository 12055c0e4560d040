"""Pre-flight's catch-up rule at its edges: the period it names for a stall of a minute, found without
replaying every grid point up to it, and one the same measurement holds."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from drives.safety import SafetySettings
from haptic_bus.app import preflight
from haptic_bus.app.preflight import (
    PERIOD_GRID,
    PreflightReport,
    Timing,
    allowed_overruns,
    catch_up_overruns,
    held_period,
    judge_delay,
)

T = 1e-3


def _stalled(stall: float, cycles: int = 500, exchange: float = 100e-6, period: float = T) -> Timing:
    """``cycles`` cycles due every ``period``, 20 us late, 0.1 ms exchanges; cycle 250 starts ``stall`` s late."""
    late = np.full(cycles, 20e-6)
    starts = np.arange(cycles) * period + late
    starts[250:] += stall
    late[250] += stall
    return Timing(period, late, starts, np.full(cycles, exchange), int(np.sum(late > period)))


def test_a_stall_of_a_minute_names_the_shortest_period_replaying_few_of_the_grid(monkeypatch: pytest.MonkeyPatch) -> None:
    """A 60 s stall puts 240 000 grid points between the busy rule's period and the stall's: replaying them
    all at once took 0.8 s of CPU (500 cycles of 240 000-wide arrays) in the run's pre-flight.  A binary search
    on the grid replays one period a step, 18 steps.  The period named is the shortest on the grid at which at most 5 of the 500
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
    assert sum(replayed) <= 20  # ceil(log2(240 000)) steps of one period, and T itself once
    assert named == pytest.approx(10.00025, abs=1e-9)
    at, below = catch_up_overruns(timing, np.array([named, named - PERIOD_GRID]))
    assert at <= allowed < below


def _judged(timing: Timing, watchdog_at: Callable[[float], float], periods: int) -> PreflightReport:
    return judge_delay(timing, 1.0, lambda delay: True, "guard", watchdog_at(timing.period), periods,
                       watchdog_at=watchdog_at)


def _replayed(timing: Timing, period: float) -> Timing:
    """The same measurement judged as if its ``T`` had been ``period``."""
    return Timing(period, timing.lateness, timing.starts, timing.exchange, timing.overruns)


def _modbus_watchdog(period: float) -> float:
    return 60e-3  # a Modbus unit's watchdog, 60 ms at any T


@pytest.mark.parametrize(("watchdog_at", "periods", "stall", "named"), [
    # a 4 ms gap, x1.5 = 6 ms: at 1.5 ms a deadline of 4 periods is 6 ms, which the gap reaches (refused); at 1.75 ms
    # the 3 ms stall leaves a gap of 4.75 ms, x1.5 = 7.125 ms, over the 7 ms deadline there: 2 ms
    (SafetySettings(rpdo_deadline_periods=4, consumer_ms=1000).canopen_stall, 4, 3e-3, 2e-3),
    # a 4 ms gap: at 1.25 ms the drive's deadline is 5 x 1.25 = 6.25 -> 6 ms, whole ms, which 1.5 x 4.25 ms reaches;
    # at 1.5 ms it is 8 ms, over 1.5 x 4.5 ms
    (SafetySettings(rpdo_deadline_periods=5, consumer_ms=1000).canopen_stall, 5, 3e-3, 1.5e-3),
    # a 51 ms gap, x1.5 = 76.5 ms: a deadline of 30 periods grows past it, but the heartbeat consumer's slack
    # (90 - 20 = 70 ms) does not grow with T: no T holds it
    (SafetySettings().canopen_stall, 30, 50e-3, None),
    # a 39 ms gap, x1.5 = 58.5 ms, under a 60 ms watchdog at T = 1 ms; its 38 ms stall's catch-up needs T >= 7.75 ms,
    # where the gap is 45.75 ms, x1.5 = 68.6 ms: no T holds both
    (_modbus_watchdog, None, 38e-3, None),
])
def test_the_period_named_for_a_stall_is_one_whose_watchdog_the_same_gap_does_not_reach(
        watchdog_at: Callable[[float], float], periods: int | None, stall: float, named: float | None) -> None:
    """Judged again with ``T`` set to the period named, the same measurement holds (the rule refuses a gap
    that, x1.5, reaches the watchdog: the period named must put it strictly under, with the deadline the drive
    keeps, whole ms, and the heartbeat consumer's slack, which a longer ``T`` does not lengthen, and the stall
    lasting as long at a longer ``T``); where no ``T`` does, none is named and the refusal says to lengthen the
    watchdog."""
    timing = _stalled(stall)
    report = _judged(timing, watchdog_at, periods)
    assert not report.holdable
    if named is None:
        assert report.smallest_period is None
        assert report.reason.endswith(f"a gap of {(stall + T) * 1e3:.3g} ms between cycles measured, x1.5, would "
                                      "fault the drive at any T: lengthen the drive's watchdog ([safety])")
        return
    assert report.smallest_period == pytest.approx(named, abs=1e-12)
    again = _judged(_replayed(timing, named), watchdog_at, periods)
    assert again.holdable, again.reason
    measured_there = _judged(_stalled(stall, period=named), watchdog_at, periods)  # the same stall, at that T
    assert measured_there.holdable, measured_there.reason


def test_a_held_run_names_no_shorter_period_than_its_watchdog_holds_the_gap_measured_at() -> None:
    """At T = 2 ms, 0.12 ms busy cycles, the gap between cycles is 2 ms, x1.5 = 3 ms, under a deadline of 5
    periods, 10 ms: held.  The busy time alone would name 0.25 ms, where the deadline is 1 ms (whole ms, at
    least 1), and 0.5 ms names 2 ms (2.5 rounded): judged again at those, the same gap is refused.  0.75 ms:
    a deadline of 4 ms (3.75 rounded)."""
    safety = SafetySettings(rpdo_deadline_periods=5, consumer_ms=1000)
    timing = _stalled(0.0, period=2e-3)
    report = _judged(timing, safety.canopen_stall, 5)
    assert report.holdable and report.smallest_period == pytest.approx(0.75e-3, abs=1e-12)
    assert _judged(_replayed(timing, 0.75e-3), safety.canopen_stall, 5).holdable
    assert not _judged(_replayed(timing, 0.5e-3), safety.canopen_stall, 5).holdable
