"""Issue 26, side work gets data, not the GIL: while a run cycles, its control process holds the
control thread and nothing that formats or writes: the record, the bus log and the live view are
the writer process' (``hb-writer``, a child of the control process).

The run is ``haptic_bus.run_canopen`` in this process' main thread (the control thread) against
the simulated drive in another process on ``udp_multicast``, in virtual time, live view on; a
thread of this test samples ``threading.enumerate()`` while the record grows, then stops the run.  The threads still
allowed, each with its reason, are :data:`ALLOWED`.  The bench's per-thread CPU account counts
the writer process beside them.
"""

from __future__ import annotations

import os
import pathlib
import sys
import threading
import time
from typing import Any

import pytest

from haptic_bus.app.profiles import load_profile
from haptic_bus.app.record_stream import FLUSH_INTERVAL
from haptic_bus.app.run_folder import read_run_folder
from haptic_bus.app.run_options import VIRTUAL
from haptic_bus.app.run_writer import RunWriter
from haptic_bus.app.runner import RunOptions, run_canopen
from haptic_bus.app.writer_process import COMM
from haptic_bus.bench.thread_tuning import ENDED, ThreadCpu

NODE = 5
CONTROLLER_NODE = 127
START_WAIT = 30.0  # s: the simulated drive imports numpy/scipy/canopen before it answers
SAMPLES = 20  # samples of the process' threads, 20 ms apart, once the run cycles
ALLOWED = {
    "verdict-collect": "the upload judge's executor thread (concurrent.futures): blocked on the worker process' "
                       "result pipe, it runs only while an upload is judged (haptic_bus/node/verdicts.py)",
    "verdict-feed": "the same executor's call-queue feeder: blocked until an upload is submitted",
    "hb-write-watch": "blocked in read on the writer's alarm pipe, it runs once if the folder cannot be written "
                      "(a full disk, the folder deleted) to stop the run (haptic_bus/app/run_writer.py)",
}


def _children_named(comm: str) -> list[int]:
    """This process' children whose ``/proc/PID/comm`` is ``comm``."""
    found = []
    for entry in pathlib.Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:  # gone meanwhile
                continue
            name, rest = stat[stat.index("(") + 1:stat.rindex(")")], stat[stat.rindex(")") + 2:].split()
            if name == comm and int(rest[1]) == os.getpid():
                found.append(int(entry.name))
    return found


def test_while_cycling_the_control_process_runs_the_control_thread_and_no_writer(
        multicast: tuple[str, int], sim_process: Any, tmp_path: pathlib.Path) -> None:
    group, port = multicast
    sim = sim_process("--interface", "udp_multicast", "--channel", group, "--bus-option", f"port={port}",
                      "--node-id", str(NODE), "--profile", "cia402-handle")
    sim.wait_for_line("serving", START_WAIT)
    out = tmp_path / "run"
    seen: list[set[str]] = []
    writers: list[list[int]] = []
    modules: list[frozenset[str]] = []  # the modules loaded at the first sample and at the last

    def sample() -> None:
        record = out / "record.csv"
        deadline = time.monotonic() + START_WAIT
        while time.monotonic() < deadline and not (record.is_file() and record.stat().st_size > 20_000):
            time.sleep(0.01)
        try:
            for k in range(SAMPLES):
                seen.append({thread.name for thread in threading.enumerate() if thread is not threading.current_thread()})
                writers.append(_children_named(COMM))
                if k in (0, SAMPLES - 1):
                    modules.append(frozenset(sys.modules))
                time.sleep(0.02)
        finally:
            options.stop.event.set()  # sampled: the run may end (as SIGTERM ends haptic-bus run)

    # the run goes on until the samples are taken, then is stopped: cycling on to a fixed duration in virtual
    # time (4 s were 4 000 cycles of both processes) showed nothing the samples had not
    options = RunOptions(600.0, pacing=VIRTUAL, out_dir=out, live=True, plots=False)
    sampler = threading.Thread(target=sample, name="test-sampler")
    sampler.start()
    try:
        result = run_canopen(load_profile("cia402-handle"), {"interface": "udp_multicast", "channel": group, "port": port},
                             NODE, options, CONTROLLER_NODE)
    finally:
        sampler.join(timeout=START_WAIT + 5.0)
        sim.stop()
    assert (result.exit_reason, result.error) == ("stopped", None)
    assert len(seen) == SAMPLES, "the run ended before the samples were taken"
    assert all(threads == {"MainThread", *ALLOWED} for threads in seen), seen
    assert all(len(pids) == 1 for pids in writers), writers  # the record, the log and the view: one writer process
    assert sorted(modules[-1] - modules[0]) == []  # nothing imported while the cycles ran (an import holds the GIL)
    assert _children_named(COMM) == []  # it ended with the run


def test_the_writer_process_reports_its_own_cpu(tmp_path: pathlib.Path) -> None:
    writer = RunWriter(tmp_path, bus_log=True)
    stats = writer.close()
    assert stats.keys() == {"records", "bus_log", "writer"}
    assert stats["records"] == {} and stats["bus_log"] == {"frames": 0, "frames_lost": 0}
    assert stats["writer"]["cpu_s"] > 0.0  # its start alone imports python-can's ASC writer: tens of ms of CPU at least


def test_the_bench_counts_each_thread_and_those_that_ended_meanwhile() -> None:
    """No thread samples while the block runs: a thread that started and ended within it is counted
    with the others that did (the process's CPU less its living threads')."""
    def busy(seconds: float) -> None:
        end = time.thread_time() + seconds
        while time.thread_time() < end:
            pass

    with ThreadCpu() as cpu:
        ended = threading.Thread(target=busy, args=(0.2,), name="ends-meanwhile")
        ended.start()
        ended.join()
        busy(0.1)
    threads = cpu.by_name()
    assert "ends-meanwhile" not in threads
    # 0.2 s and 0.1 s of CPU, each read to the ns; the thread's start and the block's reads of /proc add
    # about a ms (the process's other threads, xdist's, are counted under their own names): within 50 ms
    assert threads[ENDED] == pytest.approx(0.2, abs=0.05)
    assert threads[threading.current_thread().name] == pytest.approx(0.1, abs=0.05)


def test_a_run_whose_drive_is_in_this_process_writes_from_a_thread(haptic_sim: Any, tmp_path: pathlib.Path) -> None:
    """On the lock-step bus the drive runs in the control process: the same writer loop runs in a
    thread named ``hb-writer`` (no child process), and writes every cycle, as the process does."""
    drive = haptic_sim("cia402-handle", interface="lockstep", node_id=NODE)
    out = tmp_path / "run"
    options = RunOptions(60.0, pacing=VIRTUAL, out_dir=out, live=False, plots=False)
    seen: list[tuple[set[str], list[int]]] = []

    def sample() -> None:  # once the writer has drained rows below the header, then the run may end
        record = out / "record.csv"
        deadline = time.monotonic() + START_WAIT
        try:
            while time.monotonic() < deadline and not (record.is_file() and record.read_bytes().count(b"\n") > 1):
                time.sleep(FLUSH_INTERVAL / 5)
            seen.append(({thread.name for thread in threading.enumerate()}, _children_named(COMM)))
        finally:
            options.stop.event.set()

    sampler = threading.Thread(target=sample, name="test-sampler")
    sampler.start()
    result = run_canopen(load_profile("cia402-handle"), drive.bus, NODE, options, CONTROLLER_NODE)
    sampler.join(timeout=START_WAIT + 5.0)
    assert result.exit_reason == "stopped" and result.summary is not None, result.error
    assert len(seen) == 1 and COMM in seen[0][0] and seen[0][1] == [], seen
    assert COMM not in {thread.name for thread in threading.enumerate()}  # it ended with the run
    run = read_run_folder(out)
    assert run.record is not None and run.record.cycles == result.summary.cycles > 0
    assert run.document["record"] == {"rows_written": result.summary.cycles, "rows_lost": 0}
