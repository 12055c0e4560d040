"""``haptic-bus sim`` / ``python -m sim_drive``: arguments (one parser for the CANopen slave and the
Modbus server), profiles, clean stop on signals."""

from __future__ import annotations

import os
import pathlib
import re
import signal
import socket
import struct
import subprocess
import sys
import threading

import can
import pytest

from drives.bus_config import open_bus
from drives.cia402 import Command
from haptic_bus.errors import ParameterError
from sim_drive import serve
from sim_drive.canopen.slave import CanopenSimDrive
from sim_drive.cli import _parse, build_parser, main
from sim_drive.eds import eds_path
from sim_drive.operator import HandModel
from sim_drive.parameters import Timing
from sim_drive.profile import read_simulated_device
from sim_drive.setups import modbus_axes_setup, node_id, unit_id

NODE = 11
BOOT_WAIT = 20.0  # s: the subprocess imports numpy, canopen, python-can first
STOP_AFTER = 20.0  # s: SIGTERM to a simulator in this process that serves where the test expects a refusal
MODBUS_URL = "tcp://127.0.0.1:0"
REPO = pathlib.Path(__file__).resolve().parents[1]


def one_error_line(err: str) -> str:
    """The single ``haptic-bus sim: error: ...`` line a usage error writes (and nothing else)."""
    assert err.startswith("haptic-bus sim: error: ") and err.count("\n") == 1, err
    assert "Traceback" not in err
    return err


def test_eds_path(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--eds-path"]) == 0
    assert capsys.readouterr().out.strip() == str(eds_path())


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--interface", "virtual", "--channel", "x"], "--node-id is missing; allowed: --interface NAME --channel CHANNEL"),
        (["--node-id", "5"], "--interface is missing; allowed: --interface NAME --channel CHANNEL and --node-id N"),
        (["--interface", "virtual", "--channel", "x", "--node-id", "0"], "--node-id = 0 is invalid; allowed: CANopen node ids"),
        (["--interface", "virtual", "--channel", "x", "--node-id", "3", "--timing", "late"], "invalid choice"),
        (["--interface", "virtual", "--channel", "x", "--node-id", "3", "--bus-option", "port"], "KEY=VALUE"),
        (["--interface", "virtual", "--channel", "x", "--node-id", "3", "--profile", "/nonexistent.toml"], "existing TOML"),
    ],
)
def test_bad_arguments_exit_2(argv: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(argv) == 2
    assert message in one_error_line(capsys.readouterr().err)


@pytest.mark.parametrize(
    "argv", [["--help"], ["-h"], ["--modbus", MODBUS_URL, "--help"], ["--modbus", "--help"], ["--node-id", "x", "--help"]]
)
def test_help_exits_0_and_shows_both_servers(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(argv) == 0
    out, err = capsys.readouterr()
    assert out.startswith("usage: haptic-bus sim") and err == ""
    for option in ("--interface", "--node-id", "--eds-path", "--modbus", "--unit-id", "--word-order", "--timing", "--profile"):
        assert option in out


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--modbus", MODBUS_URL, "--node-id", "3"], "CANopen options cannot be combined with --modbus: --node-id"),
        (["--modbus", MODBUS_URL, "--interface", "virtual", "--channel", "x", "--bitrate", "500000"],
         "--modbus: --interface = 'virtual', --channel = 'x', --bitrate = 500000"),
        (["--modbus", MODBUS_URL, "--bus-option", "port=1"], "--modbus: --bus-option"),
        (["--eds-path", "--modbus", MODBUS_URL], "--modbus: --eds-path"),
        (["--interface", "virtual", "--channel", "x", "--node-id", "3", "--unit-id", "2"],
         "Modbus options need --modbus: --unit-id"),
        (["--eds-path", "--word-order", "little", "--unit-id", "1"],
         "Modbus options need --modbus: --unit-id = 1, --word-order = 'little'"),
        (["--modbus"], "expected one argument"),
        (["--modbus", "udp://127.0.0.1:502"], "tcp://HOST:PORT"),
        (["--modbus", "tcp://127.0.0.1:99999"], "tcp://HOST:PORT"),
        (["--modbus", MODBUS_URL, "--unit-id", "256"], "--unit-id = 256 is invalid; allowed: Modbus unit ids 1..247"),
        (["--modbus", MODBUS_URL, "--unit-id", "248"], "Modbus unit ids 1..247"),  # as --unit-ids: what run can reach
        (["--modbus", MODBUS_URL, "--unit-id", "0"], "Modbus unit ids 1..247"),
        (["--modbus", MODBUS_URL, "--unit-id", "one"], "--unit-id = 'one' is invalid; allowed: Modbus unit ids 1..247"),
        (["--modbus", MODBUS_URL, "--unit-id", "0x100"], "--unit-id = 0x100 is invalid; allowed: Modbus unit ids 1..247"),
        (["--interface", "virtual", "--channel", "x", "--node-id", "0x7", "--unit-id", "0x02"],
         "Modbus options need --modbus: --unit-id = 0x02"),
        (["--modbus", MODBUS_URL, "--word-order", "middle"], "invalid choice"),
        (["--modbus", MODBUS_URL, "--profile", "/nonexistent.toml"], "an existing TOML file"),
        (["--frobnicate"], "unrecognized arguments: --frobnicate"),
        (["--interface", "virtual", "--channel", "x", "--unit-ids", "1,2"], "Modbus options need --modbus: --unit-ids"),
        (["--modbus", MODBUS_URL, "--unit-ids", "1,1"],
         "'1,1' is invalid; allowed: distinct Modbus unit ids 1..247 (1 is given twice)"),
        (["--modbus", MODBUS_URL, "--unit-ids", "1,248"], "Modbus unit ids 1..247"),
        (["--modbus", MODBUS_URL, "--unit-ids", "1,2", "--unit-id", "3"], "--unit-id = 3 is invalid; allowed: --unit-ids"),
        (["--modbus", MODBUS_URL, "--profile", "gantry-3d"], "--unit-ids is missing; allowed: one unit id per axis"),
        (["--modbus", MODBUS_URL, "--modbus", MODBUS_URL, "--profile", "gantry-3d"],
         f"--modbus = '{MODBUS_URL}' is invalid; allowed: one for every axis, or one per axis (3 axes; given twice)"),
        (["--modbus", MODBUS_URL, "--modbus", "tcp://127.0.0.1:47810", "--unit-ids", "1,2,3"],  # as run words it
         "--modbus = 'tcp://127.0.0.1:47810' is invalid; allowed: one for every unit, or one per unit (3 units; 2 given, "
         "this one last)"),
        (["--modbus", MODBUS_URL, "--unit-ids", "1,2", "--profile", "gantry-3d"], "one unit id per axis of the profile (3)"),
    ],
)
def test_modbus_usage_errors_exit_2_with_one_line(argv: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(argv) == 2
    assert message in one_error_line(capsys.readouterr().err)


def test_ids_read_in_hexadecimal_as_haptic_bus_run_reads_them() -> None:
    """``--node-id 0x7`` and ``--unit-id 0x10`` are node 7 and unit 16, as ``run`` and ``sim --unit-ids`` read
    them (the simulator refused them as text); ``07`` is refused by both."""
    canopen = _parse(build_parser(), ["--interface", "virtual", "--channel", "x", "--node-id", "0x7"])
    modbus = _parse(build_parser(), ["--modbus", MODBUS_URL, "--unit-id", "0x10"])
    assert (node_id(canopen), unit_id(modbus)) == (7, 16)
    with pytest.raises(ParameterError, match="--node-id = '07' is invalid"):
        node_id(_parse(build_parser(), ["--interface", "virtual", "--channel", "x", "--node-id", "07"]))


@pytest.mark.parametrize("profile", [[], ["--profile", "gantry-3d"]])
def test_one_unit_id_may_repeat_on_servers_of_their_own(profile: list[str]) -> None:
    """``--unit-ids 1,1,1`` with three ``--modbus`` addresses: unit 1 on each server, as ``haptic-bus run``
    accepts it (and as the simulator does when no unit id is given)."""
    urls = [arg for n in range(3) for arg in ("--modbus", f"tcp://127.0.0.1:{15020 + n}")]
    args = _parse(build_parser(), [*urls, "--unit-ids", "1,1,1", *profile])
    axes, _ = modbus_axes_setup(args)
    assert [unit for unit, _, _ in axes] == [1, 1, 1]


def test_modbus_address_in_use_exits_1_with_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        url = f"tcp://127.0.0.1:{taken.getsockname()[1]}"
        assert main(["--modbus", url]) == 1
    # the system's reason, not pymodbus' "Could not start listen, please check address." (break18)
    assert one_error_line(capsys.readouterr().err) == f"haptic-bus sim: error: cannot serve on {url}: Address already in use\n"


@pytest.mark.parametrize("ids", [["--node-id", str(NODE)], ["--node-ids", f"{NODE - 1},{NODE}"]], ids=["one", "axes"])
def test_a_node_id_already_on_the_bus_exits_1_with_one_line_before_any_boot_up(
        ids: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    """A second ``haptic-bus sim --node-id 11`` on a bus with a node 11 served beside it (break18): every SDO
    answered twice, scan's and run's sessions failing with "Node returned a value for 0x1018:04 instead".
    It now listens first (its heartbeat comes every 100 ms) and refuses, sending nothing."""
    channel = f"sim-cli-dup-{'-'.join(ids)}"
    first = CanopenSimDrive({"interface": "virtual", "channel": channel}, NODE).start()
    bound = threading.Timer(STOP_AFTER, os.kill, (os.getpid(), signal.SIGTERM))  # a sim that serves is stopped (exit 0)
    try:
        with open_bus(interface="virtual", channel=channel) as sniffer:
            bound.start()
            assert main(["--interface", "virtual", "--channel", channel, *ids]) == 1
            frames = [sniffer.recv(0.0) for _ in range(100)]  # bounded: what reached the bus meanwhile
    finally:
        bound.cancel()
        first.stop()
    line = one_error_line(capsys.readouterr().err)
    assert line == (f"haptic-bus sim: error: node {NODE} is already on this bus (a frame of it heard: a drive or "
                    "another simulator with that id); stop it or give another node id\n")
    assert not [f for f in frames if f is not None and f.arbitration_id in (0x700 + NODE - 1, 0x700 + NODE) and
                f.data == bytearray([0])]  # no boot-up of the second: a master cycling node 11 saw no reset


def test_two_simulators_of_one_id_started_at_one_instant_both_refuse(monkeypatch: pytest.MonkeyPatch,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """Two ``haptic-bus sim --node-id 11`` whose listening began within 2 ms of each other heard nothing of each
    other and both served (break18b: 4 of 4 so started on udp_multicast); each now keeps listening past its own
    boot-up, hears the other's beside it, stops and exits 1.  The twin here: a boot-up of node 11 sent the
    instant this one's listening ends, before its own."""
    channel = "sim-cli-twin"
    listened = serve.node_heard

    def twin_listened_too(listener: can.BusABC, node_ids: list[int], seconds: float) -> int | None:
        heard = listened(listener, node_ids, seconds)
        with open_bus(interface="virtual", channel=channel) as twin:
            twin.send(can.Message(arbitration_id=0x700 + NODE, data=[0], is_extended_id=False))
        return heard

    monkeypatch.setattr(serve, "node_heard", twin_listened_too)
    bound = threading.Timer(STOP_AFTER, os.kill, (os.getpid(), signal.SIGTERM))  # a sim that serves is stopped (exit 0)
    try:
        bound.start()
        assert main(["--interface", "virtual", "--channel", channel, "--node-id", str(NODE)]) == 1
    finally:
        bound.cancel()
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.splitlines()[-1] == (
        f"haptic-bus sim: error: node {NODE} booted twice on this bus at once (another simulator with that id started "
        "at the same instant); stop it or give another node id")


def test_a_master_resetting_the_node_as_it_boots_is_no_twin(monkeypatch: pytest.MonkeyPatch,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """A master that heard the boot-up and resets the node (NMT reset communication) within the 0.25 s the
    simulator still listens gets a second boot-up of it: that is no twin (the plugin's rig did so, and the
    simulator refused, every SDO unanswered).  It serves, and SIGTERM ends it, exit 0."""
    channel = "sim-cli-reset"
    listened = serve.node_heard

    def reset_as_it_boots(listener: can.BusABC, node_ids: list[int], seconds: float) -> int | None:
        heard = listened(listener, node_ids, seconds)

        def reset() -> None:
            with open_bus(interface="virtual", channel=channel) as master:
                master.send(can.Message(arbitration_id=0, data=[0x82, NODE], is_extended_id=False))

        threading.Timer(0.05, reset).start()  # after its boot-up, within the listening after it
        os.kill(os.getpid(), signal.SIGTERM)  # kept by its stop signals: served, then stopped
        return heard

    monkeypatch.setattr(serve, "node_heard", reset_as_it_boots)
    with open_bus(interface="virtual", channel=channel) as sniffer:
        assert main(["--interface", "virtual", "--channel", channel, "--node-id", str(NODE)]) == 0
        frames = [sniffer.recv(0.0) for _ in range(100)]  # bounded: what reached the bus meanwhile
    boot_ups = [f for f in frames if f is not None and f.arbitration_id == 0x700 + NODE and f.data == bytearray([0])]
    assert len(boot_ups) == 2 and "error" not in capsys.readouterr().err


def test_a_program_calling_main_keeps_its_logging(capsys: pytest.CaptureFixture[str]) -> None:
    """The simulator logs on stderr while it serves (its root handler, the bus library at WARNING); a program
    that called its main has its own handlers and levels back when it returns (here from an address in use)."""
    import logging

    root, own = logging.getLogger(), logging.NullHandler()
    before = root.handlers[:], root.level, logging.getLogger("pymodbus").level
    root.addHandler(own)
    try:
        with socket.socket() as taken:
            taken.bind(("127.0.0.1", 0))
            taken.listen()
            assert main(["--modbus", f"tcp://127.0.0.1:{taken.getsockname()[1]}"]) == 1
        assert (root.handlers, root.level, logging.getLogger("pymodbus").level) == ([*before[0], own], *before[1:])
    finally:
        root.removeHandler(own)
    capsys.readouterr()


def test_python_m_sim_drive_refuses_mixed_options_without_traceback(capsys: pytest.CaptureFixture[str]) -> None:
    """The refusal through ``python -m sim_drive`` (its ``__main__`` passes main's status to the
    shell); the help is argparse's output in this process (the same ``main``, no second interpreter)."""
    refused = subprocess.run([sys.executable, "-m", "sim_drive", "--modbus", MODBUS_URL, "--node-id", "3"], cwd=REPO,
                             capture_output=True, text=True, timeout=60)
    assert refused.returncode == 2 and refused.stdout == ""
    assert "--modbus: --node-id" in one_error_line(refused.stderr)
    assert main(["--modbus", "--help"]) == 0
    out, err = capsys.readouterr()
    assert "--unit-id" in out and err == ""


def test_profile_tables(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "p.toml"
    path.write_text(
        '[device]\nmass = 0.8\nfriction = 2.0\nfriction_source = "guide"\nrated_torque = 0.5\nmax_torque_permille = 1500\n'
        '[loop]\nperiod = 0.002\ntiming = "ideal"\n'
        '[operator_model]\nmodel = "hand"\nstiffness = 250.0\ndamping = 3.0\n'
    )
    axis, operator = read_simulated_device(path).one_axis()
    parameters = axis.parameters
    assert (parameters.mass, parameters.friction, parameters.rated_torque_mnm, parameters.max_torque_permille) == (
        0.8, 2.0, 500, 1500)
    assert parameters.period == 0.002 and axis.timing is Timing.IDEAL
    assert operator == HandModel(250.0, 3.0)
    path.write_text(path.read_text() + '[[scene.objects]]\nkind = "wall"\n')  # the controller's table, checked alike
    with pytest.raises(ParameterError, match=r"scene\.objects\[0\]\.name is missing; allowed: "):
        read_simulated_device(path)
    path.write_text("[device]\nm = 1.0\n")
    with pytest.raises(ParameterError, match=r"device\.m"):
        read_simulated_device(path)
    path.write_text("[device\n")
    with pytest.raises(ParameterError, match="valid TOML"):
        read_simulated_device(path)


def test_every_shipped_profile_reads_as_a_drive() -> None:
    for name, timing in (("seed-ideal", Timing.IDEAL), ("cia402-handle", Timing.CIA402), ("multi-object", Timing.CIA402)):
        (axis,) = read_simulated_device(name).axes
        assert axis.parameters.period == 1e-3 and axis.timing is timing


@pytest.mark.parametrize(
    "sig, twice", [(signal.SIGTERM, False), (signal.SIGINT, False), (signal.SIGTERM, True)],
    ids=["SIGTERM", "SIGINT", "SIGTERM-twice"],
)
def test_signal_stops_cleanly_and_state_changes_are_logged(
    sig: signal.Signals, twice: bool, multicast: tuple[str, int], sim_process, frames
) -> None:
    group, port = multicast
    with open_bus(interface="udp_multicast", channel=group, port=port) as master:
        process = sim_process("--interface", "udp_multicast", "--channel", group, "--node-id", str(NODE),
                              "--bus-option", f"port={port}", "--log-wall-clock", "--bitrate", "1000000")
        try:
            assert frames.recv_id(master, 0x700 + NODE, timeout=BOOT_WAIT) is not None, "no boot-up/heartbeat"
            frames.send(master, 0x000, [0x01, NODE])
            for command in (Command.SHUTDOWN, Command.SWITCH_ON):
                frames.send(master, 0x600 + NODE, struct.pack("<BHBH2x", 0x2B, 0x6040, 0, command.word))
                assert frames.recv_id(master, 0x580 + NODE) is not None
            for _ in range(2):  # the second SYNC closes a cycle for the bus-load report
                frames.send(master, 0x080)
                assert frames.recv_id(master, 0x180 + NODE) is not None
        finally:
            if twice:
                process.process.send_signal(sig)
            status, log = process.stop(sig)
    assert status == 0, log
    transitions = re.findall(r"^\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3} node 11: (.+) \(transition (\d+)\) at t = ", log, re.M)
    assert transitions == [("SWITCH ON DISABLED -> READY TO SWITCH ON", "2"), ("READY TO SWITCH ON -> SWITCHED ON", "3")], log
    assert "stopped after 2 SYNCs" in log
    assert re.search(r"bus load \d+\.\d % at 1000000 bit/s, worst cycle \d+\.\d us", log), log

