"""The one stderr line of a command whose run ended without its result says the reason once (breaker13).

``haptic-bus validate`` interrupted by Ctrl-C printed ``interrupted: interrupted (Ctrl-C)``: the
run's error already names its reason.  ``identify`` had its own copy of the check; both use
:func:`~haptic_bus.app.run_options.ended_line` now.
"""

from __future__ import annotations

from haptic_bus.app.run_options import ended_line


def test_an_error_naming_its_reason_is_said_once() -> None:
    assert ended_line("interrupted", "interrupted (Ctrl-C)") == "interrupted (Ctrl-C)"


def test_an_error_not_naming_its_reason_is_prefixed_by_it() -> None:
    assert ended_line("stopped", "the run ended before the probe's last period") == \
        "stopped: the run ended before the probe's last period"
    assert ended_line("drive error", "node 5: no TPDO within 0.03 s") == "drive error: node 5: no TPDO within 0.03 s"
