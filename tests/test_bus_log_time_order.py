"""bus.asc in time order: a sent frame is stamped when the link hands it to the bus, not after the
send returned, and the log is written in time order (breaker6: a run's bus.asc on udp_multicast had
1768 of its 8409 frames stamped earlier than the frame before them -- each SYNC after the TPDOs that
answered it -- and, while canopen's notifier read the bus, SDO answers written before their requests)."""

from __future__ import annotations

import os
import pathlib

import can

from drives.canopen.link import NetworkLink
from haptic_bus.app.bus_log import FRAME, BusLogFile, FrameTap, frames
from haptic_bus.control.ring import Ring


def test_a_sent_frame_is_stamped_before_the_bus_takes_it() -> None:
    channel = f"bus-log-time-order-{os.getpid()}"
    ring = Ring(FRAME, 8)
    link = NetworkLink("test link", bus_args=("virtual", channel, None, {}))
    with can.Bus(interface="virtual", channel=channel) as drive_side:
        link.open()
        try:
            link.tap = FrameTap(ring)
            link.send(can.Message(arbitration_id=0x080, is_extended_id=False, data=b""))
        finally:
            link.close()
        taken = drive_side.recv(1.0)  # python-can's virtual bus stamps its copy inside send
    assert taken is not None
    [sync] = frames(ring.read_from(0)[1])
    assert (sync.arbitration_id, sync.is_rx) == (0x080, False)
    # the same clock (time.time) read before and inside the send: ordered whatever the machine's load
    assert 0.0 < sync.timestamp <= taken.timestamp
    ring.close()


def test_an_answer_tapped_before_its_request_is_logged_after_it(tmp_path: pathlib.Path) -> None:
    ring = Ring(FRAME, 8)
    tap = FrameTap(ring)
    request = can.Message(timestamp=1000.0, arbitration_id=0x605, is_extended_id=False,  # upload 0x6041
                          data=bytes([0x40, 0x41, 0x60, 0, 0, 0, 0, 0]))
    answer = can.Message(timestamp=1000.0002, arbitration_id=0x585, is_extended_id=False,
                         data=bytes([0x4B, 0x41, 0x60, 0, 0x37, 0x12, 0, 0]))
    tap(answer, False)  # the notifier thread's tap ran first
    tap(request, True)
    log = BusLogFile(tmp_path / "bus.asc", ring)
    log.close()  # the last drain, End TriggerBlock, the ring let go
    read = list(can.LogReader(tmp_path / "bus.asc"))
    assert [(m.arbitration_id, m.is_rx) for m in read] == [(0x605, False), (0x585, True)]
    # ASC keeps 1 us: the 200 us between them, as stamped
    assert abs((read[1].timestamp - read[0].timestamp) - 200e-6) < 1.5e-6
