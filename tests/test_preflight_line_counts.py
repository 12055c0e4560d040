"""Pre-flight's printed line never states two counts that contradict each other (breaker13).

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
    assert "0 started more than T late" in line
    assert "0 overruns" not in line
