"""A drive error's line names a stall of this process as its cause (haptic_bus.app.runner._stall_before) whether
the process was held before a cycle started (that cycle's start lateness) or in the middle of its exchange (how
long the cycle that met the error had run: ``error_cycle_s``).  CI, December 7: a SIGSTOP that landed in the
exchange left the line without its cause, the cycles before having started on time."""

from __future__ import annotations

import time
from types import SimpleNamespace
from typing import Any, cast

import pytest

from haptic_bus.app.runner import _stall_before
from haptic_bus.control.clock import RealClock

T = 1e-3
STALL = 0.1  # s: the shortest stall the drive's watchdog faults on


def on_time_clock(cycles: int = 3) -> RealClock:
    clock = RealClock(T, capacity=16)
    for k in range(cycles):
        clock.wait_next(k)
    return clock


def test_a_cycle_held_in_its_exchange_is_named_as_the_stall() -> None:
    controller = cast(Any, SimpleNamespace(clock=on_time_clock(), error_cycle_s=0.25))
    assert _stall_before(controller, STALL) == (" (a cycle just before was held 250 ms late, past the 100 ms the drive's "
                                                "watchdog allows: this process did not run for that long, stopped or "
                                                "starved of CPU)")


def test_cycles_on_time_and_an_error_met_at_once_add_nothing() -> None:
    clock = on_time_clock()
    if clock.lateness().max() >= STALL:
        pytest.skip(f"this machine held this test's own cycles {clock.lateness().max() * 1e3:.3g} ms")
    assert _stall_before(cast(Any, SimpleNamespace(clock=clock, error_cycle_s=0.0)), STALL) == ""


def test_since_start_is_the_time_since_the_latest_cycle_began() -> None:
    clock = RealClock(T, capacity=4)
    assert clock.since_start() == 0.0  # before the first cycle
    clock.wait_next(0)
    time.sleep(0.02)
    assert clock.since_start() >= 0.02
