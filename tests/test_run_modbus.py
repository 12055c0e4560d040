"""``haptic-bus run PROFILE --modbus tcp://127.0.0.1:PORT`` against ``haptic-bus sim --modbus``
in another process: the same controller, unchanged, over Modbus TCP on loopback."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from haptic_bus.app.profiles import load_profile

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("profile_name", ["cia402-handle"])
def test_run_over_modbus_settles_at_f_over_k(
    profile_name: str, tmp_path: Path, free_port: int, sim_process: Callable[..., Any]
) -> None:
    port = free_port
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    url = f"tcp://127.0.0.1:{port}"
    server = sim_process("--modbus", url, "--profile", profile_name)
    try:
        server.wait_for_line(f"serving Modbus TCP on {url}", 15.0)
        run = subprocess.run([sys.executable, "-m", "haptic_bus.app.cli", "run", profile_name, "--modbus", url,
                              "--virtual-time", "--duration", "1.5", "--no-plots", "--out", str(tmp_path)],
                             cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    finally:
        server_status, server_log = server.stop()  # SIGTERM, at most 10 s
    assert run.returncode == 0, run.stderr
    assert "cycles 1500" in run.stdout
    profile = load_profile(profile_name)
    wall = profile.scene[0]
    with (tmp_path / "record.csv").open() as file:
        rows = list(csv.DictReader(file))
    position = float(rows[-1]["position_m"])
    push = profile.operator_model["level"]
    lsb = profile.scaling().newton_per_permille / wall.stiffness  # one torque count of penetration
    assert position - wall.position == pytest.approx(push / wall.stiffness, abs=lsb)
    assert server_status == 0, server_log


def test_a_scaling_conflict_over_modbus_names_the_profile_as_canopen_does(
    tmp_path: Path, free_port: int, sim_process: Callable[..., Any]
) -> None:
    url = f"tcp://127.0.0.1:{free_port}"
    server = sim_process("--modbus", url)  # the simulator's own device: its 0x606C factor is not cia402-handle's
    try:
        server.wait_for_line(f"serving Modbus TCP on {url}", 15.0)
        run = subprocess.run([sys.executable, "-m", "haptic_bus.app.cli", "run", "cia402-handle", "--modbus", url,
                              "--virtual-time", "--no-plots", "-q", "--out", str(tmp_path)],
                             cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)), capture_output=True, text=True,
                             timeout=120)
    finally:
        server.stop()
    assert run.returncode == 1 and run.stderr.count("\n") == 1
    assert "scaling conflict for velocity_per_count: 1e-06 m/s from register 0x0040 but " in run.stderr
    assert " m/s from profile [device] " in run.stderr  # the words the CANopen run uses for the same source
