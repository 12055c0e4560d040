"""Frames stay on this host: every udp_multicast bus the project opens sends with hop limit 0.

python-can's udp_multicast defaults to ``hop_limit=1`` (IPv4 TTL 1), so every frame also goes
out of the network interface.  The project's bus configuration sets ``hop_limit=0`` whenever
the user names none.  Proven two ways: the socket's ``IP_MULTICAST_TTL`` read back on each path
that opens a bus (configuration, master, simulated drive, controller node), and the packets the
machine's non-loopback interfaces transmit around a run of 500 frames plus a simulator
subprocess started from its command line.
"""

from __future__ import annotations

import pathlib
import socket
import time

import can
import canopen
import pytest

from drives.bus_config import open_bus, resolve_bus_config
from drives.canopen.link import NOTIFIER_CYCLE
from tests.conftest import SDO_WAIT

FRAMES = 500
# A leak sends every one of the FRAMES frames out (plus the simulator's heartbeats); the machine's
# own traffic (0-2 packets a second idle, ~170 with other sessions talking to their services) is
# measured in an equal window just before and subtracted: what the frames add must stay far below FRAMES.
LEAK_ALLOWANCE = FRAMES // 2
# s: each window, the one before the frames and the one they are sent in (500 sends take ~20 ms); half a second
# holds ~85 packets of the machine's own traffic at its busiest, so what the windows differ by stays far below it
WINDOW = 0.5


def multicast_ttl(bus: can.BusABC) -> int:
    """The IPv4 multicast TTL of the socket a udp_multicast bus sends from (the project's bus sends from
    its own, :mod:`drives.udp_multicast`; python-can's from its receiving socket)."""
    sock = getattr(bus, "_sender", None) or bus._multicast._socket  # python-can 4.x: GeneralPurposeUdpMulticastBus
    return int(sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL))


def transmitted_packets() -> int:
    """Packets sent so far by every interface but loopback (``/proc/net/dev``)."""
    total = 0
    for line in pathlib.Path("/proc/net/dev").read_text().splitlines()[2:]:
        name, _, counters = line.partition(":")
        if name.strip() != "lo":
            total += int(counters.split()[9])
    return total


def test_the_configuration_keeps_udp_multicast_on_the_host(multicast: tuple[str, int]) -> None:
    group, port = multicast
    assert resolve_bus_config(interface="udp_multicast", channel=group, port=port)["hop_limit"] == 0
    assert resolve_bus_config(interface="udp_multicast", channel=group, port=port, hop_limit=3)["hop_limit"] == 3
    assert "hop_limit" not in resolve_bus_config(interface="virtual", channel="local")


def test_buses_the_project_opens_send_with_ttl_zero(multicast: tuple[str, int]) -> None:
    group, port = multicast
    with open_bus(interface="udp_multicast", channel=group, port=port) as bus:
        assert multicast_ttl(bus) == 0
    with open_bus(interface="udp_multicast", channel=group, port=port, hop_limit=2) as bridged:
        assert multicast_ttl(bridged) == 2  # a user who bridges machines says so


def test_master_and_simulator_send_with_ttl_zero(bus_spec) -> None:
    from drives.canopen.drive import CanopenDrive
    from sim_drive.canopen.slave import CanopenSimDrive
    from sim_drive.eds import eds_path

    spec = bus_spec("udp_multicast")
    sim = CanopenSimDrive({"interface": spec.interface, "channel": spec.channel, **spec.extra}, 5).start()
    drive = CanopenDrive(5, **spec.drive_kwargs(), eds=eds_path(), sdo_timeout=SDO_WAIT)
    try:
        assert multicast_ttl(sim._network.bus) == 0
        drive.connect()
        assert drive.link.bus is not None
        assert multicast_ttl(drive.link.bus) == 0
    finally:
        drive.close()
        sim.stop()


def test_the_controller_node_gets_ttl_zero_from_the_runners_configuration(bus_spec) -> None:
    """The runner hands ``resolve_bus_config(**bus)`` to canopen's ``Network.connect``, which
    passes it to ``can.Bus`` as it stands."""
    spec = bus_spec("udp_multicast")
    network = canopen.Network()
    network.NOTIFIER_CYCLE = NOTIFIER_CYCLE  # canopen's 1 s recv block made the disconnect wait up to 1 s
    network.connect(**resolve_bus_config(interface=spec.interface, channel=spec.channel, **spec.extra))
    try:
        assert multicast_ttl(network.bus) == 0
    finally:
        network.disconnect()


def test_no_frame_leaves_the_host(multicast: tuple[str, int], sim_process) -> None:
    if not any(line.partition(":")[0].strip() != "lo" for line in pathlib.Path("/proc/net/dev").read_text().splitlines()[2:]):
        pytest.skip("no network interface but loopback: nothing could leave the host")
    group, port = multicast
    sim = sim_process("--interface", "udp_multicast", "--channel", group, "--bus-option", f"port={port}",
                      "--node-id", "5")
    with open_bus(interface="udp_multicast", channel=group, port=port) as bus:
        deadline = time.monotonic() + 15.0
        while time.monotonic() < deadline:  # the simulator's boot-up or heartbeat: it is on the bus
            message = bus.recv(0.1)
            if message is not None and message.arbitration_id == 0x705:
                break
        else:
            pytest.fail(f"no heartbeat of the simulator within 15 s: {sim.log()[-1000:]}")
        idle = transmitted_packets()
        time.sleep(WINDOW)  # the simulator's heartbeats and the machine's own traffic, without our frames
        before = transmitted_packets()
        started = time.monotonic()
        for i in range(FRAMES):
            bus.send(can.Message(arbitration_id=0x7E0, data=i.to_bytes(2, "little"), is_extended_id=False))
        time.sleep(max(0.0, WINDOW - (time.monotonic() - started)))  # the simulator's heartbeats go on meanwhile
        sent = transmitted_packets() - before
    background = before - idle
    assert sent - background < LEAK_ALLOWANCE, \
        f"{sent} packets left through the network interface while {FRAMES} frames were sent ({background} in the second before)"
