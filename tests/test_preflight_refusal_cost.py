"""Pre-flight refuses a machine far behind without judging the scene at its absurd delay.

A three-axis run against a loaded machine measured a p99 lateness of 0.72 s at T = 2 ms: a loop
delay of 362 samples, where the coupled gate took over four minutes (27.7 s at 91 samples) while
the run, already refused by its busy cycles, waited with the drives' heartbeats going.
"""

from __future__ import annotations

import numpy as np

from haptic_bus.app.preflight import Timing, judge_delay

PERIOD = 2e-3  # s
CYCLES = 500


def _timing(exchange: float, late_by: float) -> Timing:
    """``CYCLES`` cycles on a T grid, each started ``late_by`` s late and busy ``exchange`` s."""
    deadlines = np.arange(CYCLES) * PERIOD
    lateness = np.full(CYCLES, late_by)
    return Timing(PERIOD, lateness, deadlines + lateness, np.full(CYCLES, exchange), 0)


def _never_judged(delay: float) -> bool:
    raise AssertionError(f"the gate was asked about a delay of {delay} samples on a refused timing")


def test_a_timing_the_machine_cannot_hold_is_refused_without_asking_the_gate() -> None:
    # every exchange 1.5 T: the median exchange alone refuses it; p99 lateness 0.7 s is 351 samples
    report = judge_delay(_timing(1.5 * PERIOD, 0.7), 1.0, _never_judged, "guard", 0.07, None)
    assert not report.holdable and report.reason.startswith("refused: one exchange with the drive takes 3 ms")
    assert report.passive_at_observed is None and report.to_dict()["passive_at_observed"] is None
    assert report.lateness["p99"] == 0.7  # still recorded: what the machine showed


def test_a_timing_the_machine_holds_asks_the_gate_once_at_the_measured_delay() -> None:
    asked: list[float] = []

    def passes_at(delay: float) -> bool:
        asked.append(delay)
        return delay < 2.0

    # each exchange 0.2 T, started 0.1 T late: held; the gate asked at 1 + 0.1 samples
    report = judge_delay(_timing(0.2 * PERIOD, 0.1 * PERIOD), 1.0, passes_at, "off", 0.07, None)
    assert report.holdable and report.passive_at_observed is True
    assert asked == [report.observed_delay] and abs(report.observed_delay - 1.1) < 1e-12  # float division only
    # assumed 1.7 samples, started 0.4 T late (busy 0.6 T, x1.5 within T: held): 2.1 samples, not passive, no layer
    late = judge_delay(_timing(0.2 * PERIOD, 0.4 * PERIOD), 1.7, passes_at, "off", 0.07, None)
    assert not late.holdable and late.passive_at_observed is False and "layer = \"off\"" in late.reason
