"""``CanopenAxes.write_outputs`` refuses as ``read_inputs`` does, before any frame: before
``connect()`` ("not connected"), after ``close()`` ("closed"), and a count of torques other than one
per axis is invalid input (it used to try the safe stop on a bus never opened or released, log a
line per axis, and raise "the bus is closed"; a short list left an axis without its RPDO)."""

from __future__ import annotations

import logging
import re

import pytest

from drives.canopen.axes import CanopenAxes
from drives.errors import DriveError, ParameterError


def _axes() -> CanopenAxes:
    return CanopenAxes([5, 6], scalings=[None, None], interface="virtual", channel="axes-write-outputs")


@pytest.mark.parametrize(("closed", "said"), [(False, "not connected; call connect() first"),
                                              (True, "closed; create a new one")], ids=["new", "closed"])
def test_write_outputs_says_the_master_state_and_sends_nothing(closed: bool, said: str,
                                                              caplog: pytest.LogCaptureFixture) -> None:
    axes = _axes()
    if closed:
        axes.close()
    try:
        with caplog.at_level(logging.WARNING), pytest.raises(DriveError, match=rf"^CANopen nodes 5, 6: {re.escape(said)}$"):
            axes.write_outputs([0, 0])
        assert caplog.records == []  # no safe stop tried on a bus that is not there
    finally:
        axes.close()


@pytest.mark.parametrize("torques", [[0], [0, 0, 0], []], ids=["short", "long", "empty"])
def test_one_torque_per_axis(torques: list[int]) -> None:
    axes = _axes()
    try:
        with pytest.raises(ParameterError, match=rf"^CANopen nodes 5, 6: torques = {len(torques)} is invalid; "
                                                 r"allowed: one per axis \(2\)$"):
            axes.write_outputs(torques)
    finally:
        axes.close()
