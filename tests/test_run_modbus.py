"""``haptic-bus run PROFILE --modbus tcp://127.0.0.1:PORT`` against the simulated drive's Modbus
TCP server on loopback: the same controller, unchanged, over Modbus TCP.

Both run in this process (the real command line, the real server on a real socket): what is
asserted is the loop's settling and the refusal's words, not the processes.  A run and the
simulator in two processes over Modbus are tested where the process is the point (kill -9 and
SIGSTOP: tests/test_safety_chain.py, tests/test_operations_e2e.py).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from haptic_bus.app.profiles import load_profile
from sim_drive.modbus import ModbusSimServer
from tests.run_rig import read_record, run_cli, simulated_drive


@pytest.mark.parametrize("profile_name", ["cia402-handle"])
def test_run_over_modbus_settles_at_f_over_k(profile_name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with simulated_drive("modbus", profile_name, hand_needs_power=True) as sim:  # the hand as ``haptic-bus sim`` has it
        run = run_cli(capsys, "run", profile_name, *sim.args, "--virtual-time", "--duration", "1.5", "--no-plots",
                      "--out", str(tmp_path))
    assert run.code == 0, run.err
    assert "cycles 1500" in run.out
    profile = load_profile(profile_name)
    wall = profile.scene[0]
    _, record = read_record(tmp_path)
    position = record["position_m"][-1]
    push = profile.operator_model["level"]
    lsb = profile.scaling().newton_per_permille / wall.stiffness  # one torque count of penetration
    assert position - wall.position == pytest.approx(push / wall.stiffness, abs=lsb)


def test_a_scaling_conflict_over_modbus_names_the_profile_as_canopen_does(tmp_path: Path,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    server = ModbusSimServer("127.0.0.1", 0, hand_needs_power=True)  # the simulator's own device: its 0x606C factor
    server.start()                                                   # is not cia402-handle's
    try:
        run = run_cli(capsys, "run", "cia402-handle", "--modbus", server.url, "--virtual-time", "--no-plots", "-q",
                      "--out", str(tmp_path))
    finally:
        server.stop()
    assert run.code == 1 and run.err.count("\n") == 1
    assert "scaling conflict for velocity_per_count: 1e-06 m/s from register 0x0040 but " in run.err
    assert " m/s from profile [device] " in run.err  # the words the CANopen run uses for the same source


def test_a_run_on_a_server_this_process_serves_writes_from_a_thread() -> None:
    """The run writes from a thread (no writer process and its second interpreter's imports) where
    its drive is in this process: every Modbus URL it reaches served here while the server serves."""
    from haptic_bus.app.run_writer import writer_for

    with ModbusSimServer("127.0.0.1", 0) as one, ModbusSimServer("127.0.0.1", 0) as two:
        assert writer_for({"kind": "modbus", "url": one.url, "unit_id": 1})
        assert writer_for({"kind": "modbus", "urls": [one.url, two.url], "unit_ids": [1, 1]})
        elsewhere = "tcp://127.0.0.1:1"  # served by no one here (a simulator in another process, a real drive)
        assert not writer_for({"kind": "modbus", "urls": [one.url, elsewhere], "unit_ids": [1, 1]})
    assert not writer_for({"kind": "modbus", "url": one.url, "unit_id": 1})  # stopped: no longer served here
