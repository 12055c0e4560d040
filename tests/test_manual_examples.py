"""The manual's examples (``docs/*.md``) run here as the pages show them: every Python block (the drive
loop's documented bus the one substitution: this test's own simulated drive), and the console blocks
whose output does not depend on the machine, typed into bash from a folder that holds the repository's
``profiles`` and ``tests`` as the pages' "from the repository's root" asks, their output compared line
for line.

The console walk-through of ``docs/commissioning.md`` runs in ``tests/test_commissioning_walkthrough.py``.
The rest are recorded sessions whose path a test of its own drives as real processes (``RECORDED``);
every ``haptic-bus`` command line of every page is parsed by its own parser in ``tests/test_readme.py``.
"""

from __future__ import annotations

import ast
import json
import pathlib
import re
import shlex
import signal
import subprocess
import sys
import time
from typing import Any

import can
import pytest

from drives.safety import DEFAULT_SAFETY
from sim_drive.modbus.server import ModbusSimServer
from tests.console import Shell, console_commands, user_env
from tests.doc_blocks import PAGES, REPO, code_blocks
from tests.run_rig import profile_variant, run_cli, wait_until

DOCS = REPO / "docs"
DOCUMENTED_DRIVE_BUS = 'interface="udp_multicast", channel="239.74.163.2", bus_kwargs={"port": 43113}'


RUN_HERE = {  # (page, kind, index): the tests at the end of this file
    ("profiles.md", "console", 0), ("foreign-drive.md", "console", 0),
    ("operations.md", "console", 0), ("operations.md", "console", 1), ("operations.md", "json", 0),
}
WALKTHROUGH = {("commissioning.md", "console", i) for i in range(5)}  # tests/test_commissioning_walkthrough.py
RECORDED = {  # several processes, or several axes for 12 s: the tests that drive the same path
    ("controller.md", "bash", 0): "tests/test_run_plots.py",
    ("axes.md", "bash", 0): "tests/test_axes_run.py",
    ("axes.md", "bash", 1): "tests/test_modbus_axes.py",
    ("operations.md", "bash", 0): "tests/test_operations_e2e.py",
    ("validate.md", "bash", 0): "tests/test_validate.py",
}


def _example(page: str, index: int = 0) -> str:
    return code_blocks(DOCS / page, "python")[index]


def _run(code: str, page: str) -> dict[str, object]:
    namespace: dict[str, object] = {"__name__": f"docs.{page}"}
    exec(compile(code, str(DOCS / page), "exec"), namespace)
    return namespace


def test_every_python_example_of_the_manual_has_its_test_here() -> None:
    found = {(path.name, i) for path in PAGES for i, _ in enumerate(code_blocks(path, "python"))}
    assert found == {("errors.md", 0), ("errors.md", 1), ("python-api.md", 0), ("axes.md", 0)}  # the tests below


def test_every_other_block_of_the_manual_is_run_here_or_by_a_test_it_names() -> None:
    """A console, bash or JSON block runs here or in the walk-through, or names the test that drives its
    path (and that test exists)."""
    blocks = {(path.name, kind, i) for path in PAGES for kind in ("console", "bash", "json", "toml")
              for i, _ in enumerate(code_blocks(path, kind))}
    assert blocks == RUN_HERE | WALKTHROUGH | set(RECORDED)
    for (page, _, _), test in RECORDED.items():
        assert (REPO / test).is_file() and test in (DOCS / page).read_text(), (page, test)


def _from_the_root(tmp_path: pathlib.Path) -> pathlib.Path:
    """An empty folder that reads like the repository's root: its profiles and tests, linked."""
    for name in ("profiles", "tests"):
        (tmp_path / name).symlink_to(REPO / name)
    return tmp_path


def test_both_readers_refuse_a_bad_profile_with_the_same_line(tmp_path: pathlib.Path) -> None:
    commands = console_commands("```console\n" + code_blocks(DOCS / "profiles.md", "console")[0] + "```")
    assert len(commands) == 3
    shell = Shell(_from_the_root(tmp_path))
    try:
        for command, status in zip(commands, (0, 2, 2), strict=True):
            assert shell.type(command.text, 120) == (status, command.shown + "\n" if command.shown else ""), command.text
    finally:
        shell.close()


def test_the_simulator_behind_a_vendors_eds_logs_what_the_eds_lacks(tmp_path: pathlib.Path) -> None:
    """The page's lines are the simulator's first; it then serves until SIGTERM, which it exits on with 0."""
    [command] = console_commands("```console\n" + code_blocks(DOCS / "foreign-drive.md", "console")[0] + "```")
    shown = command.shown.splitlines()
    process = subprocess.Popen(["bash", "-c", f"exec {command.text}"], cwd=_from_the_root(tmp_path), env=user_env(),
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert process.stdout is not None
    try:
        deadline = time.monotonic() + 120  # s of wall clock: the imports, on a loaded machine
        lines = []
        while len(lines) < len(shown) and time.monotonic() < deadline:
            lines.append(process.stdout.readline().rstrip("\n"))
        unprivileged = r"; no real-time scheduling \(SCHED_FIFO 70 not granted: .*\)$"  # the page shows a privileged run
        assert [re.sub(unprivileged, "; SCHED_FIFO 70", line) for line in lines] == shown
    finally:
        process.send_signal(signal.SIGTERM)
        status = process.wait(30)
        process.stdout.close()
    assert status == 0


def test_the_errors_page_catches_each_branch_before_the_root() -> None:
    """The block runs (its body is `...`: it catches nothing); its handlers catch the classes haptic_bus.errors
    exports, each branch before the root, none after a class it derives from (a clause that never runs)."""
    from haptic_bus import errors

    code = _example("errors.md")
    namespace = _run(code, "errors.md")
    [block] = [node for node in ast.walk(ast.parse(code)) if isinstance(node, ast.Try)]
    caught = [namespace[ast.unparse(handler.type)] for handler in block.handlers if handler.type is not None]
    assert caught == [errors.ParameterError, errors.Refusal, errors.DriveError, errors.HapticBusError]
    assert not [(later, earlier) for i, earlier in enumerate(caught) for later in caught[i + 1:]
                if issubclass(later, earlier)]


@pytest.mark.parametrize("silenced", [False, True])
def test_the_errors_page_silences_a_bus_librarys_log_line(silenced: bool) -> None:
    """A program with no logging configured: canopen's ERROR record (the page's line) reaches stderr through
    Python's last-resort handler, and after the page's block it does not.  In a process of its own: the
    block sets a level on a logger this process shares."""
    record = 'logging.getLogger("canopen.sdo.client").error("Transfer aborted by client with code 0x05040000")'
    program = "\n".join([_example("errors.md", 1) if silenced else "import logging", record])
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, timeout=60, cwd=REPO)
    assert done.returncode == 0 and done.stdout == ""
    assert done.stderr == ("" if silenced else "Transfer aborted by client with code 0x05040000\n")


def test_the_drive_loop_of_the_python_api_page_runs_against_the_simulated_drive(haptic_sim) -> None:
    """1000 cycles of the page's 2 N s/m damper against the simulated drive in this process (the lock-step
    bus), whose hand pushes a constant 3 N on a handle of m = 1 kg, b = 20 N s/m.  The handle
    settles at v = 3 / (20 + 2) m/s: its time constant m / 22 = 45 ms is 1/22 of the loop's second
    (transient e^-22), and the damper's force is sent in whole per mille of torque (one per mille is
    0.32 N m x 50 / 1000 = 16 mN), so v is within 8 mN / 22 N s/m = 0.36 mm/s of it, plus one
    0x606C count (1 um/s)."""
    code = _example("python-api.md")
    assert code.count(DOCUMENTED_DRIVE_BUS) == 1
    push = {"model": "constant", "level": 3.0}
    drive = haptic_sim("cia402-handle", interface="lockstep", mass=1.0, friction=20.0, operator=push)
    bus = dict(drive.bus)
    interface, channel = bus.pop("interface"), bus.pop("channel")
    spelled = f"interface={interface!r}, channel={channel!r}, bus_kwargs={bus!r}"
    namespace = _run(code.replace(DOCUMENTED_DRIVE_BUS, spelled), "python-api.md")
    master, scaling = namespace["drive"], namespace["scaling"]
    assert master.stats.syncs_sent >= 1000
    assert master.stats.saturated_outputs == 0  # 3 N of damper force is 188 per mille, below the 500 asked
    velocity = namespace["inputs"].velocity * scaling.velocity_per_count
    permille_force = 0.32 * 50.0 / 1000.0
    assert velocity == pytest.approx(3.0 / 22.0, abs=permille_force / 2 / 22.0 + 1e-6)


def test_the_coupled_gate_example_agrees_with_its_own_limit() -> None:
    """The oblique wall K = 1500 N/m, B = 10 N s/m along (1, 1, 1) is passive exactly when 1500 N/m
    lies within the passive K the limits find along that direction at B = 10 (their ends are exact to
    1e-9 relative, far inside the distance of 1500 from either end)."""
    namespace = _run(_example("axes.md"), "axes.md")
    verdict = namespace["verdict"]
    largest = namespace["passive_along"](namespace["axes"], [1, 1, 1], K=0.0, B=10.0, which="K").largest
    assert verdict.passive == (1500.0 <= largest)
    assert (verdict.margin >= 0) == verdict.passive
    assert abs(1500.0 - largest) > 1e-6 * largest  # the verdict is not decided at a boundary's round-off


def _same_session(shown: str, got: str) -> bool:
    """``got`` is the output ``shown``, but for what moves from run to run: every decimal number (a
    position, a count of heartbeats, an elapsed time), a run folder's name (``...``), the columns' padding."""
    pattern = ""
    for piece in re.split(r"(?<![\w.])(-?\d+(?:\.\d+)?)(?![\w.])|(\.\.\.)|(\s+)", shown.strip()):
        if piece is None or piece == "":
            continue
        if re.fullmatch(r"-?\d+(?:\.\d+)?", piece):
            pattern += r"-?\d+(?:\.\d+)?"
        elif piece == "...":
            pattern += r"\S+"
        elif piece.isspace():
            pattern += r"\s+"
        else:
            pattern += re.escape(piece)
    return re.fullmatch(pattern, got.strip()) is not None


def test_the_operations_session_after_a_fault_on_canopen(haptic_sim: Any, frames: Any, tmp_path: pathlib.Path,
                                                         monkeypatch: pytest.MonkeyPatch,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """The page's CANopen session against the simulated drive in this process, left as the page's killed
    run left it (OPERATIONAL, cyclic synchronous torque, 500 ms heartbeat consumer for node 127, 200 ms
    RPDO deadline) and faulted as its RPDO deadline faults it (0x8250); its bus (``$B``) the one
    substitution, ``handle.toml`` the shipped profile with that ``[safety]``.  Each command's exit
    status is the one the page's text gives it.  Then the page's ``run --reset-fault`` after another
    fault, and the first event of its run.json, the page's JSON but for the reset's elapsed time."""
    page = (DOCS / "operations.md").read_text()
    documented = re.search(r'`B="([^"]*)"`', page)
    assert documented is not None
    drive = haptic_sim("cia402-handle")  # in this process, on python-can's virtual bus
    sim, channel = drive.sim, drive.bus["channel"]
    ours = f"--interface virtual --channel {channel}"
    master = can.Bus(interface="virtual", channel=channel)
    try:
        frames.nmt_start(master)
        assert wait_until(lambda: sim.nmt_state == "OPERATIONAL", 5.0)
        for index, subindex, value, size in ((0x6060, 0, 10, 1), (0x1016, 1, 127 << 16 | 500, 4), (0x1400, 5, 200, 2)):
            assert frames.sdo_write(master, index, subindex, value, size)[0] == 0x60, hex(index)  # download answered
        sim.enter_fault(0x8250)
    finally:
        master.shutdown()
    monkeypatch.chdir(tmp_path)
    profile_variant(tmp_path, "cia402-handle", "handle", extra="[safety]\nconsumer_ms = 500\nrpdo_deadline_periods = 200\n")
    commands = console_commands("```console\n" + code_blocks(DOCS / "operations.md", "console")[0] + "```")
    statuses = [1, 1, 0, 0, 0, 0, 1, 2]  # FAULT; refused in FAULT; reset; nothing to reset; read; write; abort; invalid
    assert len(commands) == len(statuses)
    for command, status in zip(commands, statuses, strict=True):
        typed = shlex.split(command.text.replace("$B", ours))
        assert typed[0] == "haptic-bus"
        result = run_cli(capsys, *typed[1:])
        got = result.out + result.err
        assert result.code == status, f"$ {command.text}\n{got}"
        assert _same_session(command.shown.replace(documented.group(1), ours), got), f"$ {command.text}\n{got}"
    # "After another kill -9, run --reset-fault ... runs, and run.json's first event is": the page's JSON
    sim.enter_fault(0x8250)
    result = run_cli(capsys, "run", "handle.toml", *shlex.split(ours), "--node-id", "5", "--duration", "0.05",
                     "--virtual-time", "--reset-fault", "-q", "--no-plots", "--out", "again")
    assert result.code == 0, result.err
    expected = json.loads(code_blocks(DOCS / "operations.md", "json")[0])
    event = json.loads((tmp_path / "again" / "run.json").read_text())["events"][0]
    assert _same_session(expected.pop("message"), event.pop("message"))
    elapsed = event["data"].pop("elapsed_s")
    assert 0 < elapsed < 1 and expected["data"].pop("elapsed_s") > 0  # s of wall clock: the reset's round trips
    assert event == expected


def test_the_operations_session_after_a_fault_on_modbus(capsys: pytest.CaptureFixture[str]) -> None:
    """The page's Modbus session against the simulated Modbus drive in this process on 127.0.0.1, left as
    a killed run leaves it (cyclic synchronous torque, the default watchdog, fault on connection loss)
    and faulted as its connection closing faults it (0x8100); its URL the one substitution."""
    commands = console_commands("```console\n" + code_blocks(DOCS / "operations.md", "console")[1] + "```")
    documented = "tcp://127.0.0.1:15020"
    server = ModbusSimServer("127.0.0.1", 0)
    server.start()
    try:
        server.drive.write_object(0x6060, 10)
        server.drive.write_object(0x6007, 1)
        server.bank.watchdog_ms = DEFAULT_SAFETY.modbus_watchdog_ms
        server.drive.fault(0x8100)
        for command, status in zip(commands, (1, 0, 2), strict=True):  # FAULT; reset; not an object of the map
            typed = shlex.split(command.text.replace(documented, server.url))
            result = run_cli(capsys, *typed[1:])
            got = result.out + result.err
            assert result.code == status, f"$ {command.text}\n{got}"
            assert _same_session(command.shown.replace(documented, server.url), got), f"$ {command.text}\n{got}"
    finally:
        server.stop()
