"""SafetySettings.longest_tpdo_wait with custom settings: a refusal names each watchdog as it is set
(none where it is off), and a wait no watchdog bounds must still be finite (a silent drive would hold
the cycle for ever)."""

import math
import re

import pytest

from drives.errors import ParameterError
from drives.safety import SafetySettings

PERIOD = 0.001  # s


def test_no_watchdog_allows_any_finite_wait_but_not_an_endless_one() -> None:
    settings = SafetySettings(rpdo_deadline_periods=0, master_node_id=None)
    assert settings.longest_tpdo_wait(PERIOD, 10.0) == 10.0
    assert settings.longest_tpdo_wait(PERIOD, None) == 0.05  # DEFAULT_TPDO_WAIT
    with pytest.raises(ParameterError, match=r"tpdo_timeout = inf is invalid; allowed: a finite real > 0 s: no stall "
                                             r"faults the drive at T = 1 ms \(RPDO deadline none, heartbeat "
                                             r"consumer slack none \(no heartbeat\)"):
        settings.longest_tpdo_wait(PERIOD, math.inf)


@pytest.mark.parametrize(("settings", "most_ms", "named"), [
    (SafetySettings(rpdo_deadline_periods=0), 35, "RPDO deadline none, heartbeat consumer slack 70 ms"),
    (SafetySettings(master_node_id=None), 15, "RPDO deadline 30 ms, heartbeat consumer slack none (no heartbeat)"),
])
def test_a_refusal_names_only_the_watchdogs_that_are_set(settings: SafetySettings, most_ms: int, named: str) -> None:
    # half the stall: (90 - 20) ms of consumer slack / 2 = 35 ms; 30 periods of 1 ms / 2 = 15 ms
    assert settings.longest_tpdo_wait(PERIOD, most_ms / 1000) == most_ms / 1000
    with pytest.raises(ParameterError, match=rf"a finite real in \(0, {most_ms / 1000:g}\] s: .*\({re.escape(named)}\)"):
        settings.longest_tpdo_wait(PERIOD, 0.1)


def test_a_wait_that_is_no_number_is_a_parameter_error() -> None:
    with pytest.raises(ParameterError, match=re.escape("tpdo_timeout = '0.01'")):
        SafetySettings().longest_tpdo_wait(PERIOD, "0.01")  # type: ignore[arg-type]
