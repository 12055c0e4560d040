"""The judge worker leaves Ctrl-C to the control process: a terminal's SIGINT reaches the whole
process group, and the worker printed a KeyboardInterrupt traceback beside the run's one line
(`haptic-bus run` / `validate` interrupted with exit 130)."""

from __future__ import annotations

import signal

from haptic_bus.node.verdicts import judge_pool


def test_the_judge_worker_ignores_sigint() -> None:
    assert judge_pool().submit(signal.getsignal, signal.SIGINT).result(timeout=120) == signal.SIG_IGN
