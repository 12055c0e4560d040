"""``haptic-bus scan``: real simulated drives on python-can's ``virtual`` bus and on the lock-step
bus (with ``haptic-bus run``'s runner and its controller node cycling), and the real pymodbus
simulated server on 127.0.0.1 (a scan over ``udp_multicast``: ``test_cli_small_things.py``).
Expected values are read from the simulator's EDS and objects, never written down twice."""

from __future__ import annotations

import json
import re
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import can
import canopen
import pytest

from drives.canopen.scan import scan_canopen
from drives.errors import ParameterError
from drives.modbus.scan import scan_modbus
from haptic_bus.app.cli import main
from haptic_bus.app.profiles import load_profile
from haptic_bus.app.run_options import exit_status
from haptic_bus.app.runner import RunOptions, RunResult, run_canopen
from haptic_bus.node.controller_node import controller_dictionary
from haptic_bus.testing.buses import unique_name
from sim_drive.canopen.slave import CanopenSimDrive
from sim_drive.device import SUPPORTED_DRIVE_MODES
from sim_drive.eds import eds_path
from sim_drive.modbus.server import ModbusSimServer
from tests.raw_bus import queued

STATE_KEYS = {"statusword", "cia402_state", "error_code", "error_code_text"}
CANOPEN_KEYS = {"protocol", "node_id", "device_type", "device_profile", "device_kind", "vendor_id", "product_code", "revision",
                "serial", "nmt_state", "boot_up_seen", "supported_drive_modes", "cst_supported", "cia402", "notes", *STATE_KEYS}
MODBUS_KEYS = {"protocol", "unit_id", "our_map", "word_order", "map_identity", "supported_drive_modes", "cst_supported",
               "cia402", "device_identification", "notes", *STATE_KEYS}
# A scan's time bound is timeout + 8 * answer_timeout (plus opening and closing the bus); a
# loaded 2-core machine may stall a thread for a few hundred ms, so elapsed times are held to
# several times the bound, never to the bound itself.
SLACK = 5.0
START_WAIT = 30.0  # s: the longest the controller node may take to answer (commissioning first)
PROBE_WAIT = 10.0  # s: a bound on a scan's start (a thread, a bus opened), not a pace
RUN_STOP_WAIT = 60.0  # s: the longest a run asked to stop may take to end (its folder written)


def scan_cli(*argv: str) -> int:
    """``haptic-bus scan ARGV`` in this process; its exit status (argparse's own exit included)."""
    try:
        return main(["scan", *argv])
    except SystemExit as exit_:
        return int(exit_.code or 0)


def identity_of(dictionary: canopen.ObjectDictionary) -> dict[str, int]:
    """0x1000 and 0x1018:01..04 as an object dictionary (EDS) holds them."""
    def value(index: int, subindex: int) -> int:
        variable = dictionary.get_variable(index, subindex)
        assert variable is not None and variable.default is not None, f"0x{index:04X}:{subindex:02X} missing"
        return int(variable.default)

    return {"device_type": value(0x1000, 0), "vendor_id": value(0x1018, 1), "product_code": value(0x1018, 2),
            "revision": value(0x1018, 3), "serial": value(0x1018, 4)}


SIM_IDENTITY = identity_of(canopen.import_od(str(eds_path())))


def expect_sim_drive(node: dict[str, Any], node_id: int, nmt_state: str | None, cia402_state: str = "SWITCH ON DISABLED",
                     error_code: int = 0) -> None:
    assert set(node) == CANOPEN_KEYS
    assert {key: node[key] for key in SIM_IDENTITY} == SIM_IDENTITY
    assert (node["node_id"], node["nmt_state"], node["supported_drive_modes"]) == (node_id, nmt_state, SUPPORTED_DRIVE_MODES)
    assert node["device_profile"] == 402 and node["device_kind"] == "CiA-402 servo drive"
    assert node["cst_supported"] is True and node["cia402"] is True and node["notes"] == []
    assert (node["cia402_state"], node["error_code"]) == (cia402_state, error_code)


@pytest.fixture
def second_drive(channel: str, sim: CanopenSimDrive) -> Iterator[CanopenSimDrive]:
    """A second simulated drive, node 9, on the ``sim`` fixture's channel."""
    drive = CanopenSimDrive({"interface": "virtual", "channel": channel}, 9).start()
    yield drive
    drive.stop()


# ----------------------------------------------------------------------------- CANopen, virtual bus
def test_virtual_bus_lists_exactly_the_drives_with_their_eds_identity_nmt_state_and_cst(
        channel: str, master: can.BusABC, second_drive: CanopenSimDrive, frames: Any) -> None:
    frames.nmt_start(master, 9)  # by the test, not by the scan: node 9 OPERATIONAL, node 5 stays PRE-OPERATIONAL
    frames.drain(master)
    nodes = scan_canopen({"interface": "virtual", "channel": channel}, timeout=0.5)  # ~5 heartbeats of 100 ms
    assert [n.node_id for n in nodes] == [5, 9]
    expect_sim_drive(nodes[0].to_dict(), 5, "PRE-OPERATIONAL")
    expect_sim_drive(nodes[1].to_dict(), 9, "OPERATIONAL")
    assert not nodes[0].boot_up_seen and not nodes[1].boot_up_seen  # both booted before the scan


def test_a_drive_with_standard_objects_only_is_listed_the_same(channel: str, master: can.BusABC) -> None:
    drive = CanopenSimDrive({"interface": "virtual", "channel": channel}, 7, od="standard").start()  # no 0x2000-0x5FFF
    try:
        nodes = scan_canopen({"interface": "virtual", "channel": channel}, [7], timeout=0.3)
    finally:
        drive.stop()
    assert len(nodes) == 1
    expect_sim_drive(nodes[0].to_dict(), 7, "PRE-OPERATIONAL")


def test_the_scan_sends_sdo_upload_requests_only(channel: str, master: can.BusABC, second_drive: CanopenSimDrive,
                                                 frames: Any) -> None:
    frames.drain(master)
    scan_canopen({"interface": "virtual", "channel": channel}, timeout=0.3)
    sent = [m for m in queued(master) if not (0x580 < m.arbitration_id < 0x600 or 0x700 < m.arbitration_id < 0x780)]
    assert sent and all(0x600 < m.arbitration_id < 0x680 for m in sent), "only SDO requests: no NMT, SYNC, PDO, EMCY"
    assert all(m.data[0] == 0x40 for m in sent), "initiate upload (read) requests only: no download, no abort"
    per_node = {node: sum(m.arbitration_id == 0x600 + node for m in sent) for node in range(1, 128)}
    # the probe reaches every id once; the two drives are then read 0x1000, 0x1018:01..04, 0x6502, 0x6041, 0x603F
    assert per_node == {node: 9 if node in (5, 9) else 1 for node in range(1, 128)}


def test_a_node_booting_during_the_window_is_listed_and_a_malformed_heartbeat_is_noted(
        channel: str, master: can.BusABC, sim: CanopenSimDrive, frames: Any) -> None:
    result: list[Any] = []
    scanner = threading.Thread(target=lambda: result.append(
        scan_canopen({"interface": "virtual", "channel": channel}, timeout=1.5)))
    late = CanopenSimDrive({"interface": "virtual", "channel": channel}, 12)  # built (its dictionary read) before the window
    scanner.start()
    # inside the 1.5 s window: once the probe's last request (to node 127) is on the bus, the scan listens (a fixed
    # 0.3 s sleep was, beside the suite's load, sometimes before the scan had opened its bus: the frame went unseen)
    assert frames.recv_id(master, 0x600 + 127, PROBE_WAIT) is not None, "the scan sent no probe"
    frames.send(master, 0x705, b"")  # on node 5's heartbeat COB-ID, but no state byte
    late.start()  # boot-up now
    try:
        scanner.join(timeout=10.0)
        assert not scanner.is_alive()
    finally:
        late.stop()
    by_id = {n.node_id: n for n in result[0]}
    assert sorted(by_id) == [5, 12]
    assert by_id[12].boot_up_seen and by_id[12].nmt_state == "PRE-OPERATIONAL"
    assert {key: by_id[12].to_dict()[key] for key in SIM_IDENTITY} == SIM_IDENTITY
    assert by_id[5].notes == ("1 frame(s) on COB-ID 0x705 that are not 1-byte heartbeats",)
    assert by_id[5].nmt_state == "PRE-OPERATIONAL"  # the valid heartbeats still count


def test_an_empty_bus_answers_no_within_the_bound(channel: str, capsys: pytest.CaptureFixture[str]) -> None:
    timeout, answer = 0.3, 0.1
    start = time.monotonic()
    assert scan_canopen({"interface": "virtual", "channel": channel}, timeout=timeout, answer_timeout=answer) == []
    elapsed = time.monotonic() - start
    assert timeout <= elapsed < SLACK * (timeout + 8 * answer)  # the window is listened to in full, and no longer
    start = time.monotonic()
    status = scan_cli("--interface", "virtual", "--channel", channel, "--timeout", str(timeout), "--json")
    elapsed = time.monotonic() - start
    out, err = capsys.readouterr()
    assert status == 1 and json.loads(out) == []
    assert err.strip() == f"haptic-bus scan: no node answered on virtual:{channel} within {timeout:g} s"
    assert timeout <= elapsed < SLACK * (timeout + 8 * answer)


def test_cli_json_and_table(channel: str, second_drive: CanopenSimDrive, capsys: pytest.CaptureFixture[str]) -> None:
    assert scan_cli("--interface", "virtual", "--channel", channel, "--timeout", "0.3", "--json") == 0
    out, err = capsys.readouterr()
    document = json.loads(out)
    assert err == "" and [node["node_id"] for node in document] == [5, 9]
    for node in document:
        expect_sim_drive(node, node["node_id"], "PRE-OPERATIONAL")
    assert scan_cli("--interface", "virtual", "--channel", channel, "--timeout", "0.3", "--node-ids", "9-20") == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2 and lines[0].split()[:3] == ["node", "device", "type"]
    assert lines[1].split() == ["9", f"0x{SIM_IDENTITY['device_type']:08X}", "CiA-402", "servo", "drive",
                                *(f"0x{SIM_IDENTITY[k]:08X}" for k in ("vendor_id", "product_code", "revision", "serial")),
                                "PRE-OPERATIONAL", "yes", "yes", "SWITCH", "ON", "DISABLED", "0x0000"]


def test_a_faulted_drive_shows_fault_and_its_error_code(channel: str, sim: CanopenSimDrive,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    sim.enter_fault(0x8250)  # RPDO timeout, as the drive's own deadline would
    assert scan_cli("--interface", "virtual", "--channel", channel, "--timeout", "0.3", "--json") == 0
    (node,) = json.loads(capsys.readouterr().out)
    expect_sim_drive(node, 5, "PRE-OPERATIONAL", "FAULT", 0x8250)
    assert node["statusword"] == sim.drive.statusword and node["error_code_text"] == "RPDO timeout"
    assert scan_cli("--interface", "virtual", "--channel", channel, "--timeout", "0.3") == 0
    assert capsys.readouterr().out.splitlines()[1].split()[-2:] == ["FAULT", "0x8250"]


@pytest.mark.parametrize("argv", [
    ["--node-ids", "0-5"],
    ["--node-ids", "5-128"],
    ["--node-ids", "9-5"],
    ["--node-ids", "five"],
    ["--timeout", "0"],
    ["--timeout", "nan"],
    ["--answer-timeout", "-1"],
    ["--unit-ids", "1"],  # a Modbus option without --modbus
])
def test_invalid_canopen_arguments_exit_2_before_the_bus_is_touched(
        argv: list[str], channel: str, master: can.BusABC, capsys: pytest.CaptureFixture[str]) -> None:
    assert scan_cli("--interface", "virtual", "--channel", channel, *argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and ("invalid" in err or "Modbus option" in err), err
    assert master.recv(0.05) is None  # not one frame: the bus was never opened


@pytest.mark.parametrize("value", [0, -1, 3600.5, float("nan"), float("inf"), True, "1"])
@pytest.mark.parametrize("keyword", ["timeout", "answer_timeout"])
def test_a_scan_s_time_budget_is_refused_in_the_command_line_s_words(
        keyword: str, value: object, channel: str, master: can.BusABC, capsys: pytest.CaptureFixture[str]) -> None:
    """Both scans check their times with the one range check (drives.ranges.real_in_range): refused in the
    words ``haptic-bus scan --timeout`` says (they said "a time in (0, 3600] s"), before a bus is opened or a
    server connected; 3600 s, the bound, is kept."""
    allowed = "a finite real in (0, 3600] s"
    scans = (lambda: scan_canopen({"interface": "virtual", "channel": channel}, **{keyword: value}),
             lambda: scan_modbus("tcp://127.0.0.1:1", **{keyword: value}))
    for scan in scans:
        with pytest.raises(ParameterError) as refused:
            scan()
        assert str(refused.value) == f"scan: {keyword.replace('_', ' ')} = {value!r} is invalid; allowed: {allowed}"
    assert master.recv(0.05) is None  # not one frame: the bus was never opened
    if keyword == "timeout" and value == 0:  # the command line's refusal: the same words
        assert scan_cli("--interface", "virtual", "--channel", channel, "--timeout", "0") == 2
        said = capsys.readouterr().err
        assert said == f"haptic-bus scan: error: --timeout = 0 is invalid; allowed: {allowed}\n"


@pytest.mark.parametrize("argv", [
    ["--modbus", "tcp://127.0.0.1"],  # no port
    ["--modbus", "udp://127.0.0.1:{port}"],
    ["--modbus", "tcp://127.0.0.1:{port}", "--unit-ids", "0"],
    ["--modbus", "tcp://127.0.0.1:{port}", "--unit-ids", "1-248"],
    ["--modbus", "tcp://127.0.0.1:{port}", "--interface", "virtual"],
    ["--modbus", "tcp://127.0.0.1:{port}", "--node-ids", "5"],
])
def test_invalid_modbus_arguments_exit_2_before_connecting(argv: list[str], free_port: int,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as listener:
        listener.bind(("127.0.0.1", free_port))
        listener.listen()
        listener.settimeout(0.05)
        assert scan_cli(*(a.format(port=free_port) for a in argv)) == 2
        assert capsys.readouterr().err.count("\n") == 1
        with pytest.raises(TimeoutError):
            listener.accept()  # nobody connected


# ----------------------------------------------------------------------------- CANopen, a running controller
def test_two_drives_and_a_running_controller_undisturbed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Two drives and ``haptic-bus run``'s runner (controller node 42) cycling in a thread, all in this
    process on the lock-step bus: the scan lists the three and the run cycles on until it is stopped."""
    bus = {"interface": "lockstep", "channel": unique_name("scan")}
    drives = [CanopenSimDrive(bus, node).start() for node in (5, 9)]
    options = RunOptions(600.0, pacing="virtual", out_dir=tmp_path, live=False, plots=False)
    ended: list[RunResult] = []
    run = threading.Thread(target=lambda: ended.append(run_canopen(load_profile("seed-ideal"), bus, 5, options, 42)),
                           daemon=True)
    run.start()
    try:
        deadline = time.monotonic() + START_WAIT  # the controller node answers once the drive is commissioned
        while not scan_canopen(bus, [42], timeout=0.2, answer_timeout=0.5) and time.monotonic() < deadline:
            assert run.is_alive(), ended
        capsys.readouterr()
        # a 1 s window: 10 of the drives' heartbeats (0x1017: 100 ms), 50 of the controller's (20 ms), the NMT states
        # the scan reports, beside stalls of a few hundred ms; the run cycles at full speed all the while (2 s did)
        assert scan_cli("--interface", "lockstep", "--channel", bus["channel"], "--timeout", "1", "--answer-timeout", "0.5",
                        "--json") == 0
        document = {node["node_id"]: node for node in json.loads(capsys.readouterr().out)}
        assert run.is_alive(), "the scan must not disturb the running loop"
        assert sorted(document) == [5, 9, 42]
        expect_sim_drive(document[5], 5, "OPERATIONAL", "OPERATION ENABLED")  # the run started it and enabled it
        expect_sim_drive(document[9], 9, "PRE-OPERATIONAL")
        controller = document[42]
        assert {key: controller[key] for key in SIM_IDENTITY} == identity_of(controller_dictionary([]))
        assert controller["nmt_state"] == "OPERATIONAL" and controller["device_kind"] == "no device profile"
        assert controller["cia402"] is False and controller["cst_supported"] is None and controller["notes"] == []
    finally:
        options.stop.event.set()  # as SIGTERM does haptic-bus run
        run.join(timeout=RUN_STOP_WAIT)
        for drive in drives:
            drive.stop()
    assert not run.is_alive() and [result.exit_reason for result in ended] == ["stopped"]
    assert exit_status("stopped") == 0


# ----------------------------------------------------------------------------- Modbus TCP
@pytest.mark.parametrize("word_order", ["big", "little"])
def test_modbus_finds_the_simulated_unit_only(word_order: str) -> None:
    with ModbusSimServer(port=0, unit_id=3, word_order=word_order) as server:
        scan = scan_modbus(server.url, range(1, 11))
    assert scan.unprobed == [] and [u.unit_id for u in scan.units] == [3]  # the others answer 0x0B: nobody there
    unit = scan.units[0].to_dict()
    assert set(unit) == MODBUS_KEYS
    assert unit["our_map"] is True and unit["word_order"] == word_order and unit["cia402"] is True
    assert unit["supported_drive_modes"] == SUPPORTED_DRIVE_MODES and unit["cst_supported"] is True
    assert (unit["cia402_state"], unit["statusword"], unit["error_code"]) == ("SWITCH ON DISABLED", 0x0240, 0)
    # pymodbus answers FC43/14 with no objects: the simulator configures no device identification
    assert unit["device_identification"] == {} and unit["notes"] == []


def test_modbus_a_faulted_unit_shows_fault_and_its_error_code(capsys: pytest.CaptureFixture[str]) -> None:
    with ModbusSimServer(port=0, unit_id=2) as server:
        server.drive.fault(0x8130)  # the watchdog's code
        assert scan_cli("--modbus", server.url, "--unit-ids", "1-3", "--json") == 0
        (unit,) = json.loads(capsys.readouterr().out)
        assert scan_cli("--modbus", server.url, "--unit-ids", "2") == 0
        row = capsys.readouterr().out.splitlines()[1].split()
    assert (unit["unit_id"], unit["cia402_state"], unit["error_code"]) == (2, "FAULT", 0x8130)
    assert unit["error_code_text"] == "Life guard error or heartbeat error" and unit["notes"] == []
    assert row[-5:] == ["FAULT", "0x8130", "answered,", "no", "objects"], row


def test_modbus_exception_means_present_but_not_our_map_and_a_drop_is_reconnected() -> None:
    with ModbusSimServer(port=0, unit_id=3) as server:
        server.faults.exception(0x02)  # unit 3's map identity read: illegal data address
        first = scan_modbus(server.url, range(1, 6))
        server.faults.drop()  # unit 3's first request: the connection is cut
        second = scan_modbus(server.url, range(1, 6))
    (unit,) = first.units
    assert (unit.unit_id, unit.our_map, unit.cia402, unit.cst_supported, unit.map_identity) == (3, False, False, None, None)
    assert unit.notes == ("unit 3: map identity: exception 0x02 ILLEGAL DATA ADDRESS",)
    assert [(u.unit_id, u.our_map) for u in second.units] == [(3, True)]


def test_modbus_a_unit_slower_than_the_answer_timeout_is_skipped_and_the_sweep_goes_on() -> None:
    with ModbusSimServer(port=0, unit_id=3) as server:
        server.faults.delay(0.3)  # unit 3's first request answered 0.3 s late
        slow = scan_modbus(server.url, range(1, 6), answer_timeout=0.1)
        server.faults.delay(0.3)
        patient = scan_modbus(server.url, range(1, 6), answer_timeout=1.0)
    assert slow.units == [] and slow.unprobed == []
    assert [u.unit_id for u in patient.units] == [3]


def test_modbus_cli_json_unprobed_and_unreachable(refusing_port: int, capsys: pytest.CaptureFixture[str]) -> None:
    with ModbusSimServer(port=0) as server:
        assert scan_cli("--modbus", server.url, "--unit-ids", "1-3", "--json") == 0
        out, err = capsys.readouterr()
        assert err == "" and [u["unit_id"] for u in json.loads(out)] == [1]
        assert set(json.loads(out)[0]) == MODBUS_KEYS
        assert scan_cli("--modbus", server.url, "--unit-ids", "200-247", "--timeout", "1e-9") == 1
        err = capsys.readouterr().err
        assert re.search(r"unit ids [\d,-]*247 not probed: --timeout 1e-09 s spent", err), err
        assert "no node answered at " + server.url in err
    assert scan_cli("--modbus", f"tcp://127.0.0.1:{refusing_port}") == 1  # nothing listens there
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "drive error" in err and "cannot connect" in err
