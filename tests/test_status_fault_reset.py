"""``haptic-bus status`` and ``haptic-bus fault-reset`` (and ``run --reset-fault``) against the
simulated drive: a real CANopen slave on python-can's ``virtual`` bus, a real pymodbus server
on 127.0.0.1, both in this process, driven through the real command line.  The frames a command
sends are sniffed on the bus; what it reports is compared with the simulated drive's own state.
"""

from __future__ import annotations

import json
import socket
import struct
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import can
import pytest
from canopen import objectdictionary as od
from canopen.objectdictionary import import_od

from drives.cia402 import State
from sim_drive.canopen.slave import CanopenSimDrive
from sim_drive.device import SimulatedDrive
from sim_drive.eds import eds_path
from sim_drive.modbus.server import ModbusSimServer
from tests.run_rig import CliResult, profile_variant, read_run, run_cli, simulated_drive, wait_until

NODE = 5
# These runs are about the fault reset, not the heartbeat chain: a lock-step run on a loaded
# 2-core machine (load average 9 measured) lets the 20 ms heartbeat thread miss the default 60 ms
# consumer time, and the drive then faults with EMCY 0x8130 mid-run.
PATIENT_CONSUMER = "[safety]\nconsumer_ms = 2000\n"
SDO_REQUEST = 0x600 + NODE
UPLOAD_REQUEST = 0x40  # SDO initiate upload (a read)
DOWNLOAD_2_BYTES = 0x2B  # SDO expedited download of 2 bytes (a controlword write)


def bus_args(channel: str) -> list[str]:
    return ["--interface", "virtual", "--channel", channel]


def sent_by_tool(bus: can.BusABC) -> list[can.Message]:
    """Every frame queued on ``bus`` that the simulated drive did not send (its SDO answers,
    heartbeats and EMCYs are left out)."""
    frames = []
    for _ in range(100_000):
        message = bus.recv(0.0)
        if message is None:
            break
        if message.arbitration_id not in (0x580 + NODE, 0x700 + NODE, 0x80 + NODE):
            frames.append(message)
    return frames


def controlword_writes(frames: list[can.Message]) -> list[int]:
    """The values the frames wrote to 0x6040 by expedited SDO download."""
    return [struct.unpack_from("<H", m.data, 4)[0] for m in frames if m.arbitration_id == SDO_REQUEST
            and m.data[0] == DOWNLOAD_2_BYTES and struct.unpack_from("<HB", m.data, 1) == (0x6040, 0)]


def refault_on_reset(drive: SimulatedDrive, code: int) -> None:
    """A drive whose cause persists: it faults again with ``code`` as soon as a reset takes it out of FAULT."""
    drive.state_listeners.append(lambda old, new, number: drive.fault(code) if old is State.FAULT else None)


def one_line(result: CliResult) -> str:
    assert len(result.err_lines) == 1 and "Traceback" not in result.err, result.err
    return result.err_lines[0]


# ----------------------------------------------------------------------------- CANopen: status
def test_status_of_a_faulted_drive_reads_only_and_names_the_error(channel: str, master: can.BusABC, sim: CanopenSimDrive,
                                                                  frames: Any, capsys: pytest.CaptureFixture[str]) -> None:
    frames.nmt_start(master)
    # its log line is written by then, not into the command's stderr
    assert wait_until(lambda: sim.nmt_state == "OPERATIONAL", 5.0)
    sim.enter_fault(0x8250)  # what the drive's RPDO deadline does
    frames.drain(master)
    result = run_cli(capsys, "status", *bus_args(channel), "--node-id", "5", "--listen", "0.3", "--json")
    assert result.code == 1  # a drive in FAULT
    status = json.loads(result.out)
    readings = status["readings"]
    assert (status["cia402_state"], status["faulted"], status["nmt_state"]) == ("FAULT", True, "OPERATIONAL")
    assert status["heartbeats"] >= 1 and status["sync_frames"] == 0 and status["listen_s"] >= 0.3
    assert readings["cia402_state"]["value"] == sim.drive.statusword and readings["cia402_state"]["source"] == "0x6041"
    assert readings["error_code"] == {"source": "0x603F", "value": 0x8250, "text": "0x8250 RPDO timeout", "missing": None}
    assert readings["error_register"]["value"] == 0x11 and readings["error_register"]["text"] == "0x11: generic, communication"
    assert readings["mode_of_operation"]["value"] == 0 and readings["abort_connection_option"]["text"] == "1: fault"
    assert readings["position"]["value"] == sim.drive.position_counts
    assert readings["velocity"]["value"] == sim.drive.velocity_counts
    assert readings["heartbeat_consumer"]["details"] == [{"node_id": 0, "time_ms": 0}]
    assert readings["rpdo1_deadline"]["value"] == 0 and readings["rpdo1_deadline"]["text"] == "0: off"
    assert readings["error_history"]["missing"] == "absent"  # the simulated drive has no 0x1003
    assert "0x06020000" in readings["error_history"]["text"]
    line = one_line(result)
    assert "FAULT (error code 0x8250 RPDO timeout)" in line
    assert line.endswith(f"then: haptic-bus fault-reset --interface virtual --channel {channel} --node-id 5")
    sent = sent_by_tool(master)
    assert sent and all(m.arbitration_id == SDO_REQUEST and m.data[0] == UPLOAD_REQUEST for m in sent), sent
    assert sim.nmt_state == "OPERATIONAL" and sim.drive.state is State.FAULT  # nothing changed


def test_status_table_and_the_emcys_heard_while_listening(channel: str, master: can.BusABC, sim: CanopenSimDrive,
                                                          frames: Any, capsys: pytest.CaptureFixture[str]) -> None:
    def fault_once_status_asks() -> None:  # status listens from before its first request on
        if frames.recv_id(master, SDO_REQUEST, timeout=20.0) is not None:
            sim.enter_fault(0x8130)

    frames.drain(master)
    injector = threading.Thread(target=fault_once_status_asks)
    injector.start()
    try:
        # 0.4 s: the EMCY goes out as the first request arrives, on a bus in this process (1 s waited 0.6 s more)
        result = run_cli(capsys, "status", *bus_args(channel), "--node-id", "5", "--listen", "0.4")
    finally:
        injector.join(timeout=25.0)
    lines = result.out.splitlines()
    assert lines[0].startswith("CANopen node 5: NMT PRE-OPERATIONAL, ")
    assert any(line.split()[:2] == ["error", "register"] for line in lines)
    (emcy,) = [line for line in lines if line.split()[:1] == ["EMCY"]]
    assert emcy.split()[1:7] == ["0x8130", "Life", "guard", "error", "or", "heartbeat"]
    assert "error register 0x11" in emcy
    result = run_cli(capsys, "status", *bus_args(channel), "--node-id", "5", "--listen", "0.2", "--json")
    assert result.code == 1 and json.loads(result.out)["emcy"] == []  # heard only while listening


def _dictionary(*, without: tuple[int, ...] = (), rpdo_subs: int = 5, errors: tuple[int, ...] = ()) -> od.ObjectDictionary:
    """The shipped EDS less ``without``, with 0x1400..0x1403 up to ``rpdo_subs``, and a 0x1003 holding ``errors``."""
    dictionary = import_od(str(eds_path()), NODE)
    for index in without:
        dictionary.names.pop(dictionary.indices.pop(index).name, None)
    for com in range(0x1400, 0x1404):
        record = dictionary[com]
        for sub in [s for s in record.subindices if s > rpdo_subs]:
            record.names.pop(record.subindices.pop(sub).name, None)
        record[0].default = rpdo_subs
    if errors:
        field = od.ODArray("Pre-defined error field", 0x1003)
        for sub, value in enumerate((len(errors), *errors)):
            variable = od.ODVariable("Number of errors" if sub == 0 else f"Standard error field {sub}", 0x1003, sub)
            variable.data_type = od.UNSIGNED8 if sub == 0 else od.UNSIGNED32
            variable.access_type, variable.default = "ro", value
            field.add_member(variable)
        dictionary.add_object(field)
    return dictionary


def test_status_of_a_drive_lacking_the_safety_objects_says_absent(channel: str, master: can.BusABC,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    dictionary = _dictionary(without=(0x1016, 0x6007), rpdo_subs=3)  # as the vendor EDS of issue 20
    with CanopenSimDrive({"interface": "virtual", "channel": channel}, NODE, dictionary=dictionary):
        result = run_cli(capsys, "status", *bus_args(channel), "--node-id", "5", "--listen", "0.2", "--json")
    assert result.code == 0 and result.err == ""
    readings = json.loads(result.out)["readings"]
    for key in ("heartbeat_consumer", "abort_connection_option"):
        assert readings[key]["missing"] == "absent" and readings[key]["value"] is None
        assert readings[key]["text"] == "SDO abort 0x06020000 Object does not exist in the object dictionary"
    assert readings["rpdo1_deadline"] == {"source": "0x1400:05", "value": None, "text": "0x1400 has sub-indices 0..3 only",
                                          "missing": "absent"}
    asked = [struct.unpack_from("<HB", m.data, 1) for m in sent_by_tool(master)]
    assert (0x1400, 0) in asked and (0x1400, 5) not in asked  # known absent from 0x1400:00: never asked


def test_status_decodes_the_pre_defined_error_field_where_the_drive_has_one(channel: str,
                                                                            capsys: pytest.CaptureFixture[str]) -> None:
    dictionary = _dictionary(errors=(0x0005_8250, 0x8130))  # newest first; 5 = manufacturer-specific info
    with CanopenSimDrive({"interface": "virtual", "channel": channel}, NODE, dictionary=dictionary):
        result = run_cli(capsys, "status", *bus_args(channel), "--node-id", "5", "--listen", "0.2", "--json")
    history = json.loads(result.out)["readings"]["error_history"]
    assert history["value"] == 2 and history["missing"] is None
    assert history["details"] == [{"code": 0x8250, "text": "RPDO timeout", "manufacturer_info": 5},
                                  {"code": 0x8130, "text": "Life guard error or heartbeat error", "manufacturer_info": 0}]
    assert history["text"].startswith("2 error(s), newest first: 0x8250 RPDO timeout, 0x8130")


def test_status_of_a_node_nobody_answers_for_is_one_line(channel: str, sim: CanopenSimDrive,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    # 0.5 s: five of node 5's heartbeats (every 100 ms) are heard meanwhile, where the assertion needs one
    result = run_cli(capsys, "status", *bus_args(channel), "--node-id", "9", "--listen", "0.3", "--timeout", "0.5")
    assert result.code == 1 and result.out == ""
    line = one_line(result)
    assert line.startswith("haptic-bus status: drive error: CANopen node 9: no SDO answer reading 0x6041:00 (Statusword)")
    assert "no heartbeat of node 9" in line and "heartbeats heard from node(s) 5" in line


def test_status_of_a_stopped_node_says_it_serves_no_sdo(channel: str, master: can.BusABC, sim: CanopenSimDrive, frames: Any,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    frames.send(master, 0x000, [0x02, NODE])  # NMT stop
    time.sleep(0.25)  # a heartbeat (every 100 ms) in STOPPED
    # 0.5 s: a STOPPED node never answers, so the timeout is waited in full; its heartbeat is heard in 0.1 s
    result = run_cli(capsys, "status", *bus_args(channel), "--node-id", "5", "--timeout", "0.5")
    assert result.code == 1
    assert "its heartbeat says STOPPED: a STOPPED node serves no SDO" in one_line(result)
    assert sim.nmt_state == "STOPPED"


# ----------------------------------------------------------------------------- CANopen: fault-reset
def test_fault_reset_clears_a_fault_whose_cause_is_gone(channel: str, master: can.BusABC, sim: CanopenSimDrive, frames: Any,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    sim.enter_fault(0x8250)
    frames.drain(master)
    # --wait 5 (five times the default): the simulated drive answers from a thread of this process, and beside
    # three other suites (load average 4-7) it left FAULT 4.12 s after the edge; the command stops waiting once it has
    result = run_cli(capsys, "fault-reset", *bus_args(channel), "--node-id", "5", "--wait", "5")
    assert result.code == 0 and result.err == ""
    assert result.out.startswith("CANopen node 5: FAULT (error code 0x8250 RPDO timeout) reset: now SWITCH ON DISABLED")
    assert sim.drive.state is State.SWITCH_ON_DISABLED and sim.drive.error_code == 0
    sent = sent_by_tool(master)
    assert all(m.arbitration_id == SDO_REQUEST for m in sent)
    assert controlword_writes(sent) == [0x0000, 0x0080, 0x0000]  # bit 7 low, the rising edge, low again


def test_fault_reset_of_a_drive_not_in_fault_writes_nothing(channel: str, master: can.BusABC, sim: CanopenSimDrive,
                                                            frames: Any, capsys: pytest.CaptureFixture[str]) -> None:
    frames.drain(master)
    result = run_cli(capsys, "fault-reset", *bus_args(channel), "--node-id", "5", "--json")
    assert result.code == 0
    outcome = json.loads(result.out)
    assert (outcome["state_before"], outcome["reset_sent"], outcome["cleared"]) == ("SWITCH ON DISABLED", False, True)
    assert all(m.data[0] == UPLOAD_REQUEST for m in sent_by_tool(master))


@pytest.mark.parametrize("transport", ["canopen", "modbus"])
def test_fault_reset_says_when_the_cause_persists(transport: str, channel: str, capsys: pytest.CaptureFixture[str]) -> None:
    with _drive(transport, channel) as (drive, args):
        drive.fault(0x8250)
        refault_on_reset(drive, 0x8250)
        result = run_cli(capsys, "fault-reset", *args, "--wait", "0.2", "--json")
        assert drive.state is State.FAULT
    assert result.code == 1
    outcome = json.loads(result.out)
    assert (outcome["reset_sent"], outcome["cleared"], outcome["state_after"]) == (True, False, "FAULT")
    assert outcome["error_code_after"] == 0x8250
    line = one_line(result)
    assert "the cause persists, the drive is still in FAULT" in line and "error code 0x8250 RPDO timeout" in line


def test_fault_reset_is_refused_while_a_master_cycles(channel: str, master: can.BusABC, sim: CanopenSimDrive,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    sim.enter_fault(0x8250)
    with can.Bus(interface="virtual", channel=channel) as other_master:
        sync = other_master.send_periodic(can.Message(arbitration_id=0x80, data=b"", is_extended_id=False), 0.005)
        try:
            result = run_cli(capsys, "fault-reset", *bus_args(channel), "--node-id", "5")
        finally:
            sync.stop()
    assert result.code == 1 and "another master is cycling" in one_line(result)
    assert sim.drive.state is State.FAULT
    assert controlword_writes(sent_by_tool(master)) == []


# ----------------------------------------------------------------------------- Modbus
@pytest.fixture
def unit() -> Iterator[ModbusSimServer]:
    with ModbusSimServer(port=0, unit_id=3) as server:
        yield server


def test_modbus_status_and_fault_reset(unit: ModbusSimServer, capsys: pytest.CaptureFixture[str]) -> None:
    unit.drive.fault(0x8130)  # what the communication watchdog does
    args = ["--modbus", unit.url, "--unit-id", "3"]
    result = run_cli(capsys, "status", *args, "--json")
    assert result.code == 1
    status = json.loads(result.out)
    assert (status["protocol"], status["cia402_state"], status["faulted"]) == ("modbus", "FAULT", True)
    assert "nmt_state" not in status and "emcy" not in status  # no NMT, no EMCY on Modbus
    readings = status["readings"]
    assert readings["error_code"]["value"] == 0x8130 and readings["error_code"]["source"] == "register 0x0028"
    assert readings["communication_watchdog"]["value"] == unit.bank.watchdog_ms
    assert readings["abort_connection_option"]["text"] == "1: fault"
    assert one_line(result).endswith(f"then: haptic-bus fault-reset --modbus {unit.url} --unit-id 3")
    result = run_cli(capsys, "fault-reset", *args)
    assert result.code == 0, result.err
    assert result.out.startswith(f"Modbus unit 3 at {unit.url}: FAULT (error code 0x8130 Life guard error or heartbeat "
                                 "error) reset: now SWITCH ON DISABLED")
    assert unit.drive.state is State.SWITCH_ON_DISABLED and unit.drive.controlword == 0
    assert run_cli(capsys, "status", *args).code == 0


def test_modbus_status_of_a_server_not_there_is_one_line(refusing_port: int, capsys: pytest.CaptureFixture[str]) -> None:
    result = run_cli(capsys, "status", "--modbus", f"tcp://127.0.0.1:{refusing_port}", "--timeout", "0.2")
    assert result.code == 1 and "cannot connect within 0.2 s" in one_line(result)


# ----------------------------------------------------------------------------- bad input
INVALID = [
    (["status", "{bus}", "--node-id", "0"], "--node-id = 0 is invalid; allowed: CANopen node ids 1..127"),
    (["status", "{bus}", "--node-id", "128"], "--node-id = 128 is invalid; allowed: CANopen node ids 1..127"),
    (["status", "{bus}"],
     "--node-id is missing; allowed: the drive's node id, one of the CANopen node ids 1..127 (or --modbus URL)"),
    (["status", "{bus}", "--node-id", "5", "--unit-id", "2"], "--unit-id = 2 is invalid; allowed: a Modbus option"),
    (["status", "--modbus", "{url}", "--node-id", "5"], "--node-id = 5 is invalid"),
    (["status", "--modbus", "{url}", "--listen", "1"], "--listen = 1.0 is invalid; allowed: a CANopen option"),
    (["status", "--modbus", "{url}", "--unit-id", "248"],
     "--unit-id = 248 is invalid; allowed: Modbus unit ids 1..247"),
    (["status", "{bus}", "--node-id", "5", "--listen", "0"], "--listen = 0 is invalid"),
    (["status", "{bus}", "--node-id", "5", "--timeout", "nan"], "--timeout = nan is invalid"),
    (["fault-reset", "{bus}", "--node-id", "5", "--wait", "-1"], "--wait = -1 is invalid"),
    (["fault-reset", "{bus}", "--node-id", "5", "--wait", "61"], "allowed: a finite real in (0, 60] s"),
    (["fault-reset", "--modbus", "{url}", "--interface", "virtual"], "--interface = 'virtual' is invalid"),
    (["fault-reset", "--modbus", "tcp://127.0.0.1"], "--modbus = 'tcp://127.0.0.1' is invalid"),
]


@pytest.mark.parametrize("argv, said", INVALID, ids=[" ".join(a) for a, _ in INVALID])
def test_invalid_input_is_exit_2_one_line_nothing_touched(argv: list[str], said: str, channel: str, master: can.BusABC,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    with socket.create_server(("127.0.0.1", 0)) as listener:
        url = f"tcp://127.0.0.1:{listener.getsockname()[1]}"
        args = [part for arg in argv for part in (bus_args(channel) if arg == "{bus}" else [url if arg == "{url}" else arg])]
        result = run_cli(capsys, *args)
        listener.setblocking(False)
        with pytest.raises(BlockingIOError):
            listener.accept()  # no connection
    assert master.recv(0.05) is None  # no frame
    assert result.code == 2 and result.out == ""
    line = one_line(result)
    assert line.startswith(f"haptic-bus {argv[0]}: error: ") and said in line, line


# ----------------------------------------------------------------------------- run
@pytest.mark.parametrize("transport", ["canopen", "modbus"])
def test_run_refuses_a_faulted_drive_naming_the_command_then_resets_it_with_reset_fault(
        transport: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    profile = str(profile_variant(tmp_path, "cia402-handle", "patient", extra=PATIENT_CONSUMER))
    with simulated_drive(transport, profile) as under:
        under.drive.fault(0x8250)
        refused = run_cli(capsys, "run", profile, *under.args, "--virtual-time", "--duration", "0.2", "-q", "--no-plots",
                          "--out", str(tmp_path / "refused"))
        assert not under.was_enabled
        done = run_cli(capsys, "run", profile, *under.args, "--virtual-time", "--duration", "0.2", "-q", "--no-plots",
                       "--out", str(tmp_path / "done"), "--reset-fault")
        faulted = [State.FAULT_REACTION_ACTIVE, State.FAULT]  # the injected fault
        assert under.states[:4] == [*faulted, State.SWITCH_ON_DISABLED, State.READY_TO_SWITCH_ON] and under.was_enabled
    assert refused.code == 1
    line = one_line(refused)
    assert "drive is in FAULT (statusword 0x0208, error code 0x8250 RPDO timeout)" in line
    assert f"then: haptic-bus fault-reset {' '.join(under.args)} (or run with --reset-fault)" in line
    assert "fault_reset()" not in line
    assert done.code == 0, done.err
    (event, *_) = read_run(tmp_path / "done")["events"]
    assert (event["kind"], event["time_s"]) == ("fault reset", 0.0)
    assert event["message"].startswith("before commissioning: ")
    assert "FAULT (error code 0x8250 RPDO timeout) reset" in event["message"]
    assert {k: event["data"][k] for k in ("state_before", "error_code_before", "error_code_before_text", "cleared")} == {
        "state_before": "FAULT", "error_code_before": 0x8250, "error_code_before_text": "RPDO timeout", "cleared": True}


@pytest.mark.parametrize("transport", ["canopen", "modbus"])
def test_a_real_time_run_names_a_faulted_drive_at_set_up_before_pre_flight(
        transport: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Real time: pre-flight would run 500 cycles (and judge the gate) before enabling; a drive
    already in FAULT is said once reached instead, one line, exit 1, pre-flight never run."""
    with simulated_drive(transport, "cia402-handle") as under:
        under.drive.fault(0x8250)
        no_bus_log = ["--no-bus-log"] if transport == "canopen" else []  # a CANopen option (refused beside --modbus)
        result = run_cli(capsys, "run", "cia402-handle", *under.args, "--duration", "0.2", "--no-plots", *no_bus_log,
                         "--out", str(tmp_path))
        assert not under.was_enabled
    assert result.code == 1
    line = one_line(result)
    assert "drive is in FAULT (statusword 0x0208, error code 0x8250 RPDO timeout)" in line
    assert line.endswith(f"then: haptic-bus fault-reset {' '.join(under.args)} (or run with --reset-fault)")
    assert "pre-flight" not in result.out
    document = read_run(tmp_path)
    assert document["exit_reason"] == "drive error" and "preflight" not in document
    # real time: the drive was given the profile's (default) safety settings
    assert document["settings"]["safety"] == {"heartbeat_ms": 20, "consumer_ms": 90, "rpdo_deadline_periods": 30,
                                              "abort_option": 1, "strict": False, "modbus_watchdog_ms": 60}


def test_run_reset_fault_with_a_persisting_cause_is_refused_and_logged(tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    with simulated_drive("canopen", "cia402-handle") as under:
        under.drive.fault(0x8130)
        refault_on_reset(under.drive, 0x8130)
        result = run_cli(capsys, "run", "cia402-handle", *under.args, "--virtual-time", "--duration", "0.2", "-q",
                         "--no-plots", "--out", str(tmp_path), "--reset-fault")
        assert not under.was_enabled
    assert result.code == 1
    assert "--reset-fault: FAULT (error code 0x8130 Life guard error or heartbeat error): the cause persists" in one_line(result)
    document = read_run(tmp_path)
    assert document["exit_reason"] == "drive error"
    (event,) = document["events"]
    assert event["kind"] == "fault reset" and event["data"]["cleared"] is False and event["data"]["error_code_after"] == 0x8130


# ----------------------------------------------------------------------------- helpers
@contextmanager
def _drive(transport: str, channel: str) -> Iterator[tuple[SimulatedDrive, list[str]]]:
    """The simulated drive of ``transport`` in this process: its SimulatedDrive, and the options reaching it."""
    if transport == "canopen":
        with CanopenSimDrive({"interface": "virtual", "channel": channel}, NODE) as slave:
            yield slave.drive, [*bus_args(channel), "--node-id", str(NODE)]
    else:
        with ModbusSimServer(port=0) as server:
            yield server.drive, ["--modbus", server.url]
