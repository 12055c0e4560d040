"""Issue 11, CLI hygiene: every argument a user can get wrong is exit 2 with one line on stderr,
no traceback and nothing touched (no file, no frame, no connection); another master on the bus
is refused without disturbing the first; Ctrl-C is exit 130 with what was done so far written;
a closed pipe is no traceback.

Argument errors run the real command line in this process; signals go to real subprocesses.
"""

from __future__ import annotations

import json
import logging
import os
import pathlib
import signal
import socket
import stat
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from typing import Any

import can
import pytest

from drives.bus_config import open_bus
from tests.run_rig import NODE, profile_variant, read_record, read_run, run_cli

REPO = pathlib.Path(__file__).resolve().parents[1]
START_WAIT = 40.0  # s: a subprocess imports numpy/scipy/canopen/matplotlib before it does anything
CHECK = ["check", "--mass", "0.5", "--friction", "0.1", "--period", "0.001", "--stiffness", "200", "--damping", "100"]
RUN = ["run", "cia402-handle"]
BUS, URL = "{bus}", "{url}"  # replaced by a sniffed virtual bus and a listening TCP port

INVALID = [
    ([*RUN, BUS, "--node-id", "5", "--duration", "nan"], "--duration = nan is invalid; allowed: a finite"),
    ([*RUN, BUS, "--node-id", "5", "--duration", "inf"], "--duration = inf is invalid"),
    ([*RUN, BUS, "--node-id", "5", "--duration", "-1"], "--duration = -1 is invalid"),
    ([*RUN, BUS, "--node-id", "5", "--duration", "0"], "--duration = 0 is invalid"),
    ([*RUN, BUS, "--node-id", "0"], "--node-id = 0 is invalid; allowed: CANopen node ids 1..127"),
    ([*RUN, BUS, "--node-id", "200"], "--node-id = 200 is invalid; allowed: CANopen node ids 1..127"),
    ([*RUN, "--modbus", URL, "--unit-id", "999"],
     "--unit-id = 999 is invalid; allowed: Modbus unit ids 1..247"),
    (["run", "gantry-3d", "--modbus", URL, "--unit-ids", "1,x"],
     "--unit-ids = '1,x' is invalid; allowed: Modbus unit ids 1..247 as N, N-M or a comma-separated list"),
    ([*RUN, "--modbus", "tcp://127.0.0.1"], "--modbus = 'tcp://127.0.0.1' is invalid; allowed: tcp://HOST:PORT"),
    ([*RUN, BUS, "--node-id", "5", "--controller-node-id", "5"],
     "--controller-node-id = 5 is invalid; allowed: a node id other than the drive's (5)"),
    ([*RUN, "--modbus", URL, "--interface", "virtual"], "--interface = 'virtual' is invalid"),
    ([*RUN, "--modbus", URL, "--node-id", "5"], "--node-id = 5 is invalid"),
    ([*RUN, "--modbus", URL, "--controller-node-id", "9"], "--controller-node-id = 9 is invalid"),
    ([*RUN, "--modbus", URL, "--no-bus-log"], "--no-bus-log = True is invalid; allowed: CANopen runs only"),
    (["validate", "cia402-handle", "--modbus", URL, "--no-bus-log"],
     "haptic-bus validate: error: --no-bus-log = True is invalid; allowed: CANopen runs only"),
    ([*RUN, BUS, "--node-id", "5", "--unit-id", "3"], "--unit-id = 3 is invalid; allowed: a Modbus option"),
    ([*RUN, BUS], "--node-id is missing; allowed: the drive's node id, one of the CANopen node ids 1..127 (or --modbus URL)"),
    (["run", "no-such-profile", BUS, "--node-id", "5"], "profile = 'no-such-profile' is invalid; allowed: an existing TOML"),
    (["run", "{malformed}", BUS, "--node-id", "5"], "(TOML syntax)"),
    (["upload", BUS, "--node-id", "127", "--object", "0", "--stiffness", "1", "--damping", "1", "--timeout", "-1"],
     "--timeout = -1 is invalid"),
    (["demo", "--duration", "nan"], "--duration = nan is invalid"),
    (["demo", "--duration", "0"], "--duration = 0 is invalid"),
    ([*CHECK, "--velocity", "bogus"], "velocity = 'bogus' is invalid; allowed: 'point', 'average'"),
    ([*CHECK, "--delay", "-1"], "delay = -1.0 is invalid; allowed: a finite real in [0, 1000] samples"),
    (["run", "gantry-3d", BUS, "--node-ids", "5,6,7"], "unrecognized arguments: --node-ids 5,6,7"),  # the command's own
]


@pytest.mark.parametrize("args, said", INVALID, ids=[" ".join(a[:1] + a[2:]) if a[0] == "run" else " ".join(a)
                                                     for a, _ in INVALID])
def test_invalid_input_is_exit_2_one_line_and_nothing_touched(
        args: list[str], said: str, tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    inputs = tmp_path / "inputs"
    inputs.mkdir()
    malformed = inputs / "malformed.toml"
    malformed.write_text("[profile\nname = ")
    work = tmp_path / "cwd"  # where runs/ or haptic-bus-demo/ would appear
    work.mkdir()
    monkeypatch.chdir(work)
    channel = f"hygiene-{os.getpid()}-{time.monotonic_ns()}"
    with can.Bus(interface="virtual", channel=channel) as sniffer, socket.create_server(("127.0.0.1", 0)) as listener:
        url = f"tcp://127.0.0.1:{listener.getsockname()[1]}"
        bus = ["--interface", "virtual", "--channel", channel]
        argv = [part for arg in args for part in (bus if arg == BUS else [arg])]
        argv = [url if arg == URL else str(malformed) if arg == "{malformed}" else arg for arg in argv]
        result = run_cli(capsys, *argv)
        assert sniffer.recv(0.05) is None  # no frame
        listener.setblocking(False)
        with pytest.raises(BlockingIOError):
            listener.accept()  # no connection
    assert result.code == 2, (result.out, result.err)
    assert len(result.err_lines) == 1 and said in result.err_lines[0], result.err
    assert result.err_lines[0].startswith(f"haptic-bus {argv[0]}: error: ")
    assert "Traceback" not in result.err and result.out == ""
    assert list(work.iterdir()) == [] and sorted(p.name for p in inputs.iterdir()) == ["malformed.toml"]


@pytest.mark.parametrize("argv", [["profiles", "list", "--x"], ["profiles", "show", "cia402-handle", "--x"]])
def test_a_stray_argument_is_the_usage_error_of_the_subcommand_it_was_given_to(
        argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    result = run_cli(capsys, *argv)
    assert result.code == 2 and result.out == ""
    assert result.err_lines == [f"haptic-bus profiles {argv[1]}: error: unrecognized arguments: --x"]


def test_sim_modbus_help_is_help(capsys: pytest.CaptureFixture[str]) -> None:
    result = run_cli(capsys, "sim", "--modbus", "--help")
    assert result.code == 0 and result.err == ""
    assert result.out.startswith("usage: haptic-bus sim") and "--modbus tcp://HOST:PORT" in result.out


def test_run_help_shows_each_default_once(capsys: pytest.CaptureFixture[str]) -> None:
    result = run_cli(capsys, "run", "--help")
    assert result.code == 0 and result.err == ""
    text = " ".join(result.out.split())  # argparse wraps lines
    assert "seconds to run (default: 10.0)" in text and "gated wall uploads (default 127)" in text
    assert "(default 1; only with --modbus)" in text and "(default: runs/<UTC time>-<profile>)" in text
    assert "(default: None)" not in text and "(default: False)" not in text  # an unset default is not a default


def test_region_png_adds_the_suffix_and_says_so(tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "rdir"
    result = run_cli(capsys, "region", "--mass", "0.5", "--friction", "0.1", "--period", "0.001", "--delay", "1",
                     "--png", str(target))
    written = tmp_path / "rdir.png"
    assert result.code == 0, result.err
    assert result.out == f"wrote {written}\n" and not target.exists()
    assert written.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("png", ["", ".", "/"])
def test_region_png_without_a_name_is_refused_in_one_line(png: str, capsys: pytest.CaptureFixture[str]) -> None:
    result = run_cli(capsys, "region", "--mass", "0.5", "--friction", "0.1", "--period", "0.001", "--png", png)
    assert (result.code, result.out) == (2, "")  # --png '' was a traceback (pathlib's "has an empty name")
    assert result.err == f"haptic-bus region: error: --png = {png!r} is invalid; allowed: a PNG file's path (empty: none given)\n"


def test_region_png_on_a_pipe_is_refused_and_left_alone(tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A pipe (as a device: --png /dev/null run as root renamed a regular file over the device) is refused
    before the work; its open for the writable check waited for a reader, for ever."""
    pipe = tmp_path / "pipe.png"
    os.mkfifo(pipe)
    result = run_cli(capsys, "region", "--mass", "0.5", "--friction", "0.1", "--period", "0.001", "--png", str(pipe))
    assert result.code == 2 and result.out == ""
    assert result.err == (f"haptic-bus region: error: --png = '{pipe}' is invalid; allowed: a regular file or none "
                          "(not a device, a pipe or a socket)\n")
    assert stat.S_ISFIFO(pipe.stat().st_mode)


# ----------------------------------------------------------------------------- subprocesses

class Command:
    """``haptic-bus ARGS`` in a subprocess; stdout and stderr in unlinked files (they cannot fill up)."""

    def __init__(self, *args: str) -> None:
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
        self._out, self._err = (_unlinked_file() for _ in range(2))
        self.process = subprocess.Popen([sys.executable, "-m", "haptic_bus", *args], cwd=REPO, env=env,
                                        stdout=self._out, stderr=self._err)

    @staticmethod
    def _read(fd: int) -> str:
        return os.pread(fd, os.fstat(fd).st_size, 0).decode(errors="replace")

    @property
    def err(self) -> str:
        """Everything on stderr so far."""
        return self._read(self._err)

    @property
    def out(self) -> str:
        """Everything on stdout so far."""
        return self._read(self._out)

    def wait_until(self, ready: Callable[[], bool], what: str, timeout: float = START_WAIT) -> None:
        """Poll ``ready`` every 20 ms until it holds (bounded by ``timeout`` s); fail if the process ends first."""
        deadline = time.monotonic() + timeout
        while not ready():
            assert self.process.poll() is None, f"ended ({self.process.returncode}) before {what}: {self.err[-2000:]}"
            assert time.monotonic() < deadline, f"no {what} within {timeout} s: {self.err[-2000:]}"
            time.sleep(0.02)

    def interrupt(self, timeout: float = 60.0, signum: int = signal.SIGINT) -> int:
        """SIGINT (Ctrl-C; or ``signum``), then the exit status (bounded wait)."""
        self.process.send_signal(signum)
        return self.process.wait(timeout=timeout)

    def close(self) -> None:
        """Kill the process if it still runs (bounded wait) and drop its output."""
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait(timeout=10)
        os.close(self._out)
        os.close(self._err)


def _unlinked_file() -> int:
    """A descriptor of a file that is gone from the folder (nothing left behind)."""
    fd, path = tempfile.mkstemp(prefix="haptic-bus-test-")
    os.unlink(path)
    return fd


def _no_traceback(command: Command) -> list[str]:
    """stderr's lines, checked for a traceback and Python's 'Exception ignored' note."""
    err = command.err
    assert "Traceback" not in err and "Exception ignored" not in err, err[-3000:]
    return [line for line in err.splitlines() if line.strip()]


@pytest.mark.slow
def test_another_master_is_refused_and_the_first_run_goes_on_until_ctrl_c(
        multicast: tuple[str, int], tmp_path: pathlib.Path, caplog: pytest.LogCaptureFixture,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Two ``run``s against one drive on udp_multicast: the first a process of its own, the second
    and the simulated drive (as ``haptic-bus sim --profile cia402-handle`` builds it) in this one.
    The second is refused (exit 1) before it sends a frame; the first cycles on, and Ctrl-C ends it
    (exit 130).  The drive is not the process that matters (the Ctrl-C'd run is): in this process
    it costs no second interpreter's imports."""
    from drives.cia402 import State
    from sim_drive.canopen.slave import CanopenSimDrive
    from sim_drive.profile import read_simulated_device

    group, port = multicast
    bus = ["--interface", "udp_multicast", "--channel", group, "--bus-option", f"port={port}"]
    truth, operator = read_simulated_device("cia402-handle").one_axis()
    caplog.set_level(logging.INFO, logger="sim_drive.canopen.slave")  # its NMT transitions
    sim = CanopenSimDrive({"interface": "udp_multicast", "channel": group, "port": port}, NODE, timing=truth.timing,
                          parameters=truth.parameters, operator=operator, hand_needs_power=True)
    states: list[State] = []
    sim.drive.state_listeners.append(lambda old, new, number: states.append(new))
    sim.start()
    # the drive's heartbeat consumer at 1 s (default 60 ms, which this loaded machine can starve a
    # process for): what is tested here is the other master, not the heartbeat
    profile = profile_variant(tmp_path, "cia402-handle", "patient", extra="[safety]\nconsumer_ms = 1000\n")
    first = Command("run", str(profile), *bus, "--node-id", str(NODE), "--virtual-time", "--duration", "600", "--no-live",
                    "--no-plots", "--out", str(tmp_path / "first"))
    sniffer = open_bus(interface="udp_multicast", channel=group, port=port)
    tpdos = [0]

    def cycled(count: int) -> Callable[[], bool]:
        def ready() -> bool:  # up to 50 ms for a frame, then every frame queued (a few thousand a second)
            message = sniffer.recv(0.05)
            for _ in range(100_000):
                if message is None:
                    break
                tpdos[0] += message.arbitration_id == 0x180 + NODE
                message = sniffer.recv(0.0)
            return tpdos[0] >= count
        return ready

    try:
        first.wait_until(cycled(300), "300 cycles of the first run")
        second = run_cli(capsys, "run", "cia402-handle", *bus, "--node-id", str(NODE), "--virtual-time", "--duration", "1",
                         "--no-plots", "--out", str(tmp_path / "second"))
        first.wait_until(cycled(tpdos[0] + 300), "300 more cycles of the first run")  # not disturbed
        status = first.interrupt()
        said, printed = _no_traceback(first), first.out
    finally:
        sniffer.shutdown()
        first.close()
        sim.stop()
    assert second.code == 1, second.err
    (refusal,) = second.err_lines
    # its SYNCs, or (where the loaded machine held the first run's process for the whole listening window) the
    # drive it enabled: either names the other master (drives/canopen/commissioning.py), before a SYNC or RPDO is sent
    assert refusal.startswith(("haptic-bus run: drive error: CANopen node 5: another SYNC producer is on the bus",
                               "haptic-bus run: drive error: CANopen node 5: the drive is in OPERATION ENABLED before "
                               "this master enabled it: another master drives it")), refusal
    assert read_run(tmp_path / "second")["exit_reason"] == "drive error"
    # SIGINT stops the loop at a cycle boundary: one line says so, nothing went wrong
    assert status == 130 and said == ["haptic-bus run: interrupted (Ctrl-C)"], said
    assert "ended: interrupted; wrote " in printed
    document = read_run(tmp_path / "first")
    assert document["exit_reason"] == "interrupted" and document["events"] == []  # no fault, no alarm
    assert document["error"] == "interrupted (Ctrl-C)"
    _, record = read_record(tmp_path / "first")
    assert record["time_s"].size == document["summary"]["cycles"] >= 600
    assert not any("FAULT" in state.value for state in states), states
    assert State.OPERATION_ENABLED in states  # the listener saw the first run enable it
    started = [entry.getMessage() for entry in caplog.records if "NMT PRE-OPERATIONAL -> OPERATIONAL" in entry.getMessage()]
    assert len(started) == 1, caplog.text[-2000:]  # never reset again


@pytest.mark.slow
def test_ctrl_c_in_demo_is_130_with_the_record_written(tmp_path: pathlib.Path) -> None:
    out = tmp_path / "demo"
    demo = Command("demo", "-v", "--duration", "1000", "--out", str(out))
    try:
        demo.wait_until(lambda: "-> OPERATION ENABLED" in demo.err, "the drive enabled")  # cycling now
        time.sleep(0.2)
        assert demo.interrupt() == 130, demo.err[-2000:]
        _no_traceback(demo)
        assert "run ended early (interrupted): interrupted (Ctrl-C)" in demo.out
    finally:
        demo.close()
    assert read_run(out)["exit_reason"] == "interrupted"
    _, record = read_record(out)
    assert 0 < record["time_s"].size < 1_000_000
    assert all((out / name).is_file() for name in ("timeline.png", "force_position.png", "region.png"))


@pytest.mark.slow
def test_sigterm_in_demo_is_a_stop_exit_0_with_the_folder_complete(tmp_path: pathlib.Path) -> None:
    """A service manager's stop of ``demo`` ends it as it ends ``run`` (it was status 143, run.json left
    "running" and no pictures: break18)."""
    out = tmp_path / "demo"
    demo = Command("demo", "-v", "--duration", "1000", "--out", str(out))
    try:
        demo.wait_until(lambda: "-> OPERATION ENABLED" in demo.err, "the drive enabled")  # cycling now
        time.sleep(0.2)
        assert demo.interrupt(signum=signal.SIGTERM) == 0, demo.err[-2000:]
        _no_traceback(demo)
        assert "run ended early (stopped)\n" in demo.out
    finally:
        demo.close()
    document = read_run(out)
    assert (document["exit_reason"], document["ended"]) == ("stopped", True)
    _, record = read_record(out)
    assert 0 < record["time_s"].size == document["summary"]["cycles"] < 1_000_000
    assert all((out / name).is_file() for name in ("timeline.png", "force_position.png", "region.png"))


@pytest.mark.slow
def test_ctrl_c_in_bench_is_130_with_the_sections_done_written(tmp_path: pathlib.Path) -> None:
    out = tmp_path / "bench"
    bench = Command("bench", "--quick", "--only", "bus", "--only", "passivity", "--out", str(out))
    try:  # the bus section's last tick ends it; the passivity section's first tick takes seconds
        bench.wait_until(lambda: "bus: measured" in bench.err, "the bus section done")
        assert bench.interrupt() == 130, bench.err[-2000:]
        assert _no_traceback(bench)[-1] == ("haptic-bus bench: interrupted in section passivity; bench.json holds "
                                            "the sections before it")
    finally:
        bench.close()
    result = json.loads((out / "bench.json").read_text())
    assert result["interrupted"] == "passivity" and list(result["sections"]) == ["bus"]
    assert result["sections"]["bus"]["available"] and (out / "bench.md").is_file()


@pytest.mark.slow
def test_sigterm_in_bench_is_130_as_ctrl_c_with_the_sections_done_written(tmp_path: pathlib.Path) -> None:
    """SIGTERM (``timeout``, ``kill``) takes Ctrl-C's path: the section stops where it stands, its processes
    stopped, bench.json written with the sections so far, one line on stderr naming the signal.  It was
    SIGTERM's default action: exit 143, no bench.json, a section's simulated drive left without a parent
    (break17).  The soak ticks ten times; SIGTERM goes after its first tick, when the handlers are in place:
    2e4 cycles run on 2.9 s past it undisturbed (5.8-6.4 s beside two CPU-bound processes), and the signal takes
    milliseconds."""
    out = tmp_path / "bench"
    bench = Command("bench", "--smoke", "--only", "soak", "--soak", "2e4", "--out", str(out))
    try:
        bench.wait_until(lambda: "soak:" in bench.err, "the soak's first tick")
        assert bench.interrupt(signum=signal.SIGTERM) == 130, bench.err[-2000:]
        assert _no_traceback(bench)[-1] == ("haptic-bus bench: interrupted (SIGTERM) in section soak; bench.json holds "
                                            "the sections before it")
        assert json.loads((out / "bench.json").read_text())["interrupted"] == "soak"
    finally:
        bench.close()


PNG_END = b"IEND\xaeB`\x82"  # a PNG's last chunk (IEND, no data, its CRC): the file is written to its end


def _png_done(path: pathlib.Path) -> bool:
    """Whether ``path`` is a PNG written to its end (savefig writes the file in place: it exists, empty
    or part-written, while the figure is still being encoded)."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return False
    return data.startswith(b"\x89PNG\r\n\x1a\n") and data.endswith(PNG_END)


@pytest.mark.slow
def test_ctrl_c_in_report_is_130_with_the_figures_done_kept(tmp_path: pathlib.Path) -> None:
    """Ctrl-C once the first figure is done (written to its end: its file exists from the moment savefig
    opens it, and a Ctrl-C then left it empty, 0 bytes, in a run of the suite beside other load)."""
    out = tmp_path / "report"
    report = Command("report", "multi-object", "--out", str(out))  # five contact walls: figures for seconds
    try:
        report.wait_until(lambda: _png_done(out / "fig4_region.png"), "the first figure")
        assert report.interrupt() == 130, report.err[-2000:]
        assert _no_traceback(report) == ["haptic-bus: interrupted"]
    finally:
        report.close()
    assert _png_done(out / "fig4_region.png")


# A listing of lines, and one JSON document.  Every command prints into Python's buffer and the
# command line flushes it once at the end (haptic_bus.app.cli.main): ``profiles show`` meets the
# closed pipe where ``profiles list`` would, and costs 0.35 s of CPU where ``profiles list`` costs
# 2.5 s (it judges every shipped profile's walls before it prints).
SHOW = ["profiles", "show", "cia402-handle"]


@pytest.mark.parametrize("args", [SHOW, [*CHECK, "--json"]], ids=["profiles-show", "check-json"])
def test_a_closed_pipe_is_no_traceback(args: list[str]) -> None:
    """``haptic-bus profiles show cia402-handle | head -1`` with the reader gone before the first write (deterministic)."""
    reader, writer = os.pipe()
    os.close(reader)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    try:
        done = subprocess.run([sys.executable, "-m", "haptic_bus", *args], cwd=REPO, env=env, stdout=writer,
                              stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(writer)
    assert done.stderr == "" and done.returncode in (0, 1), done.stderr  # check: 0 passive (1 would be "not passive")


def test_a_run_whose_stdout_reader_is_gone_runs_to_its_end(haptic_sim: Any, tmp_path: pathlib.Path) -> None:
    """``haptic-bus run ... | head -1`` (break18): the run's scaling lines met the closed pipe in its set-up, the
    run ended "crashed" (BrokenPipeError in run.json, nothing recorded) and the console script exited 0 in
    silence.  The reader gone before the first write (deterministic): the run completes, every row written."""
    drive = haptic_sim("cia402-handle", interface="modbus")  # on 127.0.0.1, served by this process
    reader, writer = os.pipe()
    os.close(reader)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    try:
        done = subprocess.run([sys.executable, "-m", "haptic_bus", "run", "cia402-handle", *drive.run_args(),
                               "--virtual-time", "--duration", "0.5", "--no-plots", "--out", str(tmp_path / "run")],
                              cwd=REPO, env=env, stdout=writer, stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(writer)
    assert (done.returncode, done.stderr) == (0, "")
    document = read_run(tmp_path / "run")
    assert (document["status"], document["record"]) == ("completed", {"rows_written": 500, "rows_lost": 0})


def test_a_pipe_to_head_is_no_traceback() -> None:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    done = subprocess.run(f"{sys.executable} -m haptic_bus {' '.join(SHOW)} | head -1", shell=True, cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stderr == "" and len(done.stdout.splitlines()) == 1


def test_another_master_over_modbus_is_refused_without_a_write(tmp_path: pathlib.Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    """Modbus TCP on 127.0.0.1: a first master (the Python API, cycling in a thread) has the drive
    enabled; a second ``run`` finds it OPERATION ENABLED and is refused (exit 1) before it writes
    anything -- not even the safe outputs a closing master writes -- and the first cycles on."""
    from drives.cia402 import State
    from drives.modbus.drive import ModbusDrive
    from drives.safety import VIRTUAL_TIME_MODBUS_PATIENCE
    from haptic_bus.app.profiles import load_profile
    from haptic_bus.control.controller import WallController
    from haptic_bus.control.joints import encoder_origin
    from tests.run_rig import simulated_drive

    profile = load_profile("cia402-handle")
    ended: list[Any] = []
    with simulated_drive("modbus", "cia402-handle") as sim:
        url = sim.args[1]
        first = ModbusDrive.from_url(url, scaling=profile.scaling(), safety=profile.safety.for_virtual_time(1e-3),
                                     **VIRTUAL_TIME_MODBUS_PATIENCE)  # unpaced, beside a second process starting
        stop = threading.Event()
        try:
            first.connect()
            first.enable()
            controller = WallController(first, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit,
                                        origin=encoder_origin(first))
            thread = threading.Thread(target=lambda: ended.append(controller.run(10_000_000, stop)), daemon=True)
            thread.start()
            deadline = time.monotonic() + 30.0
            while controller.cycles < 200 and time.monotonic() < deadline:
                time.sleep(0.01)
            second = run_cli(capsys, "run", "cia402-handle", "--modbus", url, "--virtual-time", "--duration", "1",
                             "--no-plots", "--out", str(tmp_path / "second"))
            states, cycles = list(sim.states), controller.cycles
            deadline = time.monotonic() + 30.0
            while controller.cycles < cycles + 200 and time.monotonic() < deadline:
                time.sleep(0.01)
        finally:
            stop.set()
            thread.join(timeout=10.0)
            first.close()
    assert second.code == 1, second.err
    (refusal,) = second.err_lines
    assert refusal == (f"haptic-bus run: drive error: Modbus unit 1 at {url}: the drive is in OPERATION ENABLED before "
                       "this master enabled it: another master drives it; stop that master, or disable the drive, before "
                       "starting this one")
    assert read_run(tmp_path / "second")["exit_reason"] == "drive error"
    assert states[-1] is State.OPERATION_ENABLED and states.count(State.OPERATION_ENABLED) == 1, states  # undisturbed
    (summary,) = ended
    assert summary.exit_reason == "stopped" and summary.cycles >= cycles + 200
