"""``haptic_bus.app.cli.main`` called by a program, several times in one process: each call as the
first (one argparse parser serves them all), and the process' signal handling left as it was found
(a ``run`` installs its stop request for SIGINT and SIGTERM: after it returned, a Ctrl-C set that
finished run's event and interrupted nothing more)."""

from __future__ import annotations

import logging
import pathlib
import signal
import subprocess
import sys
import threading

import pytest

from drives.canopen.drive import CanopenDrive
from haptic_bus.app import cli
from haptic_bus.testing.buses import unique_name

CHECK = ["check", "--mass", "0.1", "--friction", "1", "--period", "0.001", "--stiffness", "1000", "--damping", "1"]
REGION = ["region", "--mass", "0.1", "--friction", "1", "--period", "0.001", "--png"]  # then a PNG path


def _said(capsys: pytest.CaptureFixture[str], argv: list[str]) -> tuple[int, str, str]:
    code = cli.main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_calls_in_turn_say_what_each_says_alone(tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "file").write_text("")
    unwritable = str(tmp_path / "file" / "region.png")  # under a file: no folder, not even for root
    calls = [["run", "--help"], [*CHECK, "--json", "--delay", "1"], [*CHECK, "--bogus"],
             [*REGION, unwritable, "--mark", "1,1"],
             ["upload", "--node-id", "5", "--object", "0", "--stiffness", "1", "--damping", "1", "--bus-option", "a=1",
              "--bus-option", "a=2"], ["-v", "profiles", "list"], CHECK, [*REGION, unwritable, "--mark", "x"], ["nosuch"], []]
    alone = []
    for argv in calls:
        cli._command_parser.cache_clear()  # a parser of its own, as a process of its own has
        alone.append(_said(capsys, argv))
    in_turn = [_said(capsys, argv) for argv in [*calls, *reversed(calls)]]
    assert in_turn == [*alone, *reversed(alone)]
    assert [code for code, _, _ in alone] == [0, 1, 2, 2, 2, 0, 0, 2, 2, 2]


def test_a_run_leaves_the_signal_handlers_as_it_found_them(tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str],
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    # nobody answers: the master's three waits for a drive (its statusword, the boot-up, an SDO probe) take 0.1 s
    # each, not the default 1 s, the run ending as it does at any length of them
    defaults = CanopenDrive.__init__.__kwdefaults__
    assert defaults is not None and "boot_timeout" in defaults
    monkeypatch.setitem(defaults, "boot_timeout", 0.1)
    found = {signum: signal.getsignal(signum) for signum in (signal.SIGINT, signal.SIGTERM)}
    code, _, err = _said(capsys, ["run", "cia402-handle", "--interface", "virtual", "--channel", unique_name("r8"),
                                  "--node-id", "5", "--virtual-time", "--duration", "1", "-q", "--no-plots",
                                  "--out", str(tmp_path / "run")])
    assert code == 1 and "no boot-up" in err, err  # no drive on the bus: the run got as far as its stop request
    assert {signum: signal.getsignal(signum) for signum in found} == found


def test_a_call_leaves_the_programs_logging_as_it_found_it(tmp_path: pathlib.Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """A command configures the root logger and the libraries' levels for its own output; a program's
    log file stays open and keeps what it had (``basicConfig(force=True)`` closed it, and a
    ``"w"``-mode file handler opened it again, emptied, at its next record)."""
    root, canopen_logger = logging.getLogger(), logging.getLogger("canopen")
    own = logging.FileHandler(tmp_path / "program.log", mode="w")
    found = (root.handlers[:], root.level, canopen_logger.level)
    root.addHandler(own)
    root.setLevel(logging.INFO)
    canopen_logger.setLevel(logging.NOTSET)
    try:
        logging.getLogger("program").info("before")
        code, _, err = _said(capsys, ["-v", "profiles", "list"])
        logging.getLogger("program").info("after")
        assert code == 0, err
        assert (root.handlers[-1], root.level, canopen_logger.level) == (own, logging.INFO, logging.NOTSET)
        assert own.stream is not None and not own.stream.closed
        own.flush()
        assert (tmp_path / "program.log").read_text().splitlines() == ["before", "after"]
    finally:
        root.removeHandler(own)
        own.close()
        root.handlers, _, _ = found
        root.setLevel(found[1])
        canopen_logger.setLevel(found[2])


def test_a_programs_bench_call_returns_to_the_program() -> None:
    """``haptic-bus bench`` execs the bench in the console script's process; a program's call runs it as a
    child and goes on with its status (an exec replaced the program: nothing after the call ran)."""
    program = "from haptic_bus.app.cli import main\nprint('after', main(['bench', '--no-such-option']), flush=True)\n"
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-1].split() == ["after", "2"], done.stdout
    assert "unrecognized arguments: --no-such-option" in done.stderr  # the bench's own usage error, on the streams


def test_calls_in_two_threads_leave_the_programs_logging_open_and_as_found(tmp_path: pathlib.Path,
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """Two threads' calls overlap: the first ends while the second runs (each call configures the root
    logger).  The program's log file stays open and its handler and level are the root's again (each
    call's basicConfig(force=True) closed what it found, and the second call put back the first's
    handler: the program's file closed, the root left with a closed handler at WARNING)."""
    root = logging.getLogger()
    own = logging.FileHandler(tmp_path / "program.log", mode="w")
    found = (root.handlers[:], root.level)
    configured, first_done = threading.Event(), threading.Event()
    configure = cli._configure_logging

    def call(name: str) -> None:
        codes[name] = cli.main(["-q", "profiles", "list"])

    second = threading.Thread(target=call, args=("second",), name="second")

    def overlapping(verbose: int | None, quiet: bool | None) -> None:
        configure(verbose, quiet)
        if threading.current_thread() is second:  # configured inside the first call, ends after it
            configured.set()
            assert first_done.wait(30)
        else:
            second.start()
            assert configured.wait(30)

    monkeypatch.setattr(cli, "_configure_logging", overlapping)
    codes: dict[str, int] = {}
    root.handlers = [own]
    root.setLevel(logging.INFO)
    try:
        first = threading.Thread(target=call, args=("first",), name="first")
        first.start()
        first.join(30)
        first_done.set()
        second.join(30)
        assert codes == {"first": 0, "second": 0}
        assert (root.handlers, root.level) == ([own], logging.INFO)
        assert own.stream is not None and not own.stream.closed
        logging.getLogger("program").info("after")
        own.flush()
        assert (tmp_path / "program.log").read_text().splitlines() == ["after"]
    finally:
        first_done.set()
        own.close()
        root.handlers = found[0]
        root.setLevel(found[1])
