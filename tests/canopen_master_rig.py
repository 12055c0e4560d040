"""Test rig for the CANopen master: a simulated drive (in process or as a subprocess) plus the master.

Only loopback networking: python-can's ``virtual`` bus (one process), ``udp_multicast`` on
the local host (a unique port per rig, so concurrent runs do not hear each other: the
socket binds to the port on any address, so the multicast group alone does not isolate),
and SocketCAN ``vcan0`` where the kernel has it.  Every wait is bounded in time.
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import can
import pytest

from drives.canopen.drive import CanopenDrive
from drives.safety import SafetySettings
from sim_drive.eds import eds_path
from tests.sim_fixtures import VCAN0_MISSING

REPO = Path(__file__).resolve().parents[1]
NODE_ID = 5
UDP_GROUP = "239.74.163.2"
HEARTBEAT_WAIT = 15.0  # s: the simulator subprocess imports numpy/scipy/canopen first


INTERFACE_PARAMS = [
    pytest.param("virtual", id="virtual-1-process"),
    pytest.param("udp_multicast", id="udp_multicast-2-processes"),
    pytest.param(
        "socketcan",
        id="vcan0-2-processes",
        marks=VCAN0_MISSING,
    ),
]


@dataclass
class BusSpec:
    """How both ends open the same bus."""

    interface: str
    channel: str
    extra: dict[str, Any] = field(default_factory=dict)

    def open(self) -> can.BusABC:
        """A new bus handle on this bus (a sniffer, an injector)."""
        return can.Bus(interface=self.interface, channel=self.channel, **self.extra)

    def drive_kwargs(self) -> dict[str, Any]:
        """The CanopenDrive keyword arguments selecting this bus."""
        return {"interface": self.interface, "channel": self.channel, "bus_kwargs": dict(self.extra)}


def new_bus_spec(interface: str) -> BusSpec:
    """A bus of ``interface`` not shared with any other test (unique channel or port)."""
    if interface == "virtual":
        return BusSpec("virtual", f"master-test-{uuid.uuid4().hex[:12]}")
    if interface == "udp_multicast":
        return BusSpec("udp_multicast", UDP_GROUP, {"port": random.randint(45000, 55000)})
    if interface == "socketcan":
        return BusSpec("socketcan", "vcan0")
    raise ValueError(interface)


class SimProcess:
    """``python -m sim_drive`` as a subprocess on ``spec``; stopped with SIGTERM."""

    def __init__(self, spec: BusSpec, node_id: int, timing: str) -> None:
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
        self.args = [
            sys.executable, "-m", "sim_drive",
            "--interface", spec.interface, "--channel", spec.channel,
            "--node-id", str(node_id), "--timing", timing,
        ]
        for key, value in spec.extra.items():
            self.args += ["--bus-option", f"{key}={value}"]
        self._log = tempfile.TemporaryFile(mode="w+")  # a file, not a pipe: it cannot fill up and block
        self.process = subprocess.Popen(self.args, cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=self._log)

    def stop(self) -> tuple[int, str]:
        """SIGTERM, bounded wait (then SIGKILL); the exit status and the log."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout=10)
        self._log.seek(0)
        return self.process.returncode, self._log.read()


def wait_for_heartbeat(spec: BusSpec, node_id: int, timeout: float, process: SimProcess | None = None) -> None:
    """Block until node ``node_id``'s heartbeat is seen on ``spec`` (bounded by ``timeout`` s)."""
    deadline = time.monotonic() + timeout
    with spec.open() as bus:
        while time.monotonic() < deadline:
            if process is not None and process.process.poll() is not None:
                _, err = process.stop()
                raise AssertionError(f"simulator exited early ({process.process.returncode}): {err[-2000:]}")
            msg = bus.recv(0.1)
            if msg is not None and msg.arbitration_id == 0x700 + node_id:
                return
    raise AssertionError(f"no heartbeat of node {node_id} within {timeout} s on {spec}")


@dataclass
class Rig:
    """A connected master, the bus it is on, and (in process only) the simulator object."""

    drive: CanopenDrive
    spec: BusSpec
    sim: Any = None  # sim_drive.canopen.slave.CanopenSimDrive when in process
    process: SimProcess | None = None


@contextmanager
def rig(
    interface: str = "virtual", timing: str = "ideal", node_id: int = NODE_ID, connect: bool = True, **drive_kwargs: Any
) -> Iterator[Rig]:
    """A simulated drive and a master on a fresh bus of ``interface``; everything stopped on exit."""
    spec = new_bus_spec(interface)
    sim = process = None
    if interface == "virtual":
        from sim_drive.canopen.slave import CanopenSimDrive

        sim = CanopenSimDrive({"interface": "virtual", "channel": spec.channel}, node_id, timing=timing).start()
    else:
        process = SimProcess(spec, node_id, timing)
        wait_for_heartbeat(spec, node_id, HEARTBEAT_WAIT, process)
    drive_kwargs.setdefault("eds", eds_path())
    # A test paces nothing: a loaded machine may pause it for tens of ms, which the drive's
    # RPDO deadline would rightly call a dead master.  Tests of the deadline set their own.
    drive_kwargs.setdefault("safety", SafetySettings().for_virtual_time(drive_kwargs.get("period", 1e-3)))
    drive = CanopenDrive(node_id, **spec.drive_kwargs(), **drive_kwargs)
    status = None
    try:
        if connect:
            drive.connect()
        yield Rig(drive, spec, sim, process)
    finally:
        drive.close()
        if sim is not None:
            sim.stop()
        if process is not None:
            status = process.stop()
    if status is not None and status[0] != 0:  # reached only when the test body passed
        raise AssertionError(f"simulator did not exit cleanly on SIGTERM (status {status[0]}): {status[1][-2000:]}")
