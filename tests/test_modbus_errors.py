"""ModbusDrive's typed errors against the simulated server (loopback, one process): exception
responses (illegal address, illegal value, server busy), timeouts, a dropped connection, a
wrong unit id or word order, a drive fault; each names the unit, the registers and CiA-402
objects and the exception, and the torque is zeroed wherever the link still answers.  Then the
server's own protocol edges, seen by pymodbus' plain client: one injected fault per request (so
one per FC23), foreign unit ids and functions, a dropped request closing only its connection."""

from __future__ import annotations

import time

import pytest
from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ModbusException

from drives.cia402 import QUICK_STOP_OPTION_CODE, State
from drives.modbus.drive import ModbusDrive
from drives.safety import SafetySettings
from haptic_bus.errors import DriveError, DriveFault, DriveProtocolError, DriveTimeout, ModbusLinkLost, ParameterError
from sim_drive.modbus import LINK_LOST_ERROR_CODE, FaultInjector, ModbusSimServer
from tests.run_rig import wait_until

# the loop runs in virtual time: the drive's watchdog guards a dead master, not a busy machine
VIRTUAL_TIME_SAFETY = SafetySettings().for_virtual_time(1e-3)

UNIT = 7

# every request's answer timeout (s): the server answers from a thread of this process, and beside
# the suite's other workers on two cores one answer took over 200 ms (CI, 2026-12-07); 1 s is 5x that
ANSWER_TIMEOUT = 1.0


@pytest.fixture(params=["split", "fc23"])
def running(request):
    """(server, drive) in OPERATION ENABLED after a few cycles with torque on."""
    server = ModbusSimServer(unit_id=UNIT, timing="ideal").start()
    drive = ModbusDrive("127.0.0.1", server.port, unit_id=UNIT, cycle=request.param, timeout=ANSWER_TIMEOUT,
                         safety=VIRTUAL_TIME_SAFETY)
    try:
        drive.connect()
        drive.enable()
        for _ in range(3):
            drive.read_inputs()
            drive.write_outputs(500)
        assert server.drive.target_torque == 500
        yield server, drive
    finally:
        drive.close()
        server.stop()


def test_a_cyclic_phase_saturates_at_its_limit_once_and_counts_it_once(running) -> None:
    server, drive = running
    assert drive.connect() is drive.connection and drive.connection.simulated_timing == "ideal"
    before = drive.stats.saturated_outputs
    with drive.cyclic(torque_limit=400) as cycle:
        cycle.read()
        assert cycle.saturate_and_write(900) == 400  # beyond the phase's limit: clamped once, at it
        assert server.drive.target_torque == 400
        cycle.read()
        assert cycle.saturate_and_write(-300) == -300
        assert server.drive.target_torque == -300
    assert drive.stats.saturated_outputs == before + 1
    drive.read_inputs()
    drive.write_outputs(900)  # the phase over: the drive's own limit (0x6072 = 3000) again
    assert server.drive.target_torque == 900 and drive.stats.saturated_outputs == before + 1


def unit_named(error: DriveError, port: int) -> None:
    assert f"Modbus unit {UNIT} at tcp://127.0.0.1:{port}" in str(error)


def test_illegal_address_acyclic_names_register_object_and_exception(running) -> None:
    server, drive = running
    with pytest.raises(DriveProtocolError) as caught:
        drive.read_registers(0x0001, 1)  # half of the velocity
    unit_named(caught.value, server.port)
    assert "register 0x0001: 0x0001 (0x606C Velocity actual value)" in str(caught.value)
    assert "exception 0x02 ILLEGAL DATA ADDRESS" in str(caught.value)
    assert caught.value.code == 0x02
    with pytest.raises(DriveProtocolError, match=r"register 0x0007: 0x0007 \(unmapped\).*0x02 ILLEGAL DATA ADDRESS"):
        drive.read_registers(0x0007, 1)
    assert drive.tripped is None and server.drive.state is State.OPERATION_ENABLED  # acyclic: no trip


def test_illegal_value_names_register_object_and_exception(running) -> None:
    server, drive = running
    with pytest.raises(DriveProtocolError) as caught:
        drive.write_object(QUICK_STOP_OPTION_CODE, 9)
    unit_named(caught.value, server.port)
    assert "0x0029 (0x605A Quick stop option code)" in str(caught.value)
    assert "exception 0x03 ILLEGAL DATA VALUE" in str(caught.value)
    with pytest.raises(DriveProtocolError, match=r"0x0020 \(0x6060 Modes of operation\).*0x03 ILLEGAL DATA VALUE"):
        drive.write_registers(0x0020, [0x1234])
    assert server.drive.quick_stop_option_code == 2 and server.drive.mode == 10  # nothing applied


@pytest.mark.parametrize("code, name", [(0x06, "SERVER DEVICE BUSY"), (0x02, "ILLEGAL DATA ADDRESS"),
                                        (0x03, "ILLEGAL DATA VALUE")])
def test_exception_in_the_cycle_trips_and_writes_zero_torque(running, code: int, name: str) -> None:
    server, drive = running
    if drive.cycle == "fc23":
        drive.read_inputs()  # the cached inputs; the FC23 of write_outputs meets the fault
        server.faults.exception(code)
        with pytest.raises(DriveProtocolError) as caught:
            drive.write_outputs(800)
        assert "0x0010 (0x6040 Controlword), 0x0011 (0x6071 Target torque)" in str(caught.value)
        assert "0x0000 (0x6041 Statusword), 0x0001 (0x606C Velocity actual value)" in str(caught.value)
    else:
        server.faults.exception(code)
        with pytest.raises(DriveProtocolError) as caught:
            drive.read_inputs()
        assert ("registers 0x0000..0x0004: 0x0000 (0x6041 Statusword), 0x0001 (0x606C Velocity actual value), "
                "0x0003 (0x6064 Position actual value)") in str(caught.value)
    unit_named(caught.value, server.port)
    assert f"exception 0x{code:02X} {name}" in str(caught.value)
    # one zero-torque write with DISABLE VOLTAGE reached the drive
    assert server.drive.target_torque == 0 and server.drive.state is State.SWITCH_ON_DISABLED
    assert drive.tripped is caught.value and drive.stats.safe_stops == 1
    # until fault_reset/enable, write_outputs sends the safe block, not the caller's torque
    drive.read_inputs()
    drive.write_outputs(900)
    assert server.drive.target_torque == 0 and drive.stats.suppressed_outputs == 1
    drive.enable()
    drive.read_inputs()
    drive.write_outputs(300)
    assert server.drive.target_torque == 300 and server.drive.state is State.OPERATION_ENABLED


def test_busy_during_enable_is_a_protocol_error_naming_the_object() -> None:
    with (ModbusSimServer(unit_id=UNIT) as server,
          ModbusDrive("127.0.0.1", server.port, unit_id=UNIT, timeout=ANSWER_TIMEOUT) as drive):
        drive.connect()
        server.faults.busy()
        with pytest.raises(DriveProtocolError, match=r"0x0026 \(0x6502 Supported drive modes\).*0x06 SERVER DEVICE BUSY"):
            drive.enable()
        drive.enable()  # the next try passes
        assert server.drive.state is State.OPERATION_ENABLED


def test_timeout_names_the_unit_zeroes_torque_and_closes_the_link(running) -> None:
    server, drive = running
    server.faults.delay(3 * ANSWER_TIMEOUT)
    started = time.monotonic()
    with pytest.raises(ModbusLinkLost) as caught:  # a silence in the cycle closes the link: what the caller acts on
        drive.read_inputs()
        drive.write_outputs(100)
    assert time.monotonic() - started < 2.5 * ANSWER_TIMEOUT  # the timeout ended the wait, not the late answer
    unit_named(caught.value, server.port)
    assert "no answer within 1000 ms" in str(caught.value) and "until the master reconnects" in str(caught.value)
    assert not isinstance(caught.value, TimeoutError) and not drive.link_up
    # zero torque reached the drive: either the safe write (after the late answer) or, when the
    # link closed, the server's watchdog fault; either way no torque is applied
    deadline = time.monotonic() + 3 * ANSWER_TIMEOUT + 2.0  # the late answer, then the safe write
    while server.drive.state is State.OPERATION_ENABLED and time.monotonic() < deadline:
        time.sleep(0.01)
    assert server.drive.state in (State.SWITCH_ON_DISABLED, State.FAULT)
    assert server.drive.torque_actual == 0
    # no silent reconnect: the hot path refuses until reconnect()
    with pytest.raises(ModbusLinkLost, match="until the master reconnects"):
        drive.write_outputs(100)
    drive.reconnect()
    if server.drive.state is State.FAULT:
        drive.fault_reset()
    drive.enable()
    drive.read_inputs()
    drive.write_outputs(100)
    assert server.drive.target_torque == 100


def test_a_write_answered_late_says_it_may_still_be_applied() -> None:
    """A write the unit answers after the timeout was applied all the same (break16, on CANopen: a drive stopped
    with SIGSTOP applied the write it took once resumed): the timeout's line says the request went out."""
    with (ModbusSimServer(unit_id=UNIT) as server,
          ModbusDrive("127.0.0.1", server.port, unit_id=UNIT, timeout=ANSWER_TIMEOUT) as drive):
        drive.connect()
        server.faults.delay(2 * ANSWER_TIMEOUT)
        with pytest.raises(DriveTimeout, match=r"no answer within 1000 ms while writing register 0x0029: 0x0029 "
                                               r"\(0x605A Quick stop option code\) .*; the request went out, so a unit "
                                               r"that answers late may still apply it$"):
            drive.write_object(QUICK_STOP_OPTION_CODE, 6)
        deadline = time.monotonic() + 3 * ANSWER_TIMEOUT  # bounded: the late answer, then the write applied
        while server.drive.quick_stop_option_code != 6 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert server.drive.quick_stop_option_code == 6


def test_dropped_connection_is_link_lost_and_the_drive_faults(running) -> None:
    server, drive = running
    closed_before = server.connections_closed
    server.faults.drop()
    with pytest.raises(ModbusLinkLost) as caught:
        drive.read_inputs()
        drive.write_outputs(100)
    assert not isinstance(caught.value, TimeoutError)  # a dropped connection is no silence
    unit_named(caught.value, server.port)
    assert "connection lost" in str(caught.value) and "until the master reconnects" in str(caught.value)
    deadline = time.monotonic() + 2.0
    while server.connections_closed == closed_before and time.monotonic() < deadline:
        time.sleep(0.01)
    # the link is gone, so the master could not write zero torque; the drive's watchdog did
    assert server.drive.state is State.FAULT and server.drive.error_code == LINK_LOST_ERROR_CODE
    assert server.drive.torque_actual == 0
    with pytest.raises(ModbusLinkLost):
        drive.read_inputs()
    assert server.connections_closed == closed_before + 1  # and no new connection was opened
    drive.reconnect()
    with pytest.raises(DriveError, match="FAULT"):
        drive.enable()
    drive.fault_reset()
    drive.enable()
    assert server.drive.state is State.OPERATION_ENABLED


def test_fault_bit_raises_drive_fault_with_the_error_code(running) -> None:
    server, drive = running
    drive.read_inputs()
    drive.write_outputs(100)
    server.drive.fault(0x2310)  # overcurrent, injected between cycles
    with pytest.raises(DriveFault) as caught:
        drive.read_inputs()  # split: this read samples the fault
        drive.write_outputs(100)  # fc23: the inputs above were sampled before it; this brings it
        drive.read_inputs()
    assert caught.value.code == 0x2310 and "error code 0x2310" in str(caught.value)
    unit_named(caught.value, server.port)
    assert server.drive.target_torque == 0


def test_wrong_unit_and_wrong_word_order_are_refused_at_connect() -> None:
    with ModbusSimServer(unit_id=UNIT) as server:
        with ModbusDrive("127.0.0.1", server.port, unit_id=UNIT + 1, timeout=ANSWER_TIMEOUT) as drive:
            with pytest.raises(DriveProtocolError, match=r"Modbus unit 8 .*0x0B GATEWAY TARGET DEVICE FAILED TO RESPOND: "
                                                         rf"no unit 8 answers at tcp://127.0.0.1:{server.port}, check the "
                                                         "unit id$"):
                drive.connect()  # the same words wherever the first read is (status, sdo: breaker11a)
        with ModbusDrive("127.0.0.1", server.port, unit_id=UNIT, word_order="little", timeout=ANSWER_TIMEOUT) as drive:
            with pytest.raises(DriveProtocolError, match="other word order"):
                drive.connect()


def test_nobody_listening_is_a_timeout_and_rtu_constructs() -> None:
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]  # bound, not listening: connection refused
        drive = ModbusDrive("127.0.0.1", port, unit_id=3, timeout=ANSWER_TIMEOUT)
        with pytest.raises(DriveTimeout, match=f"Modbus unit 3 at tcp://127.0.0.1:{port}: cannot connect"):
            drive.connect()
    rtu = ModbusDrive.from_url("rtu:/dev/ttyUSB0", unit_id=5, baudrate=57600)
    assert rtu.link.address.serial and rtu.link.address.port == "/dev/ttyUSB0" and rtu.name == "Modbus unit 5 at rtu:/dev/ttyUSB0"
    with pytest.raises(DriveError):  # no pyserial here, or no such port
        rtu.connect()
    with pytest.raises(ValueError, match="unit_id"):
        ModbusDrive("127.0.0.1", 502, unit_id=300)
    with pytest.raises(ValueError, match="cycle"):
        ModbusDrive("127.0.0.1", 502, cycle="fast")


def plain_client(server: ModbusSimServer) -> ModbusTcpClient:
    """pymodbus' own synchronous client, connected to ``server`` on loopback."""
    client = ModbusTcpClient("127.0.0.1", port=server.port, timeout=1.0, retries=0)
    assert client.connect()
    return client


def test_an_injected_fault_is_met_once_per_request_and_once_per_fc23() -> None:
    with ModbusSimServer(unit_id=UNIT, timing="ideal") as server:
        client = plain_client(server)
        try:
            def fc23():
                return client.readwrite_registers(read_address=0, read_count=5, write_address=0x10, values=[0, 0], device_id=UNIT)

            cycles = server.bank.cycles
            server.faults.busy(2)
            assert fc23().exception_code == 0x06 and fc23().exception_code == 0x06
            assert server.bank.cycles == cycles and server.faults.injected == 2  # nothing applied
            response = fc23()  # the two faults are spent: write (closes a cycle), then read
            assert not response.isError() and len(response.registers) == 5
            assert server.bank.cycles == cycles + 1 and server.faults.injected == 2
            server.faults.delay(0.05)  # met by the FC23's write; its read meets nothing
            started = time.monotonic()
            assert not fc23().isError()
            assert time.monotonic() - started >= 0.05
            assert server.bank.cycles == cycles + 2 and server.faults.injected == 3
            server.faults.delay(0.05, count=2)  # FC06 writes, then reads back: still one request
            assert not client.write_register(0x10, 0, device_id=UNIT).isError()
            assert server.faults.injected == 4
        finally:
            client.close()


def test_foreign_units_and_functions_are_refused_before_any_fault() -> None:
    with ModbusSimServer(unit_id=0) as server:  # unit 0 too answers for itself only
        client = plain_client(server)
        try:
            server.faults.busy()
            assert client.read_holding_registers(0x30, count=2, device_id=1).exception_code == 0x0B
            assert client.write_register(0x10, 6, device_id=255).exception_code == 0x0B
            assert client.read_coils(0, count=1, device_id=0).exception_code == 0x01
            assert client.read_input_registers(0, count=1, device_id=0).exception_code == 0x01
            assert server.faults.injected == 0 and server.drive.state is State.SWITCH_ON_DISABLED
            assert client.read_holding_registers(0x30, count=2, device_id=0).exception_code == 0x06
            assert client.read_holding_registers(0x30, count=2, device_id=0).registers == [0x4842, 0x0402]
        finally:
            client.close()
    with pytest.raises(ParameterError, match="code = 66"):
        FaultInjector().exception(0x42)


def test_a_dropped_request_closes_its_own_connection_only() -> None:
    with ModbusSimServer(unit_id=UNIT, timing="ideal") as server:
        commander, other = plain_client(server), plain_client(server)
        try:
            for controlword in (0x06, 0x07, 0x0F):
                assert not commander.write_register(0x10, controlword, device_id=UNIT).isError()
            assert server.drive.state is State.OPERATION_ENABLED
            server.faults.drop()
            with pytest.raises(ModbusException):
                other.read_holding_registers(0, count=5, device_id=UNIT)
            assert wait_until(lambda: server.connections_closed == 1)
            # the commanding connection is still up: no watchdog fault, and it is still answered
            assert server.drive.state is State.OPERATION_ENABLED
            assert not commander.read_holding_registers(0, count=5, device_id=UNIT).isError()
            commander.close()
            assert wait_until(lambda: server.connections_closed == 2)
            assert server.drive.state is State.FAULT and server.drive.error_code == LINK_LOST_ERROR_CODE
        finally:
            commander.close()
            other.close()


def test_a_url_given_as_the_host_is_refused_naming_from_url() -> None:
    from drives.errors import ParameterError
    from drives.modbus.drive import ModbusDrive

    for url in ("tcp://127.0.0.1:1502", "rtu:/dev/ttyUSB0"):
        refusal = r"host = .* is invalid; allowed: a host name or address \(a URL: ModbusDrive.from_url\)"
        with pytest.raises(ParameterError, match=refusal):
            ModbusDrive(url)
