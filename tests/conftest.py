"""Shared rigs of the bus tests, as pytest fixtures (no test module imports another).

Only loopback networking: python-can's ``virtual`` bus (one process), ``udp_multicast`` on the
local host (a unique port per test, so concurrent runs do not hear each other: the socket binds
to the port on any address, so the multicast group alone does not isolate), Modbus TCP on
127.0.0.1, and SocketCAN ``vcan0`` where the kernel has it.  Every wait is bounded in time.

Fixtures:

``channel``
    A fresh virtual-bus channel name (``str``), not used by any other test of this process.
``master``
    A raw python-can bus (``can.BusABC``) on ``channel``: the test plays the master frame by
    frame.  Shut down after the test.
``sim``
    A started in-process simulated drive (``CanopenSimDrive``), node ``NODE`` (5), on
    ``channel``; the ``master`` bus exists first.  Stopped after the test.
``remote``
    canopen's own ``RemoteNode`` for node 5 with the shipped EDS on ``channel`` (an independent
    SDO/PDO/NMT client).  Its network is disconnected after the test.
``frames``
    A :class:`Frames` object: ``send``, ``recv_id``, ``drain``, ``nmt_start``, ``sdo_write`` and
    ``enable_cst`` on any python-can bus (first argument), plus ``node`` (5, the node of ``sim``)
    and ``wait`` (1 s, the longest any single frame is waited for).
``multicast``
    A ``(group, port)`` for ``udp_multicast`` unique to this test.
``free_port``
    A TCP port (``int``) free on 127.0.0.1 when the test starts.
``sim_process``
    A factory: ``sim_process(*args)`` starts ``python -m sim_drive ARGS`` and returns a
    :class:`SimProcess` (its stderr log in a file that cannot fill up; ``stop(sig, timeout)``,
    ``wait_for_line(text, timeout)``, ``log()``).  Every process it started and the test did not
    stop is stopped at teardown (SIGTERM, bounded wait, then SIGKILL).
``bus_spec``
    A factory: ``bus_spec(interface)`` is a :class:`BusSpec` of ``"virtual"``, ``"lockstep"``,
    ``"udp_multicast"`` or ``"socketcan"`` that no other test shares (``open()`` gives a bus
    handle, ``drive_kwargs()`` the ``CanopenDrive`` keywords).
``canopen_rig``
    A factory: ``canopen_rig(interface="virtual", timing="ideal", node_id=5, connect=True,
    **drive_kwargs)`` is a context manager yielding a :class:`Rig` -- a (connected) CANopen
    master ``drive`` on a fresh bus ``spec`` with the simulated drive in process (``sim``,
    ``virtual``, or ``lockstep``: the drive serves each frame in the sender's thread, so a test
    that cycles runs in one thread, deterministically) or as a ``python -m sim_drive``
    subprocess (``process``, the other interfaces, its heartbeat awaited first).  Everything is
    stopped on exit; a subprocess that does not exit with status 0 on SIGTERM fails the test.

Markers: ``vcan0`` skips a test (or a ``pytest.param`` case) where SocketCAN ``vcan0`` does not
exist on this kernel.

The project's own modules (``drives``, ``sim_drive``) are imported inside the fixtures, not at
the top: this file is loaded for every test module, and a module that cannot be imported must
fail only the tests that use it.
"""

from __future__ import annotations

import itertools
import os
import pathlib
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import can
import canopen
import pytest

if TYPE_CHECKING:
    from drives.canopen.drive import CanopenDrive
    from sim_drive.canopen.slave import CanopenSimDrive

REPO = pathlib.Path(__file__).resolve().parents[1]
NODE = 5  # the node of ``sim``, of ``remote`` and of ``canopen_rig`` by default
WAIT = 1.0  # s: the longest any single frame is waited for (a bound, not a pace)
HEARTBEAT_WAIT = 15.0  # s: the simulator subprocess imports numpy/scipy/canopen first
STOP_WAIT = 10.0  # s: the longest a simulator subprocess is given to exit on a signal
VCAN0_REASON = (
    "SocketCAN vcan0 does not exist on this kernel "
    "(create it with: modprobe vcan; ip link add dev vcan0 type vcan; ip link set up vcan0)"
)
_counter = itertools.count()


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "vcan0: needs the SocketCAN interface vcan0 (skipped where the kernel has none)")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if pathlib.Path("/sys/class/net/vcan0").exists():
        return
    skip = pytest.mark.skip(reason=VCAN0_REASON)
    for item in items:
        if item.get_closest_marker("vcan0") is not None:
            item.add_marker(skip)


# ----------------------------------------------------------------------------- unique buses
def unique_name(prefix: str) -> str:
    """A channel name no other test in this process uses (the pid keeps concurrent runs apart)."""
    return f"{prefix}-{os.getpid()}-{next(_counter)}"


def unique_multicast() -> tuple[str, int]:
    """A multicast group and port unique to this test (the port keeps groups apart on Linux)."""
    n = next(_counter)
    return f"239.74.{163 + (os.getpid() % 64)}.{1 + n % 250}", 43200 + (os.getpid() % 400) * 40 + n % 40


@dataclass
class BusSpec:
    """How both ends open the same bus."""

    interface: str
    channel: str
    extra: dict[str, Any] = field(default_factory=dict)

    def open(self) -> can.BusABC:
        """A new bus handle on this bus (a sniffer, an injector), configured as the project's own buses are."""
        from drives.bus_config import open_bus

        return open_bus(interface=self.interface, channel=self.channel, **self.extra)

    def drive_kwargs(self) -> dict[str, Any]:
        """The CanopenDrive keyword arguments selecting this bus."""
        return {"interface": self.interface, "channel": self.channel, "bus_kwargs": dict(self.extra)}

    def sim_args(self) -> list[str]:
        """The ``python -m sim_drive`` arguments selecting this bus."""
        args = ["--interface", self.interface, "--channel", self.channel]
        for key, value in self.extra.items():
            args += ["--bus-option", f"{key}={value}"]
        return args


def new_bus_spec(interface: str) -> BusSpec:
    """A bus of ``interface`` not shared with any other test (unique channel or port)."""
    if interface in ("virtual", "lockstep"):
        return BusSpec(interface, unique_name("master-test"))
    if interface == "udp_multicast":
        group, port = unique_multicast()
        return BusSpec("udp_multicast", group, {"port": port})
    if interface == "socketcan":
        return BusSpec("socketcan", "vcan0")
    raise ValueError(interface)


@pytest.fixture
def channel() -> str:
    """A fresh virtual-bus channel name."""
    return unique_name("sim")


@pytest.fixture
def multicast() -> tuple[str, int]:
    """A udp_multicast (group, port) unique to this test."""
    return unique_multicast()


@pytest.fixture
def free_port() -> int:
    """A TCP port free on 127.0.0.1 now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@pytest.fixture
def bus_spec() -> Callable[[str], BusSpec]:
    """``bus_spec(interface)``: a BusSpec no other test shares."""
    return new_bus_spec


# ----------------------------------------------------------------------------- frames by hand
class Frames:
    """Frame-level helpers for a test that plays the CANopen master on a raw python-can bus."""

    node = NODE
    wait = WAIT

    def recv_id(self, bus: can.BusABC, can_id: int, timeout: float = WAIT) -> can.Message | None:
        """The next frame with ``can_id`` within ``timeout`` s (others are skipped), or None."""
        end = time.monotonic() + timeout
        while (left := end - time.monotonic()) > 0:
            message = bus.recv(left)
            if message is not None and message.arbitration_id == can_id:
                return message
        return None

    def drain(self, bus: can.BusABC) -> None:
        """Drop every frame already queued on ``bus`` (bounded by what is there now)."""
        for _ in range(10_000):
            if bus.recv(0.0) is None:
                return

    def send(self, bus: can.BusABC, can_id: int, data: bytes | list[int] = b"") -> None:
        """Send one standard frame."""
        bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))

    def nmt_start(self, bus: can.BusABC, node: int = NODE) -> None:
        """NMT start remote node."""
        self.send(bus, 0x000, [0x01, node])

    def sdo_write(self, bus: can.BusABC, index: int, subindex: int, value: int, size: int, node: int = NODE) -> bytes:
        """An expedited SDO download by hand; returns the server's 8-byte answer."""
        command = 0x23 | (4 - size) << 2
        data = struct.pack("<BHB", command, index, subindex) + value.to_bytes(size, "little", signed=value < 0).ljust(4, b"\0")
        self.send(bus, 0x600 + node, data)
        answer = self.recv_id(bus, 0x580 + node)
        assert answer is not None, f"no SDO answer writing 0x{index:04X}:{subindex}"
        return bytes(answer.data)

    def enable_cst(self, bus: can.BusABC, node: int = NODE) -> None:
        """Mode CST and SHUTDOWN, SWITCH ON, ENABLE OPERATION by SDO (node already OPERATIONAL)."""
        from drives.cia402 import Command

        assert self.sdo_write(bus, 0x6060, 0, 10, 1, node)[0] == 0x60
        for command in (Command.SHUTDOWN, Command.SWITCH_ON, Command.ENABLE_OPERATION):
            assert self.sdo_write(bus, 0x6040, 0, command.word, 2, node)[0] == 0x60


@pytest.fixture
def frames() -> Frames:
    """Send/receive helpers for raw python-can buses (see :class:`Frames`)."""
    return Frames()


# ----------------------------------------------------------------------------- in-process rigs
@pytest.fixture
def master(channel: str) -> Iterator[can.BusABC]:
    """A raw python-can bus on ``channel``: the test plays the master frame by frame."""
    bus = can.Bus(interface="virtual", channel=channel)
    yield bus
    bus.shutdown()


@pytest.fixture
def sim(channel: str, master: can.BusABC) -> Iterator[CanopenSimDrive]:
    """A started simulated drive, node 5, on ``channel`` (the master bus exists first)."""
    from sim_drive.canopen.slave import CanopenSimDrive

    drive = CanopenSimDrive({"interface": "virtual", "channel": channel}, NODE)
    drive.start()
    yield drive
    drive.stop()


@pytest.fixture
def remote(channel: str) -> Iterator[canopen.RemoteNode]:
    """canopen's RemoteNode for node 5 (shipped EDS) on ``channel``."""
    from sim_drive.eds import eds_path

    network = canopen.Network()
    network.connect(interface="virtual", channel=channel)
    node = canopen.RemoteNode(NODE, str(eds_path()))
    network.add_node(node)
    yield node
    network.disconnect()


# ----------------------------------------------------------------------------- subprocesses
class SimProcess:
    """``python -m sim_drive ARGS`` as a subprocess, its log (stderr) in a file that cannot fill up."""

    def __init__(self, *args: str) -> None:
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
        self.args = [sys.executable, "-m", "sim_drive", *args]
        self._log, path = tempfile.mkstemp(prefix="sim_drive-", suffix=".log")  # a file, not a pipe: it cannot fill up
        os.unlink(path)  # the descriptor keeps it; nothing is left behind
        self.process = subprocess.Popen(self.args, cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=self._log)

    def log(self) -> str:
        """Everything the process wrote to stderr so far (``pread``: the shared file offset does not move)."""
        return os.pread(self._log, os.fstat(self._log).st_size, 0).decode(errors="replace")

    def wait_for_line(self, text: str, timeout: float) -> str:
        """Block until the log contains ``text`` (bounded by ``timeout`` s); the log so far."""
        deadline = time.monotonic() + timeout
        while True:
            log = self.log()
            if text in log:
                return log
            if self.process.poll() is not None:
                raise AssertionError(f"simulator exited ({self.process.returncode}) before {text!r}: {log[-2000:]}")
            if time.monotonic() >= deadline:
                raise AssertionError(f"no {text!r} from the simulator within {timeout} s: {log[-2000:]}")
            time.sleep(0.02)

    def stop(self, sig: signal.Signals = signal.SIGTERM, timeout: float = STOP_WAIT) -> tuple[int, str]:
        """Send ``sig``, bounded wait; the exit status and the log.  A hang fails the test."""
        if self.process.poll() is None:
            self.process.send_signal(sig)
        try:
            self.process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout=timeout)
            pytest.fail(f"simulated drive did not stop on {sig.name} within {timeout} s")
        return self.process.returncode, self.log()

    def close(self) -> None:
        """Kill the process if it still runs (bounded wait) and drop the log."""
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait(timeout=STOP_WAIT)
        if self._log >= 0:
            os.close(self._log)
            self._log = -1


@pytest.fixture
def sim_process() -> Iterator[Callable[..., SimProcess]]:
    """``sim_process(*args)``: a started ``python -m sim_drive ARGS``; all stopped at teardown."""
    started: list[SimProcess] = []

    def start(*args: str) -> SimProcess:
        process = SimProcess(*args)
        started.append(process)
        return process

    yield start
    try:
        for process in started:
            if process.process.poll() is None:
                process.stop()
    finally:
        for process in started:
            process.close()


# ----------------------------------------------------------------------------- the CANopen master rig
@dataclass
class Rig:
    """A connected master, the bus it is on, and (in process only) the simulator object."""

    drive: CanopenDrive
    spec: BusSpec
    sim: CanopenSimDrive | None = None  # in process (virtual) only
    process: SimProcess | None = None  # a subprocess (the other interfaces) only


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


@contextmanager
def _rig(
    sim_process: Callable[..., SimProcess],
    interface: str = "virtual",
    timing: str = "ideal",
    node_id: int = NODE,
    connect: bool = True,
    **drive_kwargs: Any,
) -> Iterator[Rig]:
    """A simulated drive and a master on a fresh bus of ``interface``; everything stopped on exit."""
    from drives.canopen.drive import CanopenDrive
    from drives.safety import SafetySettings
    from sim_drive.canopen.slave import CanopenSimDrive
    from sim_drive.eds import eds_path

    spec = new_bus_spec(interface)
    sim = process = None
    if interface in ("virtual", "lockstep"):
        sim = CanopenSimDrive({"interface": interface, "channel": spec.channel}, node_id, timing=timing).start()
    else:
        process = sim_process(*spec.sim_args(), "--node-id", str(node_id), "--timing", timing)
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


@pytest.fixture
def canopen_rig(sim_process: Callable[..., SimProcess]) -> Callable[..., AbstractContextManager[Rig]]:
    """``canopen_rig(interface="virtual", timing="ideal", node_id=5, connect=True, **drive_kwargs)``:
    a context manager yielding a :class:`Rig`, everything stopped on exit."""

    def make(
        interface: str = "virtual", timing: str = "ideal", node_id: int = NODE, connect: bool = True, **drive_kwargs: Any
    ) -> AbstractContextManager[Rig]:
        return _rig(sim_process, interface, timing, node_id, connect, **drive_kwargs)

    return make
