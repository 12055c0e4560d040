"""``haptic-bus sdo read|write`` against the simulated drive: a real CANopen slave on python-can's
``virtual`` bus and a real pymodbus server on 127.0.0.1, in this process, through the real
command line.  Expected values come from the simulated drive's objects and its EDS."""

from __future__ import annotations

import json
import socket
from pathlib import Path
from typing import Any

import can
import pytest
from canopen.objectdictionary import import_od

from drives.canopen.sdo_values import TYPES
from drives.cia402 import DataType, ObjectSpec, OperationMode, State
from drives.object_access import object_label, parse_object
from haptic_bus.app.sdo_cli import TYPE_NAMES
from sim_drive.canopen.slave import CanopenSimDrive
from sim_drive.eds import eds_path
from sim_drive.modbus.server import ModbusSimServer
from tests.run_rig import CliResult, run_cli

EDS = str(eds_path())


def sdo(capsys: pytest.CaptureFixture[str], channel: str, *args: str) -> CliResult:
    return run_cli(capsys, "sdo", *args, "--interface", "virtual", "--channel", channel, "--node-id", "5")


def one_line(result: CliResult) -> str:
    assert len(result.err_lines) == 1 and "Traceback" not in result.err and result.out == "", result.err
    return result.err_lines[0]


def test_the_type_names_of_the_command_line_are_the_codecs() -> None:
    assert set(TYPE_NAMES) == set(TYPES)


# ----------------------------------------------------------------------------- CANopen
def test_read_names_objects_from_the_standard_dictionary(channel: str, sim: CanopenSimDrive,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    result = sdo(capsys, channel, "read", "0x6041")
    assert result.code == 0 and result.err == ""
    assert result.out == (f"CANopen node 5: read 0x6041:00 Statusword = {sim.drive.statusword} (0x{sim.drive.statusword:04X}) "
                          "(u16, SDO upload): SWITCH ON DISABLED\n")
    product = import_od(EDS, 5).get_variable(0x1018, 2).default
    result = sdo(capsys, channel, "read", "0x1018:2", "--json")
    assert json.loads(result.out) | {"drive": None} == {
        "drive": None, "object": "0x1018:02", "index": 0x1018, "subindex": 2, "name": "Identity object.Product code",
        "type": "u32", "value": product, "raw": product.to_bytes(4, "little").hex(), "shown": f"{product} (0x{product:08X})",
        "meaning": None, "where": "SDO upload"}
    result = sdo(capsys, channel, "read", "0x1008")
    assert result.out.endswith(f"Manufacturer device name = {import_od(EDS, 5)[0x1008].default!r} (str, SDO upload)\n")


def test_write_then_read_back_in_the_dictionarys_types(channel: str, sim: CanopenSimDrive,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    result = sdo(capsys, channel, "write", "0x6060", "10")
    assert result.code == 0
    assert result.out == "CANopen node 5: wrote 0x6060:00 Modes of operation = 10 (i8, SDO download): cyclic synchronous torque\n"
    assert sim.drive.mode == OperationMode.CYCLIC_SYNCHRONOUS_TORQUE
    assert sdo(capsys, channel, "write", "0x6071", "-5").code == 0 and sim.drive.target_torque == -5
    assert json.loads(sdo(capsys, channel, "read", "0x6071", "--json").out)["value"] == -5
    assert sdo(capsys, channel, "write", "0x6071", "0x7FFF", "--type", "i16").code == 0 and sim.drive.target_torque == 0x7FFF
    assert sim.drive.state is State.SWITCH_ON_DISABLED  # nothing but the objects written


def test_the_drives_eds_names_its_manufacturer_objects(channel: str, sim: CanopenSimDrive,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    per_count = sim.drive.parameters.velocity_per_count
    result = sdo(capsys, channel, "read", "0x2001:1", "--eds", EDS, "--json")
    found = json.loads(result.out)
    assert (found["name"], found["type"], found["value"]) == ("Scaling.Velocity per count (m/s)", "f64", per_count)
    result = sdo(capsys, channel, "read", "0x2001:1", "--json")  # without the EDS: an unknown object, its bytes
    found = json.loads(result.out)
    assert (found["name"], found["type"]) == ("unknown object", "hex")
    assert bytes.fromhex(found["value"]) == bytes.fromhex(found["raw"]) and len(found["raw"]) == 16


def test_the_eds_limits_are_checked_before_the_bus_and_the_drives_own_after(channel: str, master: can.BusABC,
                                                                           sim: CanopenSimDrive, frames: Any,
                                                                           capsys: pytest.CaptureFixture[str]) -> None:
    frames.drain(master)
    result = sdo(capsys, channel, "write", "0x605A", "9", "--eds", EDS)  # the EDS: LowLimit 0, HighLimit 8
    assert result.code == 2 and "VALUE = '9' is invalid; allowed: 0..8 (the object's range in the dictionary)" in one_line(result)
    assert frames.recv_id(master, 0x605, timeout=0.05) is None  # no SDO request (the drive's heartbeats go on)
    result = sdo(capsys, channel, "write", "0x605A", "9")  # the standard dictionary knows no limits: the drive refuses
    assert result.code == 1
    assert one_line(result) == ("haptic-bus sdo: drive error: CANopen node 5: SDO abort writing 0x605A:00 (Quick stop option "
                                "code): 0x06090030 Invalid value for parameter (download only)")


@pytest.mark.parametrize("args, said", [
    (["read", "0x2345"],
     "SDO abort reading 0x2345:00 (unknown object): 0x06020000 Object does not exist in the object dictionary"),
    (["read", "0x6041:1"], "SDO abort reading 0x6041:01 (Statusword): 0x06090011 Sub-index does not exist"),
    (["write", "0x6041", "3"], "SDO abort writing 0x6041:00 (Statusword): 0x06010002 Attempt to write a read only object"),
    (["read", "0x6041", "--type", "u32"],
     "0x6041:00 (Statusword) is 2 byte(s), a u32 has 4: read it with --type hex, or give its type"),
])
def test_a_drive_that_refuses_is_one_line_naming_the_object(args: list[str], said: str, channel: str, sim: CanopenSimDrive,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    result = sdo(capsys, channel, *args)
    assert result.code == 1
    assert one_line(result) == f"haptic-bus sdo: drive error: CANopen node 5: {said}"


def test_no_drive_answering_is_one_line(channel: str, sim: CanopenSimDrive, capsys: pytest.CaptureFixture[str]) -> None:
    result = run_cli(capsys, "sdo", "read", "0x6041", "--interface", "virtual", "--channel", channel, "--node-id", "9",
                     "--timeout", "1")  # ten of node 5's heartbeats meanwhile
    assert result.code == 1
    line = one_line(result)
    assert line.startswith("haptic-bus sdo: drive error: CANopen node 9: no SDO answer reading 0x6041:00 (Statusword) "
                           "within 1 s") and "heartbeats heard from node(s) 5" in line


def test_an_object_label_read_back_names_the_same_object() -> None:
    """Labels print the sub-index in hexadecimal (``0x1400:05``, ``0x1A00:10``); what they print is what
    the commands take: ``0x1A00:10`` read sub-index 10 (0x0A) and ``0x1400:05`` was refused (a decimal
    05) before."""
    for subindex in range(256):
        spec = ObjectSpec(0x1A00, "x", DataType.UNSIGNED8, "ro", subindex=subindex)
        assert parse_object(object_label(spec)) == (0x1A00, subindex)
    assert parse_object("0x1A00:10") == parse_object("0x1A00:0x10") == (0x1A00, 16)
    assert parse_object("0x1018:4") == (0x1018, 4)


INVALID = [
    (["read", "0x10000"], "object = '0x10000' is invalid; allowed: INDEX[:SUB], INDEX 0x0001..0xFFFF (0x-hexadecimal, "
                          "or decimal), SUB 00..FF hexadecimal"),
    (["read", "0"], "object = '0' is invalid"),
    (["read", "six"], "object = 'six' is invalid"),
    (["read", "0x6041:256"], "object = '0x6041:256' is invalid"),
    (["read", "0x6041:"], "object = '0x6041:' is invalid"),
    (["read", "0x6041", "5"], "VALUE = '5' is invalid; allowed: no value with read"),
    (["write", "0x6060"], "VALUE is missing; allowed: the value to write after INDEX[:SUB]"),
    (["write", "0x6060", "128"], "VALUE = '128' is invalid; allowed: i8: an integer -128..127"),
    (["write", "0x6072", "-1"], "VALUE = '-1' is invalid; allowed: u16: an integer 0..65535"),
    (["write", "0x6076", "4294967296"], "VALUE = '4294967296' is invalid; allowed: u32: an integer 0..4294967295"),
    (["write", "0x6060", "ten"], "VALUE = 'ten' is invalid; allowed: i8"),
    (["write", "0x2000:1", "1e39", "--type", "f32"], "VALUE = '1e39' is invalid; allowed: f32: a finite real"),
    (["write", "0x2000:1", "nan", "--type", "f64"], "VALUE = 'nan' is invalid; allowed: f64: a finite real"),
    (["write", "0x1008", "héllo"], "VALUE = 'héllo' is invalid; allowed: str: printable ASCII text"),
    (["write", "0x2345", "0g", "--type", "hex"], "VALUE = '0g' is invalid; allowed: hex: bytes as hexadecimal digit pairs"),
    (["write", "0x2345", "3"], "--type is missing; allowed: a type for 0x2345:00, which the dictionary does not know"),
    (["read", "0x6041", "--type", "u7"], "--type = 'u7' is invalid; allowed: u8 u16 u32 u64 i8 i16 i32 i64 f32 f64 bool str hex"),
    (["read", "0x6041", "--eds", "{missing}"], "--eds = '{missing}' is invalid; allowed: an existing EDS or DCF file"),
    (["read", "0x6041", "--eds", "{garbage}"], "is invalid; allowed: an EDS or DCF file canopen can read"),
    (["read", "0x6041", "--node-id", "0"], "--node-id = 0 is invalid; allowed: CANopen node ids 1..127"),
    (["read", "0x6041", "--node-id", "128"], "--node-id = 128 is invalid; allowed: CANopen node ids 1..127"),
    (["read", "0x6041", "--unit-id", "2"], "--unit-id = 2 is invalid; allowed: a Modbus option"),
    (["read", "0x6041", "--timeout", "0"], "--timeout = 0 is invalid"),
    (["peek", "0x6041"], "argument action: invalid choice: 'peek'"),
]


@pytest.mark.parametrize("args, said", INVALID, ids=[" ".join(a) for a, _ in INVALID])
def test_invalid_input_is_exit_2_before_the_bus_is_touched(args: list[str], said: str, channel: str, master: can.BusABC,
                                                           tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    garbage = tmp_path / "garbage.eds"
    garbage.write_text("[FileInfo]\nthis is = not an EDS\n[1000\n")
    files = {"missing": str(tmp_path / "missing.eds"), "garbage": str(garbage)}
    argv = [arg.format(**files) for arg in args]
    if "--node-id" not in argv:
        argv += ["--node-id", "5"]
    result = run_cli(capsys, "sdo", *argv, "--interface", "virtual", "--channel", channel)
    assert result.code == 2
    line = one_line(result)
    assert line.startswith("haptic-bus sdo: error: ") and said.format(**files) in line, line
    assert master.recv(0.05) is None  # not one frame (no drive on this bus)


# ----------------------------------------------------------------------------- Modbus
def test_modbus_reads_and_writes_objects_through_the_register_map(capsys: pytest.CaptureFixture[str]) -> None:
    with ModbusSimServer(port=0, unit_id=2, word_order="little") as server:
        args = ["--modbus", server.url, "--unit-id", "2"]
        result = run_cli(capsys, "sdo", "read", "0x6041", *args)
        assert result.out == (f"Modbus unit 2 at {server.url}: read 0x6041:00 Statusword = {server.drive.statusword} "
                              f"(0x{server.drive.statusword:04X}) (u16, register 0x0000): SWITCH ON DISABLED\n")
        result = run_cli(capsys, "sdo", "write", "0x6060", "10", *args)
        assert result.code == 0 and server.drive.mode == 10
        found = json.loads(run_cli(capsys, "sdo", "read", "0x6061", *args, "--json").out)
        assert (found["value"], found["meaning"], found["where"]) == (10, "cyclic synchronous torque", "register 0x0021")
        rated = json.loads(run_cli(capsys, "sdo", "read", "0x6076", *args, "--json").out)  # two registers, low word first
        assert rated["value"] == server.drive.parameters.rated_torque_mnm and rated["type"] == "u32"


@pytest.mark.parametrize("args, said", [
    (["read", "0x1018"], "object = '0x1018:00' is invalid; allowed: an object of the Modbus register map: 0x6041, 0x606C"),
    (["read", "0x6041:1"], "object = '0x6041:01' is invalid; allowed: an object of the Modbus register map"),
    (["write", "0x6041", "6"], "allowed: a writable object (0x0000 (0x6041 Statusword) is read-only)"),
    (["write", "0x6060", "200"], "VALUE = '200' is invalid; allowed: i8: an integer -128..127"),
    (["read", "0x6041", "--type", "u16"], "--type = 'u16' is invalid; allowed: only without --modbus"),
    (["read", "0x6041", "--eds", "x.eds"], "--eds = 'x.eds' is invalid"),
    (["read", "0x6041", "--node-id", "5"], "--node-id = 5 is invalid"),
])
def test_modbus_invalid_input_is_exit_2_before_connecting(args: list[str], said: str,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    with socket.create_server(("127.0.0.1", 0)) as listener:
        result = run_cli(capsys, "sdo", *args, "--modbus", f"tcp://127.0.0.1:{listener.getsockname()[1]}")
        listener.setblocking(False)
        with pytest.raises(BlockingIOError):
            listener.accept()  # nobody connected
    assert result.code == 2 and said in one_line(result), result.err


def test_modbus_no_server_is_one_line(refusing_port: int, capsys: pytest.CaptureFixture[str]) -> None:
    result = run_cli(capsys, "sdo", "read", "0x6041", "--modbus", f"tcp://127.0.0.1:{refusing_port}", "--timeout", "0.2")
    assert result.code == 1 and "cannot connect within 0.2 s" in one_line(result)
