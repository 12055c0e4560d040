"""``haptic-bus sim --mass --friction --coulomb --velocity-noise --noise-seed --operator --bus-kwargs --version``:
the command line's hidden truth and operator over the profile's, one line and exit 2 for a bad value,
and the values the running drive then serves."""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

import canopen
import pytest

from haptic_bus._version import __version__
from haptic_bus.errors import ParameterError
from sim_drive import operator as models
from sim_drive.cli import _parse, build_parser, main
from sim_drive.setups import drive_setup

CANOPEN = ["--interface", "virtual", "--channel", "overrides", "--node-id", "5"]
HEARTBEAT_WAIT = 15.0  # s: the subprocess imports numpy/scipy/canopen first


def _setup(*argv: str) -> tuple[Any, Any, str]:
    return drive_setup(_parse(build_parser(), [*CANOPEN, *argv]))


def test_the_flags_override_the_profiles_truth_and_operator() -> None:
    parameters, operator, timing = _setup("--profile", "cia402-handle", "--mass", "0.37", "--friction", "2.9",
                                          "--coulomb", "0.2", "--velocity-noise", "1000", "--noise-seed", "7",
                                          "--operator", "none")
    p = parameters
    assert (p.mass, p.friction, p.coulomb_friction, p.velocity_noise, p.noise_seed) == (0.37, 2.9, 0.2, 1000.0, 7)
    assert operator == models.NoOperator() and timing == "cia402"
    assert parameters.rated_torque == 0.32 and str(parameters.velocity) == "average"  # the rest is still the profile's
    parameters, operator, _ = _setup("--profile", "cia402-handle")
    assert (parameters.mass, parameters.friction) == (1.0, 20.0)  # no flag: the profile's
    assert operator == models.ConstantPush(3.0)


def test_without_a_profile_the_flags_override_the_defaults() -> None:
    parameters, operator, _ = _setup("--mass", "2", "--operator", "constant:-1.5")
    assert parameters.mass == 2.0 and parameters.friction == 0.1 and operator == models.ConstantPush(-1.5)


@pytest.mark.parametrize("spec, model", [
    ("none", models.NoOperator()),
    ("constant:3", models.ConstantPush(3.0)),
    ("step:2,0.5", models.StepPush(2.0, 0.5)),
    ("sinusoid:1,2", models.Sinusoid(1.0, 2.0)),
    ("sinusoid:1,2,0.5,-1", models.Sinusoid(1.0, 2.0, 0.5, -1.0)),
    ("chirp:1,0.5,20,10", models.Chirp(1.0, 0.5, 20.0, 10.0)),
    ("hand:300,5", models.HandModel(300.0, 5.0)),
    ("hand:300,5,0.001,0.01,0.002,1.5", models.HandModel(300.0, 5.0, 0.001, 0.01, 0.002, 1.5)),
])
def test_every_operator_model_has_a_spelled_form(spec: str, model: object) -> None:
    assert models.operator_from_spec(spec) == model


@pytest.mark.parametrize("spec", ["constant", "constant:1,2", "step:1,x", "hand:300", "recorded:"])
def test_a_spec_of_no_model_is_refused_with_every_spelled_form(spec: str) -> None:
    """Too few values, too many, not a number, no CSV: the spec is named as given and the usage listed
    (the command line's one line and exit 2 for it: ``push:3`` below)."""
    with pytest.raises(ParameterError) as refused:
        models.operator_from_spec(spec)
    assert (refused.value.name, refused.value.value, refused.value.allowed) == ("--operator", spec, models.operator_usage())


def test_a_recorded_operator_reads_its_csv(tmp_path: Any) -> None:
    track = tmp_path / "push, slow.csv"  # a comma in the path: only a trailing hold|linear is the interpolation
    track.write_text("time,force\n0,0\n1,2\n")
    assert models.operator_from_spec(f"recorded:{track}") == models.RecordedForce((0.0, 1.0), (0.0, 2.0), "hold")
    assert models.operator_from_spec(f"recorded:{track},linear").interpolation == "linear"


def test_a_misspelt_interpolation_after_an_existing_csv_is_named(tmp_path: Any) -> None:
    """``recorded:push.csv,cubic`` was refused as a file 'push.csv,cubic' that does not exist (break18)."""
    track = tmp_path / "push.csv"
    track.write_text("0,0\n1,2\n")
    with pytest.raises(ParameterError) as refused:
        models.operator_from_spec(f"recorded:{track},cubic")
    assert str(refused.value) == "--operator recorded: interpolation = 'cubic' is invalid; allowed: hold or linear"


@pytest.mark.parametrize("argv, message", [
    (["--mass", "-1"], "--mass = -1.0 is invalid; allowed: a finite real in [1e-09, 1e+09] kg"),
    (["--mass", "nan"], "--mass = nan is invalid"),
    (["--friction", "abc"], "--friction = 'abc' is invalid; allowed: a finite real in [0, 1e+12] N s/m"),
    (["--coulomb", "-0.1"], "--coulomb = -0.1 is invalid; allowed: a finite real in [0, 1e+06] N"),
    (["--velocity-noise", "1e12"], "--velocity-noise = 1000000000000.0 is invalid"),
    (["--noise-seed", "-1"], "--noise-seed = -1 is invalid; allowed: an integer in [0, 18446744073709551615]"),
    (["--operator", "push:3"], "--operator = 'push:3' is invalid; allowed: none | constant:level | step:level,start"),
    (["--operator", "chirp:1,2,3,0"], "--operator chirp: duration = 0.0 is invalid; allowed: a finite real in (0, 1e+09] s"),
    (["--operator", "recorded:/nonexistent.csv"], "a readable CSV file"),
    (["--bus-option", "port=1", "--bus-kwargs", "port=2"], "port = 2 is invalid; allowed: one value per key (port = 1"),
])
def test_a_bad_value_is_one_line_and_exit_2(argv: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*CANOPEN, *argv]) == 2  # refused before the bus is opened
    err = capsys.readouterr().err
    assert err.startswith("haptic-bus sim: error: ") and err.count("\n") == 1 and "Traceback" not in err, err
    assert message in err


def test_the_modbus_server_takes_the_truth_too_but_not_bus_kwargs(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--modbus", "tcp://127.0.0.1:0", "--mass", "0"]) == 2
    assert "--mass = 0.0 is invalid" in capsys.readouterr().err
    assert main(["--modbus", "tcp://127.0.0.1:0", "--bus-kwargs", "port=1"]) == 2
    assert "CANopen options cannot be combined with --modbus: --bus-kwargs" in capsys.readouterr().err


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--version"]) == 0
    assert capsys.readouterr().out == f"haptic-bus sim {__version__}\n"


def test_the_running_drive_serves_the_flags_values(sim_process: Callable[..., Any], bus_spec: Callable[[str], Any]) -> None:
    """A real ``python -m sim_drive`` on udp_multicast (its bus given with --bus-kwargs): m, b and the
    operator model read back over SDO from the manufacturer objects 0x2000 and 0x2010."""
    spec = bus_spec("udp_multicast")
    process = sim_process("--interface", "udp_multicast", "--channel", spec.channel,
                          "--bus-kwargs", *(f"{k}={v}" for k, v in spec.extra.items()), "--node-id", "5",
                          "--profile", "cia402-handle", "--mass", "0.37", "--friction", "2.9", "--operator", "none")
    process.wait_for_line("serving on", HEARTBEAT_WAIT)
    network = canopen.Network(spec.open())
    network.connect()
    try:
        node = network.add_node(canopen.RemoteNode(5, canopen.ObjectDictionary()))
        node.sdo.RESPONSE_TIMEOUT = 2.0
        mass, friction = (struct.unpack("<d", node.sdo.upload(0x2000, sub))[0] for sub in (1, 2))
        code = node.sdo.upload(0x2010, 1)[0]
    finally:
        network.disconnect()
    assert (mass, friction) == (0.37, 2.9)
    assert code == models.operator_code(models.NoOperator())  # the profile's constant push is overridden
    status, log = process.stop()
    assert status == 0, log
