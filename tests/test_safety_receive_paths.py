"""Issue 10's receive-path items, checked the way the issue's author found them.

- A 2-byte EMCY while the master cycles is a typed stop: torque zero, DISABLE VOLTAGE, the
  record kept (it used to raise ``struct.error`` out of ``read_inputs``).
- A burst of undecodable udp_multicast datagrams (DLC and data disagree, python-can raises
  ``CanOperationError`` for each) does not silence the simulated drive: it still answers SDO
  and beats.  More of them in a row than the drive's "the bus is gone" count, so the test
  fails if that count alone (not the time the bus keeps failing) decided.
- The controller node answers as a CANopen node: 0x1000, 0x1001, 0x1018, and abort 0x06090011
  for a sub-index on a single-value object (0x2000:1, 0x1001:1), read by canopen's SDO client.
"""

from __future__ import annotations

import dataclasses
import socket
import struct
import time
import uuid

import can
import canopen
import msgpack
import pytest

from drives.bus_config import open_bus
from drives.cia402 import State

NODE = 5
WAIT = 1.0  # s: the longest a single answer is waited for (a bound, not a pace)


def test_a_two_byte_emcy_while_cycling_stops_the_run_safely_with_a_typed_error(tmp_path) -> None:
    from haptic_bus.app.profiles import load_profile
    from haptic_bus.app.rig import simulated_canopen
    from haptic_bus.control.controller import WallController
    from haptic_bus.control.joints import encoder_origin
    from haptic_bus.control.scene import Wall
    from sim_drive.operator import ConstantPush

    profile = dataclasses.replace(load_profile("seed-ideal"), scene=(Wall("wall", 0.0, -1, 200.0, 100.0),))
    channel = f"short-emcy-{uuid.uuid4().hex[:10]}"
    with simulated_canopen(profile, operator=ConstantPush(1.0), channel=channel, interface="virtual") as (sim, drive):
        injector = can.Bus(interface="virtual", channel=channel)
        try:
            controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit,
                                        origin=encoder_origin(drive))

            def inject(c: WallController) -> None:
                if c.cycles == 100:  # in contact, torque nonzero: a 2-byte frame on the drive's EMCY id
                    injector.send(can.Message(arbitration_id=0x80 + 1, data=b"\x10\x23", is_extended_id=False))

            summary = controller.run(1000, on_cycle=inject)
        finally:
            injector.shutdown()
        state, torque = sim.drive.state, sim.drive.target_torque
    assert summary.error is not None and "malformed EMCY frame 0x081 of 2 bytes" in summary.error
    # the frame is seen by the master's receive thread; the cycle that checks events raises:
    # a few cycles at most on the virtual bus (a bound, not a pace; the run would go to 1000)
    assert 100 <= summary.cycles <= 110
    assert state is State.SWITCH_ON_DISABLED and torque == 0  # zero torque, then DISABLE VOLTAGE
    path = controller.record.write_csv(tmp_path / "record.csv")
    assert len(path.read_text().splitlines()) == summary.cycles + 1


def _undecodable_datagram(can_id: int) -> bytes:
    """What python-can's udp_multicast cannot turn into a frame: DLC 8 with 2 data bytes."""
    return msgpack.packb({"arbitration_id": can_id, "is_extended_id": False, "dlc": 8, "data": b"\x01\x02",
                          "timestamp": 0.0}, use_bin_type=True)


def test_a_burst_of_undecodable_datagrams_does_not_silence_the_drive(multicast) -> None:
    from sim_drive.canopen.slave import MAX_RECEIVE_ERRORS_IN_ROW, CanopenSimDrive

    group, port = multicast
    burst = 2 * MAX_RECEIVE_ERRORS_IN_ROW
    with CanopenSimDrive({"interface": "udp_multicast", "channel": group, "port": port}, NODE) as sim:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
            raw.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)  # this host only
            for n in range(burst):
                raw.sendto(_undecodable_datagram(0x600 + NODE if n % 2 else 0x000), (group, port))
        deadline = time.monotonic() + 5 * WAIT
        while sim.counters.receive_errors < burst and time.monotonic() < deadline:
            time.sleep(0.01)
        # the loopback socket buffer holds the whole burst (about 60 bytes each), so every one arrives
        assert sim.counters.receive_errors == burst and sim.serving, sim.counters
        with open_bus(interface="udp_multicast", channel=group, port=port) as probe:  # opened after the burst
            probe.send(can.Message(arbitration_id=0x600 + NODE, data=struct.pack("<BHB4x", 0x40, 0x1000, 0),
                                   is_extended_id=False))
            answers = {}
            end = time.monotonic() + 2 * WAIT  # the SDO answer and a heartbeat (0x1017 = 100 ms)
            while time.monotonic() < end and not {0x580 + NODE, 0x700 + NODE} <= answers.keys():
                message = probe.recv(0.05)
                if message is not None:
                    answers[message.arbitration_id] = bytes(message.data)
    assert answers.get(0x580 + NODE) == struct.pack("<BHBI", 0x43, 0x1000, 0, 0x00020192)
    assert answers.get(0x700 + NODE) == b"\x7f"  # PRE-OPERATIONAL: it still says it is alive, and is
    assert sim.drive.state is State.SWITCH_ON_DISABLED


def test_the_controller_node_answers_as_a_canopen_node() -> None:
    from haptic_bus.app.profiles import load_profile
    from haptic_bus.app.rig import simulated_canopen
    from haptic_bus.control.controller import WallController
    from haptic_bus.control.joints import encoder_origin
    from haptic_bus.node.controller_node import ControllerNode

    profile = load_profile("seed-ideal")
    channel = f"controller-node-{uuid.uuid4().hex[:10]}"
    bus = {"interface": "virtual", "channel": channel}
    with simulated_canopen(profile, channel=channel, interface="virtual") as (_sim, drive):
        controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit,
                                    origin=encoder_origin(drive))
        with ControllerNode(controller, 42, heartbeat_ms=20).attached(drive.link.network):
            drive.link.read_by_notifier()  # the enabling walk read the bus itself: canopen's notifier again
            network = canopen.Network()
            network.connect(**bus)
            try:
                node = network.add_node(42, None)

                def read(index: int, subindex: int = 0) -> int:
                    return int.from_bytes(node.sdo.upload(index, subindex), "little")

                assert read(0x1000) == 0 and read(0x1001) == 0 and read(0x1017) == 20
                assert read(0x1018, 0) >= 4 and read(0x1018, 2) == int.from_bytes(b"HBUS", "big")
                for index in (0x2000, 0x1001, 0x1017):
                    with pytest.raises(canopen.SdoAbortedError) as info:
                        node.sdo.upload(index, 1)
                    assert info.value.code == 0x06090011
                    with pytest.raises(canopen.SdoAbortedError) as info:
                        node.sdo.download(index, 1, b"\x01")
                    assert info.value.code == 0x06090011
            finally:
                network.disconnect()
