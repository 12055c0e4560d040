"""What ``haptic-bus validate`` says of a run that gave no verdict: the reason once (breaker13: a
SIGTERM said "stopped: the run ended before the probe's last period", Ctrl-C "interrupted:
interrupted (Ctrl-C)")."""

from __future__ import annotations

import pytest

from haptic_bus.app.validate_cli import no_verdict_line


@pytest.mark.parametrize("reason, error, said", [
    ("stopped", None, "stopped (SIGTERM) before the probe's last period: no verdict"),
    ("interrupted", "interrupted (Ctrl-C)", "interrupted (Ctrl-C)"),
    ("completed", None, "drive error: the run ended before the probe's last period"),
    ("drive error", "node 5: no TPDO within 3 ms", "drive error: node 5: no TPDO within 3 ms"),
])
def test_the_line_says_the_reason_once(reason: str, error: str | None, said: str) -> None:
    assert no_verdict_line(reason, error) == said
