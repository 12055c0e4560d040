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
import subprocess
import time
from collections.abc import Callable
from typing import Any

from haptic_bus.testing.processes import SimProcess
from tests.cli_process import cli_process, reaped

START_WAIT = 60.0  # s: the run imports, reads gantry-3d (seconds of its gate under load), commissions three axes
END_WAIT = 30.0  # s: the run notices the lost connection and writes its folder
AXES = ("x", "y", "z")


def cycling(run: subprocess.Popen[str], out: pathlib.Path) -> None:
    """Block until every axis' record holds a row after its header (bounded by :data:`START_WAIT`)."""
    records = [out / f"record-{axis}.csv" for axis in AXES]
    for _ in range(int(START_WAIT / 0.1)):
        if all(path.exists() and path.read_text().count("\n") >= 2 for path in records):
            return
        if run.poll() is not None:
            raise AssertionError(f"the run ended ({run.returncode}) before it cycled: {run.communicate()}")
        time.sleep(0.1)
    raise AssertionError(f"no rows in every axis' record within {START_WAIT} s")


def ended(run: subprocess.Popen[str], sim: SimProcess) -> tuple[int, str]:
    """Kill ``sim`` (SIGKILL: no goodbye), then the run's exit status and stderr."""
    sim.process.send_signal(signal.SIGKILL)
    _, err = run.communicate(timeout=END_WAIT)
    return run.returncode, err


def test_a_killed_modbus_simulator_is_one_line_saying_connection_lost(
        tmp_path: pathlib.Path, sim_process: Callable[..., Any]) -> None:
    sim = sim_process("--modbus", "tcp://127.0.0.1:0", "--modbus", "tcp://127.0.0.1:0", "--modbus",
                      "tcp://127.0.0.1:0", "--profile", "gantry-3d")
    line = next(line for line in sim.wait_for_line("serving Modbus TCP on", START_WAIT).splitlines()
                if "serving Modbus TCP on" in line)
    urls = line.split("serving Modbus TCP on ")[1].split(" (")[0].split(", ")
    assert len(urls) == 3
    with reaped(cli_process("run", "gantry-3d", *(arg for url in urls for arg in ("--modbus", url)), "--virtual-time",
                            "--duration", "600", "--no-plots", "--out", str(tmp_path))) as run:
        cycling(run, tmp_path)
        code, err = ended(run, sim)
    assert code == 1
    assert err.count("\n") == 1 and err.startswith("haptic-bus run: drive error: Modbus unit 1 at tcp://127.0.0.1:"), err
    assert "connection lost while " in err and "bad answer" not in err
