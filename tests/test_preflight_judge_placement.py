"""Pre-flight's judge thread runs where the real-time session puts the process's other threads.

A control thread with SCHED_FIFO (and SCHED_RESET_ON_FORK, as the session sets it) starts its
helper threads as ordinary ones; pre-flight's ``preflight-judge``, holding the GIL while an
ordinary process preempted it, held gantry-3d's cycle up 80-173 ms on a loaded machine.  It now
places itself at ``SCHED_FIFO`` :data:`GIL_PRIORITY` beside a SCHED_FIFO caller, and stays an
ordinary thread beside an ordinary one.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable

import pytest

from haptic_bus.app import preflight
from haptic_bus.app.realtime import GIL_PRIORITY, HelperPlacement

RESET_ON_FORK = getattr(os, "SCHED_RESET_ON_FORK", 0)
CALLER_PRIORITY = GIL_PRIORITY + 1  # above the judge's, as the control thread's FIFO_PRIORITY is
PERIOD = 1e-3  # s: the caller's cycle while the judge runs


def _judge_policy() -> tuple[int, int]:
    """The calling thread's scheduling policy (without the reset-on-fork flag) and priority."""
    return os.sched_getscheduler(0) & ~RESET_ON_FORK, os.sched_getparam(0).sched_priority


def _in_a_control_thread(body: Callable[[], None], fifo: bool = True) -> bool:
    """``body()`` in a fresh thread, first put at SCHED_FIFO :data:`CALLER_PRIORITY` with reset-on-fork if
    ``fifo``, as the session puts the control thread; False (``body`` not run) where SCHED_FIFO is not granted."""
    granted = [True]

    def caller() -> None:
        if fifo:
            try:
                os.sched_setscheduler(0, os.SCHED_FIFO | RESET_ON_FORK, os.sched_param(CALLER_PRIORITY))
            except PermissionError:
                granted[0] = False
                return
        body()

    thread = threading.Thread(target=caller, name="test-control")
    thread.start()
    thread.join(timeout=10.0)
    assert not thread.is_alive()
    return granted[0]


def _judged_from(fifo: bool) -> tuple[int, int] | str:
    """``while_cycling``'s work's policy, called from :func:`_in_a_control_thread`; "refused" where SCHED_FIFO is
    not granted."""
    out: list[tuple[int, int]] = []
    if not _in_a_control_thread(lambda: out.append(preflight.while_cycling(lambda: None, PERIOD, _judge_policy)), fifo):
        return "refused"
    return out[0]


def test_the_judge_is_fifo_below_a_fifo_control_thread() -> None:
    judged = _judged_from(fifo=True)
    if judged == "refused":
        pytest.skip("SCHED_FIFO not granted to this process")
    assert judged == (os.SCHED_FIFO, GIL_PRIORITY)


def test_the_judge_stays_ordinary_beside_an_ordinary_control_thread() -> None:
    assert _judged_from(fifo=False) == (os.SCHED_OTHER, 0)


def test_a_judge_left_judging_is_an_ordinary_thread_again() -> None:
    """A stop during the judgement (the exchange raises) leaves the judge working, unwaited for:
    it goes on as an ordinary thread (SCHED_OTHER), no longer above every ordinary process."""
    release = threading.Event()
    policies: list[tuple[int, int]] = []
    out: list[str] = []
    calls = [0]

    def exchange() -> None:
        calls[0] += 1
        if calls[0] == 3:
            raise KeyboardInterrupt  # what a Ctrl-C in the control thread is

    def judge() -> None:
        release.wait(timeout=10.0)
        policies.append(_judge_policy())

    def stopped_while_judged() -> None:
        try:
            preflight.while_cycling(exchange, PERIOD, judge)
        except KeyboardInterrupt:
            out.append("stopped")

    if not _in_a_control_thread(stopped_while_judged):
        pytest.skip("SCHED_FIFO not granted to this process")
    release.set()
    for judge_thread in [t for t in threading.enumerate() if t.name == "preflight-judge"]:
        judge_thread.join(timeout=10.0)
    assert out == ["stopped"]
    assert calls[0] == 3
    assert policies == [(os.SCHED_OTHER, 0)]


def test_a_judge_released_before_it_placed_itself_stays_ordinary() -> None:
    """The race a loaded machine showed (the test above once saw the judge at SCHED_FIFO 1): the stop released
    the judge before the new thread had run its first line, whose placement then made it SCHED_FIFO again.  Here
    the order is forced: the caller releases the judge, then the judge places itself."""
    policies: list[tuple[int, int]] = []
    released = threading.Event()

    def helper(placement: HelperPlacement) -> None:
        released.wait(timeout=10.0)
        placement.place()
        policies.append(_judge_policy())

    def release_first() -> None:
        placement = HelperPlacement()
        judge = threading.Thread(target=helper, args=(placement,), name="test-judge")
        judge.start()
        placement.release(judge)
        released.set()
        judge.join(timeout=10.0)

    if not _in_a_control_thread(release_first):
        pytest.skip("SCHED_FIFO not granted to this process")
    assert policies == [(os.SCHED_OTHER, 0)]
