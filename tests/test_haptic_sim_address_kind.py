"""The plugin's haptic_sim refuses, for a one-axis profile, the address its link does not use: a
unit_id on a CAN bus (``haptic_sim("cia402-handle", unit_id=3)`` started CANopen node 5) and a
node_id over Modbus (``node_id=9`` started unit 1), each ignored without a word."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from haptic_bus.errors import ParameterError


def test_a_unit_id_on_a_can_bus_is_refused(haptic_sim: Callable[..., Any]) -> None:
    with pytest.raises(ParameterError, match=r"unit_id = 3 is invalid; allowed: none with interface='virtual' "
                                             r"\(a CANopen node: node_id\)"):
        haptic_sim("cia402-handle", unit_id=3)


def test_a_node_id_over_modbus_is_refused(haptic_sim: Callable[..., Any]) -> None:
    with pytest.raises(ParameterError, match=r"node_id = 9 is invalid; allowed: none with interface='modbus' "
                                             r"\(a Modbus unit: unit_id\)"):
        haptic_sim("cia402-handle", interface="modbus", node_id=9)


def test_each_link_still_takes_its_own_address(haptic_sim: Callable[..., Any]) -> None:
    assert haptic_sim("cia402-handle", node_id=9).node_id == 9
    assert haptic_sim("cia402-handle", interface="modbus", unit_id=3).unit_ids == (3,)
