"""The simulated drive as a Modbus TCP server in its own process (``python -m sim_drive --modbus``),
spoken to by pymodbus' own client only: the documented register map, the CiA-402 walk to
OPERATION ENABLED, a few cycles, and a clean SIGTERM stop (exit status 0)."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from pymodbus.client import ModbusTcpClient

from drives.cia402 import State, decode_statusword
from drives.modbus.register_map import MAP_IDENTITY, REGISTER_BY_NAME, decode_value, encode_value

ROOT = Path(__file__).resolve().parents[1]
UNIT = 1


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def wait_for_line(process: subprocess.Popen, text: str, timeout: float) -> list[str]:
    """stderr lines up to the first that contains ``text`` (bounded by ``timeout`` s)."""
    lines: list[str] = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = process.stderr.readline()
        if not line:
            break
        lines.append(line)
        if text in line:
            return lines
    raise AssertionError(f"no {text!r} from the simulator within {timeout} s: {''.join(lines)}")


@pytest.fixture
def server_process():
    port = free_port()
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    process = subprocess.Popen(
        [sys.executable, "-m", "sim_drive", "--modbus", f"tcp://127.0.0.1:{port}", "--timing", "ideal"],
        cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )
    try:
        wait_for_line(process, f"serving Modbus TCP on tcp://127.0.0.1:{port}", 15.0)
        yield process, port
    finally:
        if process.poll() is None:
            process.kill()
            process.wait(5)
        process.stderr.close()


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

    process.send_signal(signal.SIGTERM)
    assert process.wait(10) == 0
    rest = process.stderr.read()
    assert "stopped after 4 cycles, virtual time 0.004000 s" in rest  # three FC16 + one FC23
