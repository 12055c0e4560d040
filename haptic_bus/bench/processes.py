"""The benchmark's other processes: the simulated CANopen drive on udp_multicast, and CPU hogs.

Every process started here is stopped by the context manager that started it (SIGTERM, a
bounded wait, then SIGKILL); a CPU hog also asks the kernel to kill it when the thread that
started it ends (``PR_SET_PDEATHSIG``), so an interrupted or killed benchmark leaves none behind.
A Ctrl-C while one is being started acts once it is (:func:`~haptic_bus.bench.interrupts.sigint_after`),
so the process is one the context manager stops.
"""

from __future__ import annotations

import os
import random
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from haptic_bus.app.rig import simulator_command
from haptic_bus.bench.interrupts import sigint_after

START_WAIT = 30.0  # s: the subprocess imports numpy/scipy/canopen before it answers
_REPO = Path(__file__).resolve().parents[2]
_HOG = "import ctypes, signal; ctypes.CDLL(None).prctl(1, signal.SIGKILL)\nwhile True: pass"  # 1 = PR_SET_PDEATHSIG


def stop(process: subprocess.Popen) -> int:
    """SIGTERM, a bounded wait, then SIGKILL; the exit status."""
    if process.poll() is None:
        process.terminate()
    try:
        return process.wait(10)
    except subprocess.TimeoutExpired:
        process.kill()
        return process.wait(10)


def wait_heartbeat(bus_kwargs: dict[str, Any], node_id: int, process: subprocess.Popen, timeout: float) -> None:
    """Block until node ``node_id``'s heartbeat is on the bus (bounded by ``timeout`` s)."""
    from drives.bus_config import open_bus

    deadline = time.monotonic() + timeout
    with open_bus(**bus_kwargs) as bus:
        while time.monotonic() < deadline:
            if process.poll() is not None:
                raise RuntimeError(f"the simulator exited early with status {process.returncode}")
            msg = bus.recv(0.1)
            if msg is not None and msg.arbitration_id == 0x700 + node_id:
                return
    raise RuntimeError(f"no heartbeat of node {node_id} within {timeout} s")


@contextmanager
def canopen_simulator(profile: str, node_ids: tuple[int, ...],
                      *options: str) -> Iterator[tuple[dict[str, Any], subprocess.Popen]]:
    """``python -m sim_drive`` for ``profile`` as nodes ``node_ids`` (one, or a multi-axis device) on a
    unique udp_multicast group and port, with more of its ``options`` (``--operator ...``); yields the
    bus keyword arguments and the process, once every node's heartbeat is seen."""
    group = f"239.74.{160 + os.getpid() % 64}.{1 + random.randrange(250)}"
    port = random.randint(45000, 55000)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(_REPO), env.get("PYTHONPATH")]))
    args = simulator_command("--interface", "udp_multicast", "--channel", group, "--bus-option", f"port={port}",
                             *(("--node-id", str(node_ids[0])) if len(node_ids) == 1 else
                               ("--node-ids", ",".join(map(str, node_ids)))), "--profile", profile, *options)
    bus = {"interface": "udp_multicast", "channel": group, "port": port}
    process = None
    try:
        with sigint_after():  # a simulator started is one the finally stops
            process = subprocess.Popen(args, cwd=_REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for node_id in node_ids:
            wait_heartbeat(bus, node_id, process, START_WAIT)
        yield bus, process
    finally:
        if process is not None:
            stop(process)


@contextmanager
def cpu_hogs(count: int) -> Iterator[list[subprocess.Popen]]:
    """``count`` busy Python processes (``while True: pass``, normal priority) until the block ends."""
    hogs: list[subprocess.Popen] = []
    try:
        for _ in range(count):
            with sigint_after():  # a hog started is one the finally knows of
                hogs.append(subprocess.Popen([sys.executable, "-c", _HOG], stdout=subprocess.DEVNULL,
                                             stderr=subprocess.DEVNULL))
        time.sleep(0.2)  # let them reach the loop
        yield hogs
    finally:
        for hog in hogs:
            hog.kill()
        for hog in hogs:
            hog.wait(10)
