"""A flag's text that is no number at all is one line naming the flag's range, as an out-of-range number's
line is: argparse's own ``argument --mass: invalid float value: 'x'`` and ``node id = 'x' is not an
integer`` named none; ``bench --soak inf`` was an OverflowError's traceback and ``--soak 1.5`` ran 1 cycle
(break16)."""

from __future__ import annotations

import pytest

from haptic_bus.app.cli import main

BUS = ["--interface", "virtual", "--channel", "break16-flags"]
DEVICE = ["--mass", "1", "--friction", "20", "--period", "0.001"]


@pytest.mark.parametrize(("argv", "line"), [
    (["check", "--mass", "x", "--friction", "1", "--period", "1e-3", "--stiffness", "1", "--damping", "1"],
     "haptic-bus check: error: --mass = 'x' is invalid; allowed: a finite real in [1e-09, 1e+09] kg"),
    (["check", *DEVICE, "--stiffness", "1", "--damping", "1", "--delay", "one"],
     "haptic-bus check: error: --delay = 'one' is invalid; allowed: a finite real in [0, 1000] samples"),
    (["check", *DEVICE, "--stiffness", "1,5", "--damping", "1"],
     "haptic-bus check: error: --stiffness = '1,5' is invalid; allowed: a finite real in [0, 1e+15] N/m"),
    (["region", "--mass", "1", "--friction", "1", "--period", "1ms", "--png", "never.png"],
     "haptic-bus region: error: --period = '1ms' is invalid; allowed: a finite real in [1e-09, 10] s"),
    (["upload", *BUS, "--node-id", "127", "--object", "x", "--stiffness", "1", "--damping", "1"],
     "haptic-bus upload: error: --object = 'x' is invalid; allowed: an integer in [0, 255]"),
    (["upload", *BUS, "--node-id", "127", "--object", "0", "--stiffness", "1", "--damping", "q"],
     "haptic-bus upload: error: --damping = 'q' is invalid; allowed: a finite real in [0, 1e+15] N s/m"),
    (["status", *BUS, "--node-id", "x"],
     "haptic-bus status: error: --node-id = 'x' is invalid; allowed: CANopen node ids 1..127 "
     "(decimal, or 0x-hexadecimal)"),
    (["run", "cia402-handle", *BUS, "--node-id", "5", "--bitrate", "1M"],
     "haptic-bus run: error: --bitrate = '1M' is invalid; allowed: a positive whole number of bit/s"),
    (["run", "cia402-handle", *BUS, "--node-id", "5", "--duration", "ten"],
     "haptic-bus run: error: --duration = 'ten' is invalid; allowed: a finite real in (0, 1e+07] s"),
    (["bench", "--soak", "inf"], "haptic-bus bench: error: --soak = 'inf' is invalid; allowed: "
                                 "a whole number of cycles 1..1e9 (e.g. 1e6)"),
    (["bench", "--soak", "1.5"], "haptic-bus bench: error: --soak = '1.5' is invalid; allowed: "
                                 "a whole number of cycles 1..1e9 (e.g. 1e6)"),
])
def test_a_flag_that_is_no_number_names_its_range(argv: list[str], line: str, capfd: pytest.CaptureFixture[str]) -> None:
    """capfd: bench, a command that parses its own arguments, writes its line to the process' stderr."""
    assert main(argv) == 2
    out, err = capfd.readouterr()
    assert out == "" and err == line + "\n"


def test_the_range_is_still_checked_where_it_was(capsys: pytest.CaptureFixture[str]) -> None:
    """A number out of range is refused by the analysis with the same range as before (the flag's type
    only turns text into a number)."""
    assert main(["check", "--mass", "-1", "--friction", "1", "--period", "1e-3", "--stiffness", "1", "--damping", "1"]) == 2
    assert capsys.readouterr().err == ("haptic-bus check: error: mass = -1.0 is invalid; allowed: a finite real in "
                                       "[1e-09, 1e+09] kg\n")


@pytest.mark.parametrize("argv", [
    ["demo", "--out", "/proc/break16/out"],
    ["validate", "cia402-handle", *BUS, "--node-id", "5", "--out", "/proc/break16/out"],
    ["run", "cia402-handle", *BUS, "--node-id", "5", "--out", "/proc/break16/out"],
])
def test_a_run_folder_refused_is_named_by_the_command_typed(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    """demo's and validate's --out are checked as run's: the line said ``haptic-bus demo: error: run: --out``."""
    assert main(argv) == 2
    assert capsys.readouterr().err == (f"haptic-bus {argv[0]}: error: --out = '/proc/break16/out' is invalid; allowed: "
                                       "a folder this user can create and write (No such file or directory)\n")


@pytest.mark.parametrize(("argv", "line"), [
    (["run"], "haptic-bus run: error: profile is missing; allowed: profile name or TOML path"),
    (["plot"], "haptic-bus plot: error: RUN_DIR is missing; allowed: a folder haptic-bus run or demo wrote"),
    (["sdo"], "haptic-bus sdo: error: action is missing; allowed: read (SDO upload) or write (SDO download)"),
    (["profiles"], "haptic-bus profiles: error: a command is missing; allowed: one of list, show, check, new"),
])
def test_an_argument_left_out_is_missing_as_every_value_not_given(argv: list[str], line: str,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """argparse's "the following arguments are required: X" is said as a value not given is everywhere else
    (ParameterError's rule): "X is missing; allowed: " and what X takes, one line, exit 2 (break17b)."""
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(line) and err.count("\n") == 1, err


@pytest.mark.parametrize(("argv", "line"), [
    (["status", *BUS, "--node-id", "0"], "haptic-bus status: error: --node-id = 0 is invalid; allowed: CANopen node ids 1..127"),
    (["run", "cia402-handle", *BUS, "--node-id", "128"],
     "haptic-bus run: error: --node-id = 128 is invalid; allowed: CANopen node ids 1..127"),
    (["sim", *BUS, "--node-id", "0"], "haptic-bus sim: error: --node-id = 0 is invalid; allowed: CANopen node ids 1..127"),
    (["status", "--modbus", "tcp://127.0.0.1:47510", "--unit-id", "0"],
     "haptic-bus status: error: --unit-id = 0 is invalid; allowed: Modbus unit ids 1..247"),
    (["sim", "--modbus", "tcp://127.0.0.1:47510", "--unit-id", "0"],
     "haptic-bus sim: error: --unit-id = 0 is invalid; allowed: Modbus unit ids 1..247"),
    (["scan", *BUS, "--timeout", "0"], "haptic-bus scan: error: --timeout = 0 is invalid; allowed: a finite real in "
                                       "(0, 3600] s"),
    (["run", "cia402-handle", "--modbus", "udp://127.0.0.1:47510"],
     "haptic-bus run: error: --modbus = 'udp://127.0.0.1:47510' is invalid; allowed: tcp://HOST:PORT or rtu:/dev/SERIAL"),
])
def test_a_flag_out_of_range_is_named_once_by_every_command(argv: list[str], line: str,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """argparse's line named the flag twice (``argument --unit-id: unit id = 0 ...``) and ``sim --node-id 0`` named
    the slave's keyword (``CANopen slave: node_id = 0``): each says ``--FLAG = VALUE``, as every other refusal."""
    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert out == "" and err == line + "\n"


def test_every_command_that_names_a_drive_declares_its_id_flags_alike() -> None:
    """``--node-id`` and ``--unit-id`` are declared once (haptic_bus.app.drive_address), for run and validate as for
    the commands that name one drive: the same type, the same help."""
    import argparse

    from haptic_bus.app.cli import build_parser

    commands = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)).choices
    profiles = next(a for a in commands["profiles"]._actions if isinstance(a, argparse._SubParsersAction)).choices
    parsers = [commands[name] for name in ("run", "validate", "status", "fault-reset", "sdo", "identify")]
    for flag in ("--node-id", "--unit-id"):
        declared = {(action.type, action.help) for parser in [*parsers, profiles["new"]]
                    for action in parser._actions if flag in action.option_strings}
        assert len(declared) == 1, (flag, declared)
