"""The small things of issue 20: ``--version``, python-can's ``--bus-kwargs`` beside ``--bus-option``,
and ``report --out`` refused in one line (exit 2) before any work when it cannot be a folder."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from haptic_bus._version import __version__
from haptic_bus.app.arguments import bus_arguments
from haptic_bus.app.cli import build_parser, main

REPO = Path(__file__).resolve().parents[1]
SUBPROCESS_WAIT = 60.0  # s: a Python process that imports the command line, under the suite's load
HEARTBEAT_WAIT = 15.0  # s: the simulator subprocess imports numpy/scipy/canopen first
RUN_WAIT = 60.0  # s: the longest a 0.1 s virtual-time run (100 cycles) may take, its commissioning included, in a thread


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--version"]) == 0
    assert capsys.readouterr().out == f"haptic-bus {__version__}\n"
    assert main(["sim", "--version"]) == 0
    assert capsys.readouterr().out == f"haptic-bus sim {__version__}\n"


@pytest.mark.parametrize(("argv", "code", "out"), [
    (["--version"], 0, f"haptic-bus {__version__}\n"),
    (["status", "--node-id", "0"], 2, ""),
])
def test_python_m_haptic_bus_is_the_console_script(argv: list[str], code: int, out: str,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """``python -m haptic_bus`` ran nothing: there was no ``haptic_bus/__main__.py`` (and ``python -m
    haptic_bus.app.entry`` exits 0 having done nothing: entry is the console script's target, not a module
    to run).  It now prints and exits as ``haptic-bus`` does."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    done = subprocess.run([sys.executable, "-m", "haptic_bus", *argv], cwd=REPO, env=env, capture_output=True, text=True,
                          timeout=SUBPROCESS_WAIT)
    assert main(argv) == code
    said = capsys.readouterr()
    assert (done.returncode, done.stdout, done.stderr) == (code, out, said.err) and said.out == out


@pytest.mark.parametrize(("argv", "said"), [
    (["check", "--mass", "0.5", "--friction", "0.1", "--period", "1e-3", "--stiffness", "100", "--damping", "1",
      "--position-resolution", "-1e-6"], "--position-resolution = -1e-6 is invalid; allowed: a finite real in [0, 1e+06] m"),
    (["region", "--mass", "0.5", "--friction", "0.1", "--period", "1e-3", "--png", "never-written.png", "--mark", "-1,1"],
     "'-1,1': K and B must be finite and > 0"),
    (["check", "--mass", "0.5", "--friction", "0.1", "--period", "-1E-3", "--stiffness", "100", "--damping", "1"],
     "period = -0.001 is invalid"),
])
def test_a_negative_number_in_scientific_notation_is_a_value_whose_range_is_named(
        argv: list[str], said: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Python 3.11's argparse took ``-1e-6`` for an option ("expected one argument"): break15."""
    assert main(argv) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert said in line, line


def test_bus_kwargs_is_bus_option_as_python_can_spells_it() -> None:
    parser = build_parser()
    base = ["run", "cia402-handle", "--interface", "udp_multicast", "--channel", "239.74.20.99", "--node-id", "5"]
    spelled = bus_arguments(parser.parse_args([*base, "--bus-kwargs", "port=43113", "hop_limit=0", "--bus-kwargs", "x=a"]))
    options = bus_arguments(parser.parse_args([*base, "--bus-option", "port=43113", "--bus-option", "hop_limit=0",
                                               "--bus-option", "x=a"]))
    assert spelled == options == {"interface": "udp_multicast", "channel": "239.74.20.99", "port": 43113, "hop_limit": 0,
                                  "x": "a"}
    both = bus_arguments(parser.parse_args([*base, "--bus-option", "port=43113", "--bus-kwargs", "port=43113"]))
    assert both["port"] == 43113  # the same value twice is no conflict


@pytest.mark.parametrize("argv, message", [
    (["--bus-option", "port=1", "--bus-kwargs", "port=2"], "bus argument port = 2 is invalid; allowed: one value per key "
                                                            "(port = 1 is given too)"),
    (["--bus-kwargs", "channel=other"], "bus argument channel = 'other' is invalid; allowed: one value per key"),
    (["--bus-kwargs", "port"], "argument --bus-kwargs: 'port' is not KEY=VALUE"),
])
def test_conflicting_bus_arguments_are_one_line_and_exit_2(argv: list[str], message: str,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scan", "--interface", "no-such-interface", "--channel", "c", *argv]) == 2  # the bus is never opened
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err


def test_a_scan_finds_a_drive_through_bus_kwargs(sim_process: Callable[..., Any], bus_spec: Callable[[str], Any],
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    spec = bus_spec("udp_multicast")
    process = sim_process(*spec.sim_args(), "--node-id", "7")  # the drive's bus given with --bus-option
    process.wait_for_line("serving on", HEARTBEAT_WAIT)
    assert main(["scan", "--interface", spec.interface, "--channel", spec.channel, "--node-ids", "7",
                 "--bus-kwargs", *(f"{key}={value}" for key, value in spec.extra.items())]) == 0
    assert re.search(r"^\s+7\s+0x00020192\s+CiA-402 servo drive", capsys.readouterr().out, re.M)
    status, log = process.stop()
    assert status == 0, log


@pytest.mark.parametrize("where", ["a file", "inside a file"])
def test_report_out_that_cannot_be_a_folder_is_one_line_and_exit_2(where: str, tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    afile = tmp_path / "afile"
    afile.write_text("kept\n")
    out = afile if where == "a file" else afile / "report"
    assert main(["report", "cia402-handle", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    why = f"{afile} is a file, not a folder"  # the file in the way named, in both cases
    assert err == (f"haptic-bus report: error: --out = '{out}' is invalid; allowed: a folder this user can create "
                   f"and write ({why})\n")
    assert afile.read_text() == "kept\n"


@pytest.mark.parametrize("command", [["run", "cia402-handle", "--virtual-time"], ["status"], ["scan"]])
def test_an_interface_python_can_does_not_know_is_invalid_input(command: list[str], tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    """A typo in --interface is the user's (exit 2, one line listing python-can's interfaces), and
    a run writes no folder for it."""
    out = ["--out", str(tmp_path / "run")] if command[0] == "run" else []
    node = ["--node-id", "5"] if command[0] != "scan" else []
    assert main([*command, "--interface", "nope", "--channel", "x", *node, *out]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "interface = 'nope' is invalid; allowed: one of python-can's: " in err
    assert "udp_multicast" in err and "virtual" in err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("command", [["run", "cia402-handle", "--interface", "virtual", "--channel", "x", "--node-id", "5",
                                      "--virtual-time"], ["demo"], ["report", "cia402-handle"],
                                     ["plot", "a-run"]])  # plot drew into RUN_DIR
def test_an_empty_out_is_refused_not_taken_as_the_current_folder(command: list[str], tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    assert main([*command, "--out", ""]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--out = '' is invalid; allowed: a folder path (empty: none given)" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("transport", ["canopen", "modbus"])
def test_a_program_runs_the_command_line_in_a_thread_of_its_own(transport: str, tmp_path: Path) -> None:
    """``main(["run", ...])`` called from a thread other than the main one (a program's worker thread)
    runs to its end: Python installs signal handlers in the main thread alone, so the run installs none
    there, and the program's handlers stay as they were (it raised ValueError "signal only works in main
    thread" before the bus was touched)."""
    from tests.run_rig import simulated_drive

    handlers = {signum: signal.getsignal(signum) for signum in (signal.SIGINT, signal.SIGTERM)}
    outcome: list[object] = []
    with simulated_drive(transport, "cia402-handle") as drive:
        argv = ["run", "cia402-handle", *drive.args, "--virtual-time", "--duration", "0.1", "--out", str(tmp_path / "r"),
                "--no-plots", "-q"]
        worker = threading.Thread(target=lambda: outcome.append(main(argv)), name="program-worker")
        worker.start()
        worker.join(RUN_WAIT)
    assert not worker.is_alive() and outcome == [0]
    assert {signum: signal.getsignal(signum) for signum in handlers} == handlers
    assert json.loads((tmp_path / "r" / "run.json").read_text())["exit_reason"] == "completed"


def test_the_simulator_called_from_a_thread_says_why_it_cannot_serve_there(capsys: pytest.CaptureFixture[str]) -> None:
    """``haptic-bus sim`` serves until a signal, which a thread other than the main one never gets: one line,
    exit 2, before any bus (it raised ValueError from ``signal.signal``, or over Modbus blamed the socket)."""
    from sim_drive.cli import main as sim_main

    outcome: list[int] = []
    for argv in (["--interface", "virtual", "--channel", "thread-sim", "--node-id", "5"], ["--modbus", "127.0.0.1:0"]):
        worker = threading.Thread(target=lambda argv=argv: outcome.append(sim_main(argv)))
        worker.start()
        worker.join(RUN_WAIT)
    err = capsys.readouterr().err
    assert outcome == [2, 2] and err.count("\n") == 2 and err.count("Python delivers to the main thread alone") == 2, err
