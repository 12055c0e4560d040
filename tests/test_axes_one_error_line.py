"""One drive error is one line on stderr at three axes too.

``haptic-bus run gantry-3d`` in virtual time against a simulator in another process; once every
axis' record has rows, the simulator of all three Modbus servers is killed.  The run ends "drive
error" (exit 1) with the command's one line, and nothing else on stderr at the default verbosity:
the other axes' failed goodbyes are INFO (``-v``), and a socket's ECONNRESET is "connection lost",
as pymodbus' own word for a dropped connection is.  The CANopen case (node 6's simulator process
killed) is asserted on the run of
``test_axes_run.py::test_killing_one_axis_drive_process_zeroes_every_torque_in_the_same_cycle``,
which starts the same three processes and kills the same one: one run, not two.
"""

from __future__ import annotations

import pathlib
import signal
import threading
import time
from collections.abc import Callable
from typing import Any

import pytest

from haptic_bus.app.cli import main
from haptic_bus.testing.processes import SimProcess

START_WAIT = 60.0  # s: the run reads gantry-3d (seconds of its gate under load) and commissions three axes
AXES = ("x", "y", "z")


def kill_once_cycling(sim: SimProcess, out: pathlib.Path, done: threading.Event, killed: list[float]) -> None:
    """Once every axis' record holds a row after its header, SIGKILL ``sim`` (no goodbye) and note
    when; give up when ``done`` is set (the run ended first) or after :data:`START_WAIT`."""
    records = [out / f"record-{axis}.csv" for axis in AXES]
    for _ in range(int(START_WAIT / 0.1)):
        if all(path.exists() and path.read_text().count("\n") >= 2 for path in records):
            sim.process.send_signal(signal.SIGKILL)
            killed.append(time.monotonic())
            return
        if done.wait(0.1):
            return


def test_a_killed_modbus_simulator_is_one_line_saying_connection_lost(
        tmp_path: pathlib.Path, sim_process: Callable[..., Any], capfd: pytest.CaptureFixture[str]) -> None:
    """The simulator is a process (killed with SIGKILL, its sockets reset by the kernel); the run is
    the command's ``main`` in this process, its stderr read at the file descriptor (its writer
    process' included, as a shell would show them): a process adds nothing to the one line asserted."""
    sim = sim_process("--modbus", "tcp://127.0.0.1:0", "--modbus", "tcp://127.0.0.1:0", "--modbus",
                      "tcp://127.0.0.1:0", "--profile", "gantry-3d")
    line = next(line for line in sim.wait_for_line("serving Modbus TCP on", START_WAIT).splitlines()
                if "serving Modbus TCP on" in line)
    urls = line.split("serving Modbus TCP on ")[1].split(" (")[0].split(", ")
    assert len(urls) == 3
    done, killed = threading.Event(), list[float]()
    killer = threading.Thread(target=kill_once_cycling, args=(sim, tmp_path, done, killed))
    killer.start()
    try:
        code = main(["run", "gantry-3d", *(arg for url in urls for arg in ("--modbus", url)), "--virtual-time",
                     "--duration", "600", "--no-plots", "--out", str(tmp_path)])
    finally:
        done.set()
        killer.join(START_WAIT)
    err = capfd.readouterr().err
    assert killed, f"the run ended ({code}) before every axis cycled: {err}"
    assert code == 1
    assert err.count("\n") == 1 and err.startswith("haptic-bus run: drive error: Modbus unit 1 at tcp://127.0.0.1:"), err
    assert "connection lost while " in err and "bad answer" not in err
