"""A simulated multi-axis device opens its bus once (sim_drive.canopen.bridge): the nodes sit on an
in-process lock-step channel, one bridge thread joins it to the bus.  Over udp_multicast, where every
socket gets every datagram back, its own included: each node answers one SYNC once, and a frame a
node sent is not handed back to the nodes as if another had sent it."""

from __future__ import annotations

import os
import random
import time

import can

from drives.bus_config import open_bus
from drives.lockstep_bus import LockstepBus
from sim_drive.canopen.multi_axis import MultiAxisSim
from sim_drive.parameters import DeviceParameters, Timing

NODES = (5, 6, 7)
WINDOW = 0.5  # s: frames collected after one SYNC (the nodes answer within milliseconds)


def _frames(bus: can.BusABC, seconds: float) -> list[can.Message]:
    """Every frame within ``seconds`` (bounded in time and count)."""
    deadline, seen = time.monotonic() + seconds, list[can.Message]()
    while time.monotonic() < deadline and len(seen) < 1000:
        message = bus.recv(0.05)
        if message is not None:
            seen.append(message)
    return seen


def test_three_nodes_answer_a_sync_once_each_through_one_bridge() -> None:
    bus = {"interface": "udp_multicast", "channel": f"239.74.{180 + os.getpid() % 40}.{1 + random.randrange(250)}",
           "port": random.randint(45000, 55000)}
    sim = MultiAxisSim(bus, [(node, DeviceParameters(), Timing.CIA402) for node in NODES])
    assert sim._bridge is not None  # udp_multicast is bridged (a lock-step bus would be joined directly)
    with open_bus(**bus) as master, sim, LockstepBus(sim._bridge.channel) as inside:  # what the nodes hear
        _frames(master, 0.3)  # the boot-ups
        master.send(can.Message(arbitration_id=0x000, data=[0x01, 0], is_extended_id=False))  # NMT start, every node
        _frames(master, 0.2)
        master.send(can.Message(arbitration_id=0x080, data=[], is_extended_id=False))  # one SYNC
        answered = [m.arbitration_id for m in _frames(master, WINDOW) if 0x181 <= m.arbitration_id <= 0x1FF]
        synced = [node.drive.sync_count for node in sim.nodes]
        heard = [m.arbitration_id for m in _frames(inside, 0.1) if 0x181 <= m.arbitration_id <= 0x1FF]
    assert sorted(answered) == [0x180 + node for node in NODES]  # on the bus: TPDO1 of each node, once
    assert synced == [1, 1, 1]
    # on the channel each TPDO once, from its node: its echo from the bus was not handed back in
    assert sorted(heard) == [0x180 + node for node in NODES]
