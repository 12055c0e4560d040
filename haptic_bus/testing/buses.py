"""Private CAN buses for tests: a bus no other test shares, and how both ends open it.

``virtual`` and ``lockstep`` get a channel name unique to this process (the pid keeps
concurrent test runs apart); ``udp_multicast`` a group and a port of its own (on Linux a
socket bound to a port hears every group on that port unless ``IP_MULTICAST_ALL`` is off, so
the port is what isolates), probed free before it is handed out; ``socketcan`` is ``vcan0``,
where the kernel has it.  Every bus is opened through :func:`drives.bus_config.open_bus`, so a
udp_multicast bus has ``hop_limit=0``: its frames stay on this machine.

Only the standard library is imported at module level: this module is loaded with the pytest
plugin in every test session of an environment that has haptic_bus installed.
"""

from __future__ import annotations

import itertools
import os
import pathlib
import socket
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import can

    from haptic_bus.testing.processes import SimProcess

IN_PROCESS = ("virtual", "lockstep")  # the simulated drive runs in the test's process on these
# (drives.bus_config.IN_PROCESS_INTERFACES, spelled here since the plugin imports no project package; a test checks)
SUBPROCESS = ("udp_multicast", "socketcan")  # ... and as ``python -m sim_drive`` on these
INTERFACES = IN_PROCESS + SUBPROCESS
VCAN0 = pathlib.Path("/sys/class/net/vcan0")
VCAN0_REASON = (
    "SocketCAN vcan0 does not exist on this kernel "
    "(create it with: modprobe vcan; ip link add dev vcan0 type vcan; ip link set up vcan0)"
)
HEARTBEAT_COB_BASE = 0x700  # CiA 301: a node's heartbeat is COB-ID 0x700 + node id
PORT_TRIES = 40  # udp_multicast ports probed before giving up
_counter = itertools.count()


def vcan0_exists() -> bool:
    """True where this kernel has the SocketCAN interface ``vcan0``."""
    return VCAN0.exists()


def unique_name(prefix: str) -> str:
    """A channel name no other test in this process uses (the pid keeps concurrent runs apart)."""
    return f"{prefix}-{os.getpid()}-{next(_counter)}"


def _udp_port_free(port: int) -> bool:
    """True if no socket holds UDP ``port`` (python-can's multicast sockets set SO_REUSEADDR;
    a plain bind fails beside them)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.bind(("", port))
        except OSError:
            return False
    return True


def unique_multicast() -> tuple[str, int]:
    """A multicast group and a UDP port unique to this test (the port keeps groups apart on Linux)."""
    pid = os.getpid()
    for _ in range(PORT_TRIES):
        n = next(_counter)
        group, port = f"239.74.{163 + pid % 64}.{1 + n % 250}", 43200 + (pid % 400) * 40 + n % 40
        if _udp_port_free(port):
            return group, port
    raise RuntimeError(f"no free UDP port for a udp_multicast bus after {PORT_TRIES} tries")


@dataclass
class BusSpec:
    """How both ends open the same bus: python-can's ``interface``, ``channel`` and extra keywords."""

    interface: str
    channel: str
    extra: dict[str, Any] = field(default_factory=dict)

    def open(self) -> can.BusABC:
        """A new bus handle on this bus (a sniffer, an injector), configured as the project's own buses are."""
        from drives.bus_config import open_bus

        return open_bus(interface=self.interface, channel=self.channel, **self.extra)

    def config(self) -> dict[str, Any]:
        """The python-can keyword arguments of this bus (what ``haptic_bus.run_canopen`` takes)."""
        return {"interface": self.interface, "channel": self.channel, **self.extra}

    def drive_kwargs(self) -> dict[str, Any]:
        """The CanopenDrive keyword arguments selecting this bus."""
        return {"interface": self.interface, "channel": self.channel, "bus_kwargs": dict(self.extra)}

    def sim_args(self) -> list[str]:
        """The ``python -m sim_drive`` (and ``haptic-bus run``) arguments selecting this bus."""
        args = ["--interface", self.interface, "--channel", self.channel]
        for key, value in self.extra.items():
            args += ["--bus-option", f"{key}={value}"]
        return args


def new_bus_spec(interface: str) -> BusSpec:
    """A bus of ``interface`` (one of :data:`INTERFACES`) not shared with any other test."""
    if interface in IN_PROCESS:
        return BusSpec(interface, unique_name("master-test"))
    if interface == "udp_multicast":
        group, port = unique_multicast()
        return BusSpec("udp_multicast", group, {"port": port})
    if interface == "socketcan":
        return BusSpec("socketcan", "vcan0")
    raise ValueError(f"interface = {interface!r} is invalid; allowed: {', '.join(INTERFACES)}")


def wait_for_heartbeat(spec: BusSpec, node_id: int, timeout: float, process: SimProcess | None = None) -> None:
    """Block until node ``node_id``'s heartbeat is seen on ``spec`` (bounded by ``timeout`` s);
    AssertionError (with the simulator's log) if ``process`` exits first or nothing is heard."""
    deadline = time.monotonic() + timeout
    with spec.open() as bus:
        while time.monotonic() < deadline:
            if process is not None and process.process.poll() is not None:
                _, log = process.stop()
                raise AssertionError(f"simulator exited early ({process.process.returncode}): {log[-2000:]}")
            message = bus.recv(0.1)
            if message is not None and message.arbitration_id == HEARTBEAT_COB_BASE + node_id:
                return
    raise AssertionError(f"no heartbeat of node {node_id} within {timeout} s on {spec}")
