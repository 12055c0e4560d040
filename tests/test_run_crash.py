"""Issue 20, records that survive a crash: ``kill -9`` of a real ``haptic-bus run`` at a random
moment leaves ``record.csv`` with every cycle up to 0.2 s before the kill (rows contiguous from
cycle 0, a torn last line tolerated by the reader), ``run.json`` saying the run did not end, and a
bus log that python-can's ``LogReader`` reads.

Three processes, as users start them: ``python -m sim_drive`` (the simulated CiA-402 drive, a new
one each trial: a killed controller leaves it faulted) and ``haptic-bus run --virtual-time`` on
``udp_multicast`` (loopback, hop limit 0), killed with SIGKILL from this test.
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import can
import numpy as np
import pytest

from haptic_bus.app.cli import main
from haptic_bus.app.run_folder import read_run_folder
from haptic_bus.control.record import COLUMNS

REPO = Path(__file__).resolve().parents[1]
NODE = 5
TRIALS = 5
START_WAIT = 30.0  # s: both processes import numpy/scipy/canopen before they answer
KEPT = 0.2  # s: every cycle up to this long before the kill is on disk (the bound)
PERIOD = 1e-3  # s: cia402-handle's T


def _start_run(multicast: tuple[str, int], out: Path) -> subprocess.Popen[bytes]:
    group, port = multicast
    return subprocess.Popen(
        [sys.executable, "-m", "haptic_bus.app.cli", "run", "cia402-handle", "--interface", "udp_multicast", "--channel",
         group, "--bus-option", f"port={port}", "--node-id", str(NODE), "--virtual-time", "--duration", "600",
         "--out", str(out), "-q"],
        cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)}, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def _kill_while_cycling(run: subprocess.Popen[bytes], out: Path, rng: random.Random) -> float:
    """Wait until the run cycles (its record grows), then a random 0.1-2 s more; SIGKILL; the Unix time of the kill."""
    deadline = time.monotonic() + START_WAIT
    record = out / "record.csv"
    while time.monotonic() < deadline and run.poll() is None:
        if record.is_file() and record.stat().st_size > 10_000:  # the header and some cycles
            break
        time.sleep(0.02)
    assert run.poll() is None and record.is_file(), "the run never started cycling"
    time.sleep(rng.uniform(0.1, 2.0))
    killed = time.time()
    os.kill(run.pid, signal.SIGKILL)
    run.wait(timeout=10)
    return killed


def _check_trial(out: Path, killed: float) -> dict[str, Any]:
    run = read_run_folder(out)
    record = run.record
    assert record is not None and tuple(record.columns) == COLUMNS
    cycles = record.cycles
    assert cycles > 100
    assert np.array_equal(record["time_s"], np.arange(cycles) * PERIOD)  # contiguous from cycle 0: no row lost or torn
    assert np.all(np.diff(record["monotonic_s"]) > 0) and np.all(np.diff(record["wall_clock_s"]) >= 0)
    gap = killed - float(record["wall_clock_s"][-1])
    assert 0 <= gap <= KEPT, f"the last cycle on disk started {gap:.3f} s before the kill"
    assert record["statusword"][-1] == 0x1237 and np.all(record["input_age"] >= 0)  # OPERATION ENABLED, as received
    assert not run.ended_cleanly
    assert run.document["status"] == "running" and run.document["ended"] is False and run.document["ended_utc"] is None
    assert any("did not end cleanly" in note for note in run.notes())
    frames = list(can.LogReader(str(out / "bus.asc")))  # python-can's own reader, on a log nobody closed
    ids = {frame.arbitration_id for frame in frames}
    assert {0x080, 0x180 + NODE, 0x200 + NODE} <= ids  # SYNC, TPDO1, RPDO1
    syncs = sum(frame.arbitration_id == 0x080 for frame in frames)
    return {"cycles": cycles, "gap_s": gap, "frames": len(frames), "syncs": syncs, "torn": record.torn_line}


@pytest.mark.slow
def test_kill_9_at_random_moments_keeps_every_cycle_but_the_last_0_2_s(multicast: tuple[str, int], sim_process: Any,
                                                                       tmp_path: Path, capsys: Any) -> None:
    group, port = multicast
    rng = random.Random(20)
    trials = []
    for trial in range(TRIALS):
        sim = sim_process("--interface", "udp_multicast", "--channel", group, "--bus-option", f"port={port}",
                          "--node-id", str(NODE), "--profile", "cia402-handle")
        sim.wait_for_line("serving on", START_WAIT)
        out = tmp_path / f"trial{trial}"
        run = _start_run(multicast, out)
        try:
            killed = _kill_while_cycling(run, out, rng)
        finally:
            if run.poll() is None:
                run.kill()
                run.wait(timeout=10)
            sim.stop()
        trials.append(_check_trial(out, killed))
    with capsys.disabled():
        print(json.dumps(trials))  # what -s shows: cycles, the gap from the last cycle on disk to the kill, frames
    assert all(t["syncs"] > 0 for t in trials)

    capsys.readouterr()
    assert main(["plot", str(tmp_path / "trial0")]) == 0  # the pictures of a killed run, which says how it ended
    said = capsys.readouterr().out
    assert "the run did not end cleanly" in said and "wrote " in said
    assert (tmp_path / "trial0" / "timeline.png").stat().st_size > 20_000
