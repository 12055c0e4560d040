"""Pre-flight's verdict and its numbers agree (breaker13): its line never states two counts that
contradict each other, and a profile's ``T`` off the 0.25 ms grid is refused only when more cycles
than allowed were busy longer than it.

A machine whose loop is busy longer than ``T`` in 6 of 500 cycles, each time finishing within
``T`` of the next deadline, has no cycle *started* more than ``T`` late (the clock's count, 0) yet
is refused by the rule (6 busy cycles, 5 allowed).  The line printed "0 overruns: refused: 6 of
500 cycles were busy ... longer than T": two numbers for one word.  It now names the clock's count
for what it is.
"""

from __future__ import annotations

import math

import numpy as np

from haptic_bus.app.preflight import PREFLIGHT_CYCLES, Timing, allowed_overruns, judge_delay

T = 1e-3  # s
QUICK, SLOW, LATE = 0.2e-3, 1.2e-3, 0.2e-3  # s: an ordinary exchange, an overlong one, the next cycle's late start
SLOW_CYCLES = (50, 130, 210, 290, 370, 450)  # 6 of 500: one more than allowed_overruns(500) = 5


def _timing() -> Timing:
    """500 cycles on T: six exchanges of 1.2 ms, each making the next cycle start 0.2 ms late."""
    lateness = np.zeros(PREFLIGHT_CYCLES)
    exchange = np.full(PREFLIGHT_CYCLES, QUICK)
    for k in SLOW_CYCLES:
        exchange[k] = SLOW
        lateness[k + 1] = LATE  # the slow exchange ends 0.2 ms after the next deadline
    starts = np.arange(PREFLIGHT_CYCLES) * T + lateness
    started_late = int(np.count_nonzero(lateness > T))  # the clock's overruns: none
    return Timing(T, lateness, starts, exchange, started_late)


def test_a_refusal_line_does_not_contradict_its_count() -> None:
    assert allowed_overruns(PREFLIGHT_CYCLES) == 5
    report = judge_delay(_timing(), 1.0, lambda delay: True, "off", math.inf, None)
    assert not report.holdable
    assert report.overruns == 0
    line = report.line()
    assert "6 of 500 cycles were busy (late start plus exchange) longer than T = 1 ms" in line
    assert "at most 5 of 500" in line
    assert "0 started more than T late, 6 busy longer than T (5 allowed)" in line
    assert "0 overruns" not in line
    assert (report.busy_over_period, report.busy_allowed) == (6, 5)  # run.json's preflight counts as the rule does


def _steady(period: float, exchange: float) -> Timing:
    """500 cycles on ``period`` s, each an exchange of ``exchange`` s started on its deadline."""
    return Timing(period, np.zeros(PREFLIGHT_CYCLES), np.arange(PREFLIGHT_CYCLES) * period,
                  np.full(PREFLIGHT_CYCLES, exchange), 0)


def test_a_period_off_the_grid_that_holds_is_held_and_named() -> None:
    """T = 0.7 ms, every cycle busy 0.6 ms: none busy longer than T.  It was refused ("0 of 500
    cycles were busy ... longer than T = 0.7 ms ... (at most 5 of 500 ...): this machine holds
    T >= 0.75 ms": the grid's next step above the busy time, longer than T); 1 of 500 refused it live
    over CANopen on an idle machine in 2 pre-flights of 4."""
    report = judge_delay(_steady(0.7e-3, 0.6e-3), 1.0, lambda delay: True, "off", math.inf, None)
    assert report.holdable, report.reason
    assert report.smallest_period == 0.7e-3  # T itself: the grid's 0.75 ms is longer, the grid's 0.5 ms too short
    assert "holds T >= 0.7 ms" in report.line()


def test_a_period_off_the_grid_that_does_not_hold_names_the_grid_step() -> None:
    """T = 0.7 ms, six cycles (apart) busy 0.72 ms, the rest 0.6 ms: one more than allowed busy
    longer than T, refused, the period named the grid's 0.75 ms (the next step above 0.72 ms)."""
    period, lateness, exchange = 0.7e-3, np.zeros(PREFLIGHT_CYCLES), np.full(PREFLIGHT_CYCLES, 0.6e-3)
    for k in (0, 80, 160, 240, 320, 400):
        exchange[k] = 0.72e-3
        lateness[k + 1] = 0.02e-3  # the slow exchange ends 0.02 ms after the next deadline
    slow = Timing(period, lateness, np.arange(PREFLIGHT_CYCLES) * period + lateness, exchange, 0)
    refused = judge_delay(slow, 1.0, lambda delay: True, "off", math.inf, None)
    assert not refused.holdable
    assert refused.smallest_period is not None and math.isclose(refused.smallest_period, 0.75e-3, rel_tol=1e-12)
    assert "6 of 500 cycles were busy" in refused.reason


def test_the_period_named_is_one_the_bus_carries() -> None:
    """gantry-3d's three axes at 1 Mbit/s: the bus-load check wants T >= 1.386 ms; beside one CPU
    hog pre-flight at T = 2 ms said "holds T >= 1.25 ms", a T the profile check then refused as
    invalid (exit 2).  Every cycle busy 1 ms: the grid step above the bus' floor is named (1.5 ms);
    at T = 1.4 ms, which the bus carries and the machine holds, T itself."""
    floor = 1.386e-3  # s: 970 bits per cycle / (0.7 * 1 Mbit/s)
    at_2 = judge_delay(_steady(2e-3, 1e-3), 1.0, lambda delay: True, "off", math.inf, None, floor)
    assert at_2.holdable and at_2.smallest_period is not None
    assert math.isclose(at_2.smallest_period, 1.5e-3, rel_tol=1e-12)
    at_14 = judge_delay(_steady(1.4e-3, 1e-3), 1.0, lambda delay: True, "off", math.inf, None, floor)
    assert at_14.holdable and at_14.smallest_period == 1.4e-3
