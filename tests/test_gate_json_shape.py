"""``profiles check --json`` and ``profiles show --json``: a multi-axis profile's gate has the keys a
one-axis profile's has (accepted, worst_margin, reasons, warnings), whatever else it adds."""

import json

import pytest

from haptic_bus.app.cli import main

ONE_AXIS_GATE_KEYS = {"accepted", "worst_margin", "reasons", "warnings"}


@pytest.mark.parametrize(("command", "key"), [("check", "gate"), ("show", "gate_decision")])
def test_a_multi_axis_gate_has_every_key_of_a_one_axis_gate(capsys: pytest.CaptureFixture[str], command: str,
                                                           key: str) -> None:
    gates = {}
    for name in ("cia402-handle", "gantry-3d"):
        assert main(["profiles", command, name, "--json"]) == 0
        gates[name] = json.loads(capsys.readouterr().out)[key]
    assert set(gates["cia402-handle"]) >= ONE_AXIS_GATE_KEYS
    assert set(gates["gantry-3d"]) >= ONE_AXIS_GATE_KEYS
    assert gates["gantry-3d"]["warnings"] == []  # the coupled gate of the shipped gantry warns of nothing
