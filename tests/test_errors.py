"""The error tree: one root, one class for each thing a caller catches differently, none that is
two things, every class importable from haptic_bus.errors and drawn once in its docstring; a
drive's silence, and only it, also a TimeoutError; invalid input one class wide."""

from __future__ import annotations

import ast
import functools
import pathlib
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

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = ("haptic_bus", "drives", "sim_drive")
BUILTIN_MIXINS = {"ValueError", "TimeoutError"}  # what python-can's and our errors also are, for callers of the builtins


def _drawn() -> list[str]:
    return re.findall(r"(?:^ {4}|\+-- )([A-Z]\w+)", errors.__doc__ or "", flags=re.MULTILINE)


@functools.cache
def _error_classes() -> dict[str, list[str]]:
    """Every public exception class defined in the distribution's source: name -> its bases' names
    (parsed once for the module: 0.9 s of CPU; the callers only read it)."""
    found: dict[str, list[str]] = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                    bases = [b.id if isinstance(b, ast.Name) else ast.unparse(b) for b in node.bases]
                    if any(b in BUILTIN_MIXINS | {"Exception"} or b in found or b.endswith(("Error", "Refusal"))
                           for b in bases):
                        found[node.name] = bases
    return found


def test_the_docstring_draws_every_error_class_once_and_there_are_few():
    drawn = _drawn()
    assert len(drawn) == len(set(drawn)), "a class drawn twice"
    assert set(_error_classes()) == set(drawn), sorted(set(_error_classes()) ^ set(drawn))
    assert len(drawn) == 11  # python-can has 5; one per thing a caller catches differently


def test_no_class_is_two_things():
    """Each class has one parent in the tree; a second base may only be a builtin a caller of the
    builtins catches (ValueError for invalid input, TimeoutError for a silence)."""
    for name, bases in _error_classes().items():
        ours = [b for b in bases if b not in BUILTIN_MIXINS]
        assert len(ours) == 1, (name, bases)
    assert [c for c in (errors.DriveFault, errors.ModbusLinkLost, errors.DriveRefusal) if issubclass(c, TimeoutError)] == []


def test_haptic_bus_errors_offers_every_class_of_drives():
    defined = {c for c in vars(drives.errors).values() if isinstance(c, type) and issubclass(c, Exception)
               and c.__module__ == "drives.errors"}
    assert {c.__name__ for c in defined} <= set(errors.__all__)
    assert all(getattr(errors, c.__name__) is c for c in defined)


def test_one_root_and_invalid_input_is_one_class():
    for name in ("ParameterError", "Refusal", "AssumptionBroken", "DriveError"):
        assert issubclass(getattr(errors, name), errors.HapticBusError)
    invalid = errors.ParameterError("x", 1, "0..0")
    assert isinstance(invalid, ValueError) and not isinstance(invalid, errors.DriveError)  # a misuse is no failure
    assert (invalid.name, invalid.value, invalid.allowed) == ("x", 1, "0..0")
    assert str(invalid) == "x = 1 is invalid; allowed: 0..0"


def test_a_value_not_given_is_said_missing_not_none():
    missing = errors.ParameterError("--node-id", None, "1..127", "run")
    assert str(missing) == "run: --node-id is missing; allowed: 1..127"
    assert (missing.name, missing.value, missing.detail) == ("--node-id", None, "--node-id is missing; allowed: 1..127")


def test_a_drive_in_fault_is_no_timeout_and_a_silence_is_one():
    fault = errors.DriveFault("node 5", "no OPERATION ENABLED within 1 s", state="SWITCH ON DISABLED")
    assert not isinstance(fault, TimeoutError) and isinstance(fault, errors.DriveError)
    assert (fault.node, fault.state, fault.code, str(fault)) == ("node 5", "SWITCH ON DISABLED", None,
                                                                  "node 5: no OPERATION ENABLED within 1 s")
    assert isinstance(errors.DriveTimeout("node 5", "silent"), TimeoutError)


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
    assert isinstance(caught.value, errors.HapticBusError) and not isinstance(caught.value, errors.DriveError)


def test_an_invalid_drive_argument_on_the_command_line_is_exit_2(capsys):
    """drives' bus configuration rejects a key given twice (a ParameterError): one line, exit 2,
    no bus opened."""
    args = ["scan", "--interface", "virtual", "--channel", "a", "--bus-option", "interface=socketcan", "--node-ids", "5"]
    assert main(args) == EXIT_INVALID
    err = capsys.readouterr().err
    assert err == ("haptic-bus scan: error: bus argument interface = 'socketcan' is invalid; allowed: one value per key "
                   "(interface = 'virtual' is given too)\n")


def test_refusals_share_one_class_and_keep_their_message():
    from haptic_bus.control.gate import GateDecision
    from haptic_bus.control.space_gate import SpaceDecision

    refusal = errors.Refusal.by_gate(GateDecision(False, (), ("wall: unstable",)))
    space = errors.Refusal.by_gate(SpaceDecision(False, (), ("block: unstable",)), "profile p.toml", "scene")
    assert str(refusal) == "passivity gate refused the change: wall: unstable"
    assert str(space) == "profile p.toml: passivity gate refused the scene: block: unstable"
    assert space.reasons == ("block: unstable",) and space.decision is not None
    start = errors.Refusal("handle is inside wall")
    assert start.reasons == ("handle is inside wall",) and start.decision is None


def test_importing_the_errors_loads_no_bus_library():
    code = "import sys, haptic_bus.errors; print(sorted(m for m in ('can', 'canopen', 'pymodbus') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "[]", out.stderr
