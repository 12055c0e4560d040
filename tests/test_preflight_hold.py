"""Pre-flight's judgement runs beside the cycle: the drives go on getting their exchange meanwhile."""

from __future__ import annotations

import threading

import pytest

from haptic_bus.app.preflight import while_cycling

T = 2e-3  # s
WAIT = 10.0  # s: the longest the judgement waits for the cycles it asks for (they take 5 T = 10 ms)


def test_the_cycle_goes_on_until_the_judgement_is_done_and_its_result_returns() -> None:
    """The judgement finishes only once it has seen five exchanges (no clock asserted): had the
    cycle paused for it, it would wait its whole ``WAIT`` and return False."""
    exchanges: list[str] = []
    seen = threading.Event()

    def exchange() -> None:
        exchanges.append(threading.current_thread().name)
        if len(exchanges) == 5:
            seen.set()

    def judge() -> bool:
        assert threading.current_thread().name == "preflight-judge"
        return seen.wait(WAIT)

    assert while_cycling(exchange, T, judge) is True
    assert len(exchanges) >= 5 and set(exchanges) == {threading.current_thread().name}  # the caller's thread alone


def test_a_judgement_that_fails_raises_in_the_cycle_thread() -> None:
    def judge() -> bool:
        raise ValueError("gate: delay = nan is invalid")

    with pytest.raises(ValueError, match="delay = nan"):
        while_cycling(lambda: None, T, judge)
