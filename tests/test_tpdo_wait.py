"""A cycle waits for the drives' TPDOs at most half the shortest stall that faults a drive.

A cycle that waits for a silent drive sends every drive its RPDO, and the controller's heartbeat,
that much later: with the old flat 50 ms wait, a run at T = 1.25 ms (RPDO deadline 30 periods,
38 ms) whose node 6 fell silent had node 5 fault itself on its RPDO deadline, and the run blamed
node 5.  The wait is now the stall's half at most, so a silent drive is named after
``max_missed_tpdos`` waits while the others keep their RPDOs well inside their deadline.
"""

from __future__ import annotations

import math

import pytest

from drives.canopen.axes import CanopenAxes
from drives.canopen.drive import CanopenDrive
from drives.errors import ParameterError
from drives.safety import DEFAULT_TPDO_WAIT, SafetySettings


@pytest.mark.parametrize(("period", "stall", "wait"), [
    (0.001, 0.030, 0.015),  # RPDO deadline 30 ms binds (heartbeat consumer slack 90 - 20 = 70 ms)
    (0.00125, 0.038, 0.019),  # the breaker's T: 30 periods are 37.5 ms, 38 ms in 0x1400:05 (whole ms)
    (0.002, 0.060, 0.030),
    (0.005, 0.070, 0.035),  # deadline 150 ms: the consumer slack binds
])
def test_the_default_wait_is_half_the_stall_that_faults_the_drive(period: float, stall: float, wait: float) -> None:
    safety = SafetySettings()
    assert safety.canopen_stall(period) == pytest.approx(stall, rel=1e-12)
    assert safety.longest_tpdo_wait(period, None) == pytest.approx(wait, rel=1e-12)


def test_without_watchdogs_the_wait_is_the_default() -> None:
    safety = SafetySettings(master_node_id=None, rpdo_deadline_periods=0)
    assert math.isinf(safety.canopen_stall(0.001))
    assert safety.longest_tpdo_wait(0.001, None) == DEFAULT_TPDO_WAIT
    assert safety.longest_tpdo_wait(0.001, 1.0) == 1.0


def test_a_wait_longer_than_half_the_stall_is_refused_naming_it() -> None:
    with pytest.raises(ParameterError, match=r"tpdo_timeout = 0.05 is invalid; allowed: a finite real in \(0, 0.015\] s: half "
                                             r"the shortest stall that faults the drive at T = 1 ms \(RPDO deadline 30 ms"):
        CanopenDrive(5, interface="virtual", channel="tpdo-wait-refused", period=0.001, tpdo_timeout=0.05)
    with pytest.raises(ParameterError, match="tpdo_timeout = 0 is invalid"):
        SafetySettings().longest_tpdo_wait(0.001, 0)


def test_one_drive_and_several_wait_the_same() -> None:
    drive = CanopenDrive(5, interface="virtual", channel="tpdo-wait-one", period=0.00125)
    axes = CanopenAxes([5, 6], scalings=[None, None], interface="virtual", channel="tpdo-wait-axes", period=0.00125)
    try:
        assert drive.cycle.timeout == axes.cycle.timeout == pytest.approx(0.019, rel=1e-12)
    finally:
        drive.close()
        axes.close()
