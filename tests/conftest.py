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
    A TCP port (``int``) free on 127.0.0.1 when the test starts (for a server the test starts).
``refusing_port``
    A TCP port (``int``) on 127.0.0.1 that refuses connections for the whole test (a server not there).
``canopen_rig``
    A factory: ``canopen_rig(interface="virtual", timing="ideal", node_id=5, connect=True,
    **drive_kwargs)`` is a context manager yielding a :class:`Rig` -- a (connected) CANopen
    master ``drive`` on a fresh bus ``spec`` with the simulated drive in process (``sim``,
    ``virtual``, or ``lockstep``: the drive serves each frame in the sender's thread, so a test
    that cycles runs in one thread, deterministically) or as a ``python -m sim_drive``
    subprocess (``process``, the other interfaces, its heartbeat awaited first).  Everything is
    stopped on exit; a subprocess that does not exit with status 0 on SIGTERM fails the test.

From the project's pytest plugin, :mod:`haptic_bus.testing` (loaded by ``-p haptic_bus.testing``
in pyproject.toml's ``addopts``, under the name of the ``pytest11`` entry point every user gets):
``sim_process`` (``python -m sim_drive ARGS`` as a subprocess, stopped at teardown), ``bus_spec``
(a :class:`BusSpec` of ``"virtual"``, ``"lockstep"``, ``"udp_multicast"`` or ``"socketcan"``
that no other test shares), ``haptic_sim`` (the simulated drive on a private bus, which
``canopen_rig`` starts its simulator with), ``haptic_controller`` and ``recorded_run``.

Markers: ``vcan0`` skips a test (or a ``pytest.param`` case) where SocketCAN ``vcan0`` does not
exist on this kernel.

The project's own modules (``drives``, ``sim_drive``) are imported inside the fixtures, not at
the top: this file is loaded for every test module, and a module that cannot be imported must
fail only the tests that use it (the plugin imports only the standard library and pytest).

One BLAS thread per process (``OPENBLAS_NUM_THREADS=1`` unless the environment says otherwise, set
before numpy is first imported, inherited by the child processes): the suite runs two or three
processes on two cores (``-n``), where BLAS's own threads only spin.  Measured beside the same
load: tests/test_identify_fit.py 11.6 -> 8.8 s of CPU, five numpy-heavy files together 26.8 ->
22.2 s, their wall clock no longer.

Ctrl-C reaches the child processes the tests interrupt: a shell without job control starts a
background job (``pytest ... &``, ``setsid``) with SIGINT ignored, which every child would inherit
(an ignored signal stays ignored across ``exec``), and the tests that send SIGINT would fail (7 did,
started so).  The suite's process takes Python's default handler back, which ``exec`` resets to the
default action in each child.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import json
import logging
import pathlib
import signal
import socket
import struct
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import can
import canopen
import hypothesis
import pytest

from haptic_bus.testing.buses import VCAN0_REASON, BusSpec, unique_multicast, unique_name, vcan0_exists
from haptic_bus.testing.buses import new_bus_spec as new_bus_spec  # re-exported: test modules import these from here
from haptic_bus.testing.buses import wait_for_heartbeat as wait_for_heartbeat
from haptic_bus.testing.processes import SimProcess
from haptic_bus.testing.simulated import HEARTBEAT_WAIT as HEARTBEAT_WAIT
from haptic_bus.testing.simulated import SimDriveNode

if TYPE_CHECKING:
    from drives.canopen.drive import CanopenDrive
    from sim_drive.canopen.slave import CanopenSimDrive

# This machine's environment sets PYTHONDONTWRITEBYTECODE=1, so every process of the suite (each
# xdist worker's collection, each command and simulated drive a test starts) would
# compile the project's 200 modules again, and pytest would rewrite every test module's asserts
# again: measured 21 s of CPU per collection without the cache and 10 s with it, and 0.2 s per
# command.  The suite keeps its bytecode in the tree's __pycache__ folders (git ignores them),
# for itself and for the processes it starts (they inherit this environment).
sys.dont_write_bytecode = False
os.environ.pop("PYTHONDONTWRITEBYTECODE", None)

NODE = 5  # the node of ``sim``, of ``remote`` and of ``canopen_rig`` by default
WAIT = 1.0  # s: the longest any single frame is waited for (a bound, not a pace)
# s: how long a master in a test waits for each SDO answer.  canopen's 0.3 s was outlasted twice in CI
# runs (the simulator's thread, in the test's own process, waiting for one of 2 cores that the
# suite's 3 workers share); 2 s still names a drive that never answers, at one SDO's cost.
SDO_WAIT = 2.0
FILE_COSTS = pathlib.Path(__file__).parent / "data" / "file_costs.json"  # s of wall clock per test file (its "how")


# Hypothesis: a small default profile for the README's test command, a thorough one for a long run
# (``python -m pytest --hypothesis-profile thorough``); a test that sets its own count keeps it.
hypothesis.settings.register_profile("default", max_examples=100, deadline=None)
hypothesis.settings.register_profile("thorough", max_examples=2000, deadline=None)
hypothesis.settings.load_profile("default")


def pytest_configure(config: pytest.Config) -> None:
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:  # started in the background (the docstring)
        signal.signal(signal.SIGINT, signal.default_int_handler)
    config.addinivalue_line("markers", "vcan0: needs the SocketCAN interface vcan0 (skipped where the kernel has none)")
    if not hasattr(config, "workerinput") and (config.getoption("numprocesses", None) or 0):  # xdist's controller
        from tests.bytecode_warmup import warm

        warm(config, pathlib.Path(__file__).resolve().parents[1])  # once, before the workers start (its docstring)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    # The longest files first, so that on pytest-xdist's workers they start at once and the
    # short ones fill in around them, instead of one long file starting late and leaving the other
    # workers idle at the end (longest processing time first, a makespan within 4/3 of the best).
    # pyproject's addopts deal the files to the workers one at a time in this order (--dist loadfile
    # --no-loadscope-reorder), a file's module-scoped fixture set up on one worker only.  Each
    # file's cost is the wall clock its tests took in one measured run of the suite (FILE_COSTS: how
    # it was measured, and how to measure it again); a file it does not list costs 0 and keeps its
    # place after them.  Within a file (and among the unlisted ones) the slow-marked tests come
    # first; the sort is stable, so otherwise the collection order stands.
    costs: dict[str, float] = json.loads(FILE_COSTS.read_text())["seconds"]
    items.sort(key=lambda item: (-costs.get(item.nodeid.split("::", 1)[0], 0.0), item.get_closest_marker("slow") is None))
    if vcan0_exists():
        return
    skip = pytest.mark.skip(reason=VCAN0_REASON)
    for item in items:
        if item.get_closest_marker("vcan0") is not None:
            item.add_marker(skip)


# ----------------------------------------------------------------------------- logging
@pytest.fixture(autouse=True)
def _root_logger_as_found() -> Iterator[None]:
    """A command run in-process configures logging as its process would (``haptic-bus`` and
    ``haptic-bus sim`` call ``basicConfig(force=True)``: a stderr handler, the sim's at INFO); after the
    test the root logger's level is what it was and those handlers are gone, so a later test's stderr
    holds only its own lines (test_upload_messages read the sim's INFO lines after test_sim_cli had
    run on the same worker)."""
    from haptic_bus.console import StderrHandler

    root = logging.getLogger()
    level = root.level
    yield
    root.setLevel(level)
    for handler in [handler for handler in root.handlers if isinstance(handler, StderrHandler)]:
        root.removeHandler(handler)


# ----------------------------------------------------------------------------- unique buses
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
def refusing_port() -> Iterator[int]:
    """A TCP port on 127.0.0.1 where nothing listens for the whole test: bound by it, never listening
    (a connection is refused), so that no server of a test beside it takes the port meanwhile (one
    found free and let go was, once, by another xdist worker's Modbus server)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        yield int(sock.getsockname()[1])


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
    """canopen's RemoteNode for node 5 (shipped EDS) on ``channel``, waiting :data:`SDO_WAIT` for an answer
    (canopen's own 0.3 s: an in-process drive starved by the suite's other workers missed it)."""
    from sim_drive.eds import eds_path

    network = canopen.Network()
    network.connect(interface="virtual", channel=channel)
    node = canopen.RemoteNode(NODE, str(eds_path()))
    node.sdo.RESPONSE_TIMEOUT = SDO_WAIT
    network.add_node(node)
    yield node
    network.disconnect()


# ----------------------------------------------------------------------------- the CANopen master rig
@dataclass
class Rig:
    """A connected master, the bus it is on, and (in process only) the simulator object."""

    drive: CanopenDrive
    spec: BusSpec
    sim: CanopenSimDrive | None = None  # in process (virtual) only
    process: SimProcess | None = None  # a subprocess (the other interfaces) only


@contextmanager
def _rig(
    haptic_sim: Callable[..., SimDriveNode],
    interface: str = "virtual",
    timing: str = "ideal",
    node_id: int = NODE,
    connect: bool = True,
    **drive_kwargs: Any,
) -> Iterator[Rig]:
    """A simulated drive (the plugin's ``haptic_sim``) and a master on a fresh bus of ``interface``;
    everything stopped on exit."""
    from drives.canopen.drive import CanopenDrive
    from drives.safety import VIRTUAL_TIME_CANOPEN_PATIENCE, SafetySettings
    from sim_drive.eds import eds_path

    node = haptic_sim(interface=interface, timing=timing, node_id=node_id)
    drive_kwargs.setdefault("eds", eds_path())
    # A test paces nothing: a loaded machine may pause it for tens of ms, which the drive's
    # RPDO deadline would rightly call a dead master.  Tests of the deadline set their own.
    drive_kwargs.setdefault("safety", SafetySettings().for_virtual_time(drive_kwargs.get("period", 1e-3)))
    # The same pause can hold the simulator's thread past the master's 50 ms TPDO wait (measured
    # once in a CI run beside two CPU-bound jobs); 0.25 s, as the multi-axis rig waits, where the
    # drive's watchdogs allow as much (a test of real-time watchdogs: half their shortest stall).
    period = drive_kwargs.get("period", 1e-3)
    # The simulator's heartbeat thread waits for the same turn: 328 ms without a beat, against the master's
    # default consumer time of 300 ms, was seen in a -n 3 run on this 2-core machine.  Nothing paces a
    # test, so the master listens with the patience of virtual time (tests of heartbeat loss set their own).
    drive_kwargs.setdefault("heartbeat_consumer_ms", VIRTUAL_TIME_CANOPEN_PATIENCE["heartbeat_consumer_ms"])
    drive_kwargs.setdefault("sdo_timeout", SDO_WAIT)
    drive_kwargs.setdefault("tpdo_timeout", min(0.25, drive_kwargs["safety"].canopen_stall(period) / 2.0))
    drive = CanopenDrive(node_id, **node.spec.drive_kwargs(), **drive_kwargs)
    status = None
    try:
        if connect:
            drive.connect()
        yield Rig(drive, node.spec, node.sim, node.process)
    finally:
        drive.close()
        status = node.stop()
    if status is not None and status[0] != 0:  # reached only when the test body passed
        raise AssertionError(f"simulator did not exit cleanly on SIGTERM (status {status[0]}): {status[1][-2000:]}")


@pytest.fixture
def canopen_rig(haptic_sim: Callable[..., SimDriveNode]) -> Callable[..., AbstractContextManager[Rig]]:
    """``canopen_rig(interface="virtual", timing="ideal", node_id=5, connect=True, **drive_kwargs)``:
    a context manager yielding a :class:`Rig`, everything stopped on exit."""

    def make(
        interface: str = "virtual", timing: str = "ideal", node_id: int = NODE, connect: bool = True, **drive_kwargs: Any
    ) -> AbstractContextManager[Rig]:
        return _rig(haptic_sim, interface, timing, node_id, connect, **drive_kwargs)

    return make
