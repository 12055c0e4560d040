"""The simulated drive as a Modbus TCP server in its own process (``python -m sim_drive --modbus``),
spoken to by pymodbus' own client only: the documented register map, the CiA-402 walk to
OPERATION ENABLED, a few cycles, and a clean SIGTERM stop (exit status 0)."""

from __future__ import annotations

import signal
from collections.abc import Callable
from typing import Any

import pytest
from pymodbus.client import ModbusTcpClient

from drives.cia402 import State, decode_statusword
from drives.modbus.register_map import MAP_IDENTITY, REGISTER_BY_NAME, decode_value, encode_value

UNIT = 1


@pytest.fixture
def server_process(sim_process: Callable[..., Any], free_port: int) -> tuple[Any, int]:
    """``python -m sim_drive --modbus`` serving on ``free_port`` (stopped by the test, else by ``sim_process``)."""
    process = sim_process("--modbus", f"tcp://127.0.0.1:{free_port}", "--timing", "ideal")
    process.wait_for_line(f"serving Modbus TCP on tcp://127.0.0.1:{free_port}", 15.0)
    return process, free_port


def read(client: ModbusTcpClient, name: str):
    spec = REGISTER_BY_NAME[name]
    response = client.read_holding_registers(spec.address, count=spec.count, device_id=UNIT)
    assert not response.isError(), f"{name}: {response}"
    return decode_value(spec, response.registers)


def write(client: ModbusTcpClient, name: str, value: int) -> None:
    spec = REGISTER_BY_NAME[name]
    words = encode_value(spec, value)
    if len(words) == 1:
        response = client.write_register(spec.address, words[0], device_id=UNIT)
    else:
        response = client.write_registers(spec.address, words, device_id=UNIT)
    assert not response.isError(), f"{name}: {response}"


def test_independent_client_walks_to_operation_enabled_and_sigterm_stops_cleanly(server_process) -> None:
    process, port = server_process
    client = ModbusTcpClient("127.0.0.1", port=port, timeout=2.0, retries=0)
    assert client.connect()
    try:
        assert read(client, "map_identity") == MAP_IDENTITY
        assert read(client, "supported_drive_modes") >> 9 & 1  # CST announced (bit 9)
        assert read(client, "motor_rated_torque") == 200  # mN m
        assert read(client, "max_torque") == 3000
        assert read(client, "velocity_per_count") == 1e-6
        assert read(client, "sim_timing") == 1  # ideal
        write(client, "modes_of_operation", 10)
        assert read(client, "modes_of_operation_display") == 10

        assert decode_statusword(read(client, "statusword")) is State.SWITCH_ON_DISABLED
        for controlword, expected in ((0x06, State.READY_TO_SWITCH_ON), (0x07, State.SWITCHED_ON),
                                      (0x0F, State.OPERATION_ENABLED)):
            write(client, "controlword", controlword)
            statusword = read(client, "statusword")
            assert decode_statusword(statusword) is expected, hex(statusword)
        assert read(client, "statusword") & 1 << 12  # CST: following the target

        # three cycles through the output block (FC16) with 100 per mille = 1 N on the handle
        for _ in range(3):
            response = client.write_registers(0x0010, [0x0F, 100], device_id=UNIT)
            assert not response.isError()
        block = client.read_holding_registers(0x0000, count=5, device_id=UNIT)
        assert not block.isError() and len(block.registers) == 5
        velocity = decode_value(REGISTER_BY_NAME["velocity_actual_value"], block.registers[1:3])
        assert velocity > 0 and read(client, "sim_cycle_count") == 4  # SYNC 0 plus three writes
        assert read(client, "sim_time") == pytest.approx(3e-3)
        # one FC23: write first (closes cycle 4), then read the new sample
        response = client.readwrite_registers(read_address=0, read_count=5, write_address=0x10, values=[0x0F, 0], device_id=UNIT)
        assert not response.isError() and read(client, "sim_cycle_count") == 5

        # the exceptions of the map, seen by a foreign client
        assert client.read_holding_registers(0x0001, count=1, device_id=UNIT).exception_code == 0x02
        assert client.write_register(0x0020, 0x1234, device_id=UNIT).exception_code == 0x03
        assert client.read_holding_registers(0x0000, count=1, device_id=UNIT + 1).exception_code == 0x0B
        write(client, "controlword", 0x00)  # DISABLE VOLTAGE before leaving
    finally:
        client.close()

    status, log = process.stop(signal.SIGTERM, timeout=10)
    assert status == 0
    assert "stopped after 4 cycles, virtual time 0.004000 s" in log  # three FC16 + one FC23
