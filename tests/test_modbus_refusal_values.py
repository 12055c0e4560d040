"""An option refused beside ``--modbus`` is named with the value the user typed: a list of ids as
typed (``--node-ids = '5,6'``, not ``'5 6'``, which reads as two arguments), and ``haptic-bus
sim``'s refusal names each option with its value, as the other commands' do.  Exit 2, nothing on
stdout, no server started (the port is never opened: nothing listens on it)."""

from __future__ import annotations

import pytest

from haptic_bus.app.cli import main as haptic_bus
from sim_drive.cli import main as sim

MODBUS = ["--modbus", "tcp://127.0.0.1:15598"]


@pytest.mark.parametrize(("argv", "line"), [
    (["scan", *MODBUS, "--node-ids", "5,6"],
     "haptic-bus scan: error: --node-ids = '5,6' is invalid; allowed: only Modbus options (--unit-ids) "
     "with --modbus\n"),
    (["run", "cia402-handle", *MODBUS, "--bus-kwargs", "port=4", "ttl=0"],
     "haptic-bus run: error: --bus-kwargs = 'port=4 ttl=0' is invalid; allowed: only Modbus options "
     "(--unit-id) with --modbus\n"),
])
def test_haptic_bus_names_the_value_typed(argv: list[str], line: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert haptic_bus(argv) == 2
    out, err = capsys.readouterr()
    assert (out, err) == ("", line)


@pytest.mark.parametrize(("argv", "line"), [
    ([*MODBUS, "--node-id", "5"], "haptic-bus sim: error: CANopen options cannot be combined with --modbus: --node-id = 5\n"),
    ([*MODBUS, "--bus-option", "port=4"],
     "haptic-bus sim: error: CANopen options cannot be combined with --modbus: --bus-option = 'port=4'\n"),
    ([*MODBUS, "--eds-path"], "haptic-bus sim: error: CANopen options cannot be combined with --modbus: --eds-path\n"),
    (["--unit-id", "3"], "haptic-bus sim: error: Modbus options need --modbus: --unit-id = 3\n"),
])
def test_sim_names_each_option_with_its_value(argv: list[str], line: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert sim(argv) == 2
    out, err = capsys.readouterr()
    assert (out, err) == ("", line)
