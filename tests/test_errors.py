"""The error tree: two roots (haptic_bus' and drives'), every class importable from haptic_bus.errors,
drawn once in its docstring, a drive's silence also a TimeoutError, invalid input one class wide."""

from __future__ import annotations

import importlib
import inspect
import re
import subprocess
import sys
import uuid

import pytest

import drives.errors
import haptic_bus.errors as errors
from drives.canopen.sdo import SdoAccess
from haptic_bus.app.cli import EXIT_INVALID, main
from haptic_bus.validation import real_in_range

# every module that defines an error class the docstring draws beside its own module
HOMES = ("haptic_bus.profile.reader", "haptic_bus.app.profiles", "haptic_bus.app.axes_profile",
         "haptic_bus.app.runner", "haptic_bus.control.space_gate", "haptic_bus.node.upload",
         "haptic_bus.identify.fit", "sim_drive.device")


def _classes(module: object) -> set[type[BaseException]]:
    return {c for _, c in inspect.getmembers(module, inspect.isclass)
            if issubclass(c, Exception) and c.__module__.split(".")[0] in ("drives", "haptic_bus", "sim_drive")}


def test_haptic_bus_errors_offers_every_class_of_both_roots():
    assert _classes(drives.errors) <= _classes(errors)
    assert set(errors.__all__) >= {c.__name__ for c in _classes(errors)}
    assert errors.ALL_ERRORS == (errors.HapticBusError, errors.FieldbusError)


def test_the_docstring_draws_every_error_class_once():
    drawn = re.findall(r"(?:^ {4}|\+-- )([A-Z]\w+)", errors.__doc__ or "", flags=re.MULTILINE)
    classes = _classes(errors) | set().union(*(_classes(importlib.import_module(m)) for m in HOMES))
    names = {c.__name__ for c in classes}
    assert names <= set(drawn), sorted(names - set(drawn))
    assert len(drawn) == len(set(drawn)), "a class drawn twice"


def test_the_two_roots_are_apart_and_invalid_input_spans_both():
    assert not issubclass(errors.FieldbusError, errors.HapticBusError)
    assert not issubclass(errors.HapticBusError, errors.FieldbusError)
    for invalid in (errors.ParameterError("x", 1, "0..0"), errors.DriveArgumentError("x", 1, "0..0")):
        assert isinstance(invalid, errors.InvalidInput) and isinstance(invalid, ValueError)
        assert (invalid.name, invalid.value, invalid.allowed) == ("x", 1, "0..0")
        assert str(invalid) == "x = 1 is invalid; allowed: 0..0"
        assert isinstance(invalid, errors.ALL_ERRORS)
    assert isinstance(errors.ParameterError("x", 1, ""), errors.HapticBusError)
    assert isinstance(errors.DriveArgumentError("x", 1, ""), errors.FieldbusError)
    assert not isinstance(errors.DriveArgumentError("x", 1, ""), errors.DriveError)  # a failure is not a misuse


def test_a_drive_silence_is_a_timeout_error_with_its_node():
    timeout = errors.DriveStateError("node 5", "no OPERATION ENABLED within 1 s", state="SWITCH ON DISABLED")
    assert isinstance(timeout, TimeoutError) and isinstance(timeout, errors.DriveError)
    assert (timeout.node, timeout.state, str(timeout)) == ("node 5", "SWITCH ON DISABLED",
                                                            "node 5: no OPERATION ENABLED within 1 s")
    assert issubclass(errors.ModbusLinkLost, TimeoutError) and not issubclass(errors.DriveFault, TimeoutError)


def test_a_silent_node_raises_a_timeout_a_caller_catches_as_the_builtin():
    """A real SDO read of a node nobody serves, on python-can's virtual bus."""
    import canopen

    network = canopen.Network()
    network.connect(interface="virtual", channel=f"errors-{uuid.uuid4()}")
    try:
        node = network.add_node(9, canopen.ObjectDictionary())
        node.sdo.MAX_RETRIES = 1  # one request, no retry
        with pytest.raises(TimeoutError) as caught:
            SdoAccess("node 9", node, 0.05, lambda: None).upload(0x1000)
        assert isinstance(caught.value, errors.DriveTimeout) and caught.value.node == "node 9"
    finally:
        network.disconnect()


def test_the_analysis_raises_the_haptic_bus_root():
    with pytest.raises(errors.ParameterError) as caught:
        real_in_range("mass", -1.0, 0.0, 10.0, unit="kg")
    assert isinstance(caught.value, errors.HapticBusError) and not isinstance(caught.value, errors.FieldbusError)


def test_an_invalid_drive_argument_on_the_command_line_is_exit_2(capsys):
    """drives' bus configuration rejects a key given twice (a DriveArgumentError): one line, exit 2,
    no bus opened."""
    args = ["scan", "--interface", "virtual", "--channel", "a", "--bus-option", "interface=socketcan", "--node-ids", "5"]
    assert main(args) == EXIT_INVALID
    err = capsys.readouterr().err
    assert err == ("haptic-bus scan: error: bus argument interface = 'socketcan' is invalid; allowed: one value per key "
                   "(interface = 'virtual' is given too)\n")


def test_gate_refusals_share_one_class_and_keep_their_message():
    from haptic_bus.control.gate import GateDecision
    from haptic_bus.control.space_gate import SpaceDecision, SpaceGateRefusal

    refusal = errors.GateRefusal(GateDecision(False, (), ("wall: unstable",)))
    space = SpaceGateRefusal(SpaceDecision(False, (), ("block: unstable",)), "profile p.toml")
    assert str(refusal) == "passivity gate refused the change: wall: unstable"
    assert str(space) == "profile p.toml: passivity gate refused the scene: block: unstable"
    assert isinstance(space, errors.GateRefusal) and space.decision.reasons == ("block: unstable",)


def test_importing_the_errors_loads_no_bus_library():
    code = "import sys, haptic_bus.errors; print(sorted(m for m in ('can', 'canopen', 'pymodbus') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "[]", out.stderr
