"""A drive's cyclic phase refuses what it cannot send safely (drives.base.Drive.cyclic): a limit
that is not a positive integer (one above 0x6072 is held to it), a target that is not an
integer, a second phase inside the first, and any use of the phase after it ended -- each one
line, nothing sent, the drive's own limit kept.  Against the simulated drive, a real CANopen
slave on python-can's virtual bus in this process."""

from __future__ import annotations

import math
from collections.abc import Callable
from contextlib import AbstractContextManager
from typing import Any

import numpy as np
import pytest

from drives.errors import DriveError, ParameterError


@pytest.mark.parametrize("limit", [-1, 0, math.nan, 1.5, True, "500"])
def test_a_limit_that_is_not_a_positive_integer_is_refused_and_changes_nothing(
        limit: Any, canopen_rig: Callable[..., AbstractContextManager[Any]]) -> None:
    with canopen_rig("virtual", "ideal") as r:
        own = r.drive.clamp.limit
        assert own == 3000  # the simulated drive's 0x6072 here
        refusal = r"torque_limit = .* is invalid; allowed: None or an integer >= 1 per mille \(held to the drive's own 3000"
        with pytest.raises(ParameterError, match=refusal):
            with r.drive.cyclic(limit):
                pass
        assert r.drive.clamp.limit == own
        with r.drive.cyclic(65536) as cycle:  # and the drive still opens a phase, its own limit the most
            assert cycle.saturate(70000) == own


def test_a_target_that_is_not_an_integer_sends_nothing(canopen_rig: Callable[..., AbstractContextManager[Any]]) -> None:
    with canopen_rig("virtual", "ideal") as r:
        drive = r.drive
        drive.enable()
        with drive.cyclic(500) as cycle:
            cycle.read()
            assert cycle.saturate_and_write(np.int64(100)) == 100  # numpy's integers are integers
            sent = drive.stats.rpdos_sent
            for bad in (math.nan, 250.7, "100", None, True):
                said = r"target torque (= .* is invalid|is missing); allowed: an integer, per mille"
                with pytest.raises(ParameterError, match=said):
                    cycle.saturate_and_write(bad)
                with pytest.raises(ParameterError):
                    cycle.write(bad)
            with pytest.raises(ParameterError):
                drive.write_outputs(math.nan)  # type: ignore[arg-type]
            assert drive.stats.rpdos_sent == sent  # nothing went out
            assert cycle.saturate_and_write(-9000) == -500  # the phase's limit, with its sign
        drive.disable()


def test_a_phase_is_one_at_a_time_and_ends_with_its_block(canopen_rig: Callable[..., AbstractContextManager[Any]]) -> None:
    with canopen_rig("virtual", "ideal") as r:
        drive = r.drive
        drive.enable()
        with drive.cyclic(400) as cycle:
            with pytest.raises(DriveError, match="a cyclic phase is open already"):
                with drive.cyclic():
                    pass
            cycle.read()
            cycle.saturate_and_write(100)
        sent = drive.stats.rpdos_sent
        with pytest.raises(DriveError, match="its cyclic phase has ended"):
            cycle.read()
        with pytest.raises(DriveError, match="its cyclic phase has ended"):
            cycle.saturate_and_write(400)
        assert drive.stats.rpdos_sent == sent and drive.clamp.limit == 3000
        with drive.cyclic() as again:  # a new phase opens
            again.read()
            again.saturate_and_write(0)
        drive.disable()
