"""Shared fixtures and helpers of the simulated-drive tests (import what a test module uses)."""

from __future__ import annotations

import itertools
import os
import pathlib
import signal
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator

import can
import pytest

from sim_drive.canopen.slave import CanopenSimDrive
from drives.cia402 import Command

REPO = pathlib.Path(__file__).resolve().parents[1]
_counter = itertools.count()
NODE = 5
WAIT = 1.0  # s: the longest any single frame is waited for (a bound, not a pace)


def unique_name(prefix: str) -> str:
    """A channel name no other test in this process uses."""
    return f"{prefix}-{os.getpid()}-{next(_counter)}"


def unique_multicast() -> tuple[str, int]:
    """A multicast group and port unique to this test (the port keeps groups apart on Linux)."""
    n = next(_counter)
    return f"239.74.{163 + (os.getpid() % 64)}.{1 + n % 250}", 43200 + (os.getpid() % 400) * 40 + n % 40


@pytest.fixture
def channel() -> str:
    """A fresh virtual-bus channel name."""
    return unique_name("sim")


@pytest.fixture
def master(channel: str) -> Iterator[can.BusABC]:
    """A raw python-can bus on ``channel``: the test plays the master frame by frame."""
    bus = can.Bus(interface="virtual", channel=channel)
    yield bus
    bus.shutdown()


@pytest.fixture
def sim(channel: str, master: can.BusABC) -> Iterator[CanopenSimDrive]:
    """A started simulated drive, node 5, on ``channel`` (the master bus exists first)."""
    drive = CanopenSimDrive({"interface": "virtual", "channel": channel}, NODE)
    drive.start()
    yield drive
    drive.stop()


def recv_id(bus: can.BusABC, can_id: int, timeout: float = WAIT) -> can.Message | None:
    """The next frame with ``can_id`` within ``timeout`` s (others are skipped), or None."""
    end = time.monotonic() + timeout
    while (left := end - time.monotonic()) > 0:
        message = bus.recv(left)
        if message is not None and message.arbitration_id == can_id:
            return message
    return None


def drain(bus: can.BusABC) -> None:
    """Drop every frame already queued on ``bus`` (bounded by what is there now)."""
    for _ in range(10_000):
        if bus.recv(0.0) is None:
            return


def send(bus: can.BusABC, can_id: int, data: bytes | list[int] = b"") -> None:
    """Send one standard frame."""
    bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))


def nmt_start(bus: can.BusABC, node: int = NODE) -> None:
    """NMT start remote node."""
    send(bus, 0x000, [0x01, node])


def sdo_write(bus: can.BusABC, index: int, subindex: int, value: int, size: int, node: int = NODE) -> bytes:
    """An expedited SDO download by hand; returns the server's 8-byte answer."""
    command = 0x23 | (4 - size) << 2
    data = struct.pack("<BHB", command, index, subindex) + value.to_bytes(size, "little", signed=value < 0).ljust(4, b"\0")
    send(bus, 0x600 + node, data)
    answer = recv_id(bus, 0x580 + node)
    assert answer is not None, f"no SDO answer writing 0x{index:04X}:{subindex}"
    return bytes(answer.data)


def enable_cst(bus: can.BusABC, node: int = NODE) -> None:
    """Mode CST and SHUTDOWN, SWITCH ON, ENABLE OPERATION by SDO (node already OPERATIONAL)."""
    assert sdo_write(bus, 0x6060, 0, 10, 1, node)[0] == 0x60
    for command in (Command.SHUTDOWN, Command.SWITCH_ON, Command.ENABLE_OPERATION):
        assert sdo_write(bus, 0x6040, 0, command.word, 2, node)[0] == 0x60


class SimProcess:
    """``python -m sim_drive ARGS`` as a subprocess, its log (stderr) in a file that cannot fill up."""

    def __init__(self, *args: str) -> None:
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
        self._log = tempfile.TemporaryFile(mode="w+")
        self.process = subprocess.Popen(
            [sys.executable, "-m", "sim_drive", *args], cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=self._log, text=True
        )

    def stop(self, sig: signal.Signals = signal.SIGTERM, timeout: float = 10.0) -> tuple[int, str]:
        """Send ``sig``, bounded wait; the exit status and the log.  A hang fails the test."""
        if self.process.poll() is None:
            self.process.send_signal(sig)
        try:
            self.process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout=timeout)
            pytest.fail(f"simulated drive did not stop on {sig.name} within {timeout} s")
        self._log.seek(0)
        return self.process.returncode, self._log.read()


VCAN0_MISSING = pytest.mark.skipif(
    not pathlib.Path("/sys/class/net/vcan0").exists(),
    reason="SocketCAN vcan0 does not exist on this kernel "
    "(create it with: modprobe vcan; ip link add dev vcan0 type vcan; ip link set up vcan0)",
)
