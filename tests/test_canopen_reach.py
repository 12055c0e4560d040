"""Reaching a CANopen node: a node that answers the statusword's SDO read with an abort has answered.

A device at the node id that is not a CiA-402 drive (an I/O module: no 0x6041) aborts the statusword's read,
and one that does not reset its communication on command sends no boot-up after the NMT reset.  It is on the
bus and answers SDO: commissioning goes on to 0x1000 and names what it is, not "no SDO answer ... check node
id, bitrate, wiring" as for a missing node.
"""

from __future__ import annotations

import struct
import threading
import uuid

import can
import pytest

from drives.canopen.drive import CanopenDrive
from drives.errors import DriveProtocolError, DriveTimeout
from sim_drive.eds import eds_path

NODE_ID = 5
IO_MODULE = 0x000F0191  # 0x1000 of a CiA-401 I/O module


class IoModule:
    """A node on a virtual channel that answers SDO uploads (0x1000 with :data:`IO_MODULE`, every other object
    with the abort 'object does not exist') and ignores NMT: no boot-up, ever."""

    def __init__(self, channel: str) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.requests: list[int] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="io-module", daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while not self._stop.is_set():  # bounded by close(): each recv returns within 50 ms
            msg = self.bus.recv(0.05)
            if msg is None or msg.arbitration_id != 0x600 + NODE_ID or msg.data[0] & 0xE0 != 0x40:
                continue
            index, subindex = struct.unpack_from("<HB", msg.data, 1)
            self.requests.append(index)
            if (index, subindex) == (0x1000, 0):
                data = struct.pack("<BHBI", 0x43, index, subindex, IO_MODULE)
            else:
                data = struct.pack("<BHBI", 0x80, index, subindex, 0x06020000)
            self.bus.send(can.Message(arbitration_id=0x580 + NODE_ID, data=data, is_extended_id=False))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
        self.bus.shutdown()


@pytest.fixture
def io_module():
    channel = f"reach-{uuid.uuid4().hex}"
    module = IoModule(channel)
    yield module, channel
    module.close()


def test_a_node_that_aborts_the_statusword_read_and_sends_no_boot_up_is_named_by_its_device_type(io_module):
    module, channel = io_module
    drive = CanopenDrive(NODE_ID, interface="virtual", channel=channel, boot_timeout=0.2, eds=eds_path())
    try:
        with pytest.raises(DriveProtocolError) as info:
            drive.connect()
    finally:
        drive.close()
    assert not isinstance(info.value, DriveTimeout)
    assert "0x1000 device type = 0x000F0191 is not a CiA-402 drive" in str(info.value)
    assert module.requests[0] == 0x6041  # the statusword's read came first, and the abort was its answer
