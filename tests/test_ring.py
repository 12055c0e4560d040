"""Issue 26, the ring the cycle writes into (:mod:`haptic_bus.control.ring`): records read back
whole and in order, a reader a ring behind told how many it lost, a shared ring read through a
second mapping after its name is gone, and frames through the bus log's tap and back unchanged,
from two threads at once too."""

from __future__ import annotations

import struct
import sys
import threading
from multiprocessing import shared_memory

import can
import pytest

from drives.canopen.link import PartsTap
from haptic_bus.app.bus_log import FRAME, FrameTap, frames
from haptic_bus.control.ring import Ring

PAIR = struct.Struct("=qd")  # (index, index / 2): a record whose value says which one it is


def _written(ring: Ring, first: int, count: int) -> None:
    for n in range(first, first + count):
        ring.put(n, n / 2)


def _read(ring: Ring, first: int, limit: int | None = None) -> tuple[int, list[tuple[int, float]]]:
    start, chunk = ring.read_from(first, limit)
    return start, list(PAIR.iter_unpack(chunk))


def test_records_come_back_in_order_and_a_reader_a_ring_behind_is_told_what_it_lost() -> None:
    ring = Ring(PAIR, 8)
    assert ring.total == 0 and ring.last() is None and _read(ring, 0) == (0, [])
    _written(ring, 0, 5)
    assert _read(ring, 0) == (0, [(n, n / 2) for n in range(5)]) and ring.last() == (4, 2.0)
    assert _read(ring, 3, limit=1) == (3, [(3, 1.5)])
    _written(ring, 5, 15)  # 20 written into 8 slots: the slot of the next one is not read, so 7 are kept
    start, records = _read(ring, 5)
    assert ring.total == 20 and start == 13 and records == [(n, n / 2) for n in range(13, 20)]  # 8 lost: 5..12
    assert _read(ring, 20) == (20, [])


def test_a_shared_ring_is_read_through_a_second_mapping_after_its_name_is_gone() -> None:
    ring = Ring.shared(PAIR, 16)
    reader = Ring.attach(ring.spec)
    ring.unlink()  # what the run does once its writer has attached: nothing left in /dev/shm
    with pytest.raises(FileNotFoundError):
        shared_memory.SharedMemory(name=ring.spec.name)
    _written(ring, 0, 10)
    assert reader.total == 10 and _read(reader, 4) == (4, [(n, n / 2) for n in range(4, 10)])
    reader.close()
    ring.close()


def test_private_memory_cannot_be_attached() -> None:
    with pytest.raises(ValueError, match="private memory"):
        Ring(PAIR, 4).spec  # noqa: B018


def test_frames_go_through_the_tap_and_come_back_unchanged() -> None:
    ring = Ring(FRAME, 16)
    tap = FrameTap(ring)
    sync = can.Message(arbitration_id=0x080, data=b"", is_extended_id=False)
    tpdo = can.Message(timestamp=1_700_000_000.25, arbitration_id=0x185, data=bytes(range(8)), is_extended_id=False)
    remote = can.Message(timestamp=1_700_000_000.5, arbitration_id=0x1ABCDE, is_extended_id=True, is_remote_frame=True,
                         dlc=0)
    tap(sync, True)
    tap(tpdo, False)
    tap(remote, False)
    sent, received, asked = frames(ring.read_from(0)[1])
    assert (sent.arbitration_id, bytes(sent.data), sent.is_rx, sent.timestamp > 1e9) == (0x080, b"", False, True)
    assert (received.arbitration_id, bytes(received.data), received.is_rx, received.timestamp) == \
        (0x185, bytes(range(8)), True, 1_700_000_000.25)  # a received frame keeps the time it was received
    assert (asked.arbitration_id, asked.is_extended_id, asked.is_remote_frame, asked.is_rx) == (0x1ABCDE, True, True, True)


def test_a_received_frame_given_as_its_parts_is_the_record_its_message_makes() -> None:
    """The control thread's receive hands the bus log a TPDO as its parts (``FrameTap.received``): the same record,
    byte for byte, as the message a receive would have built for it."""
    as_message, as_parts = Ring(FRAME, 4), Ring(FRAME, 4)
    FrameTap(as_message)(can.Message(timestamp=1_700_000_000.25, arbitration_id=0x285, data=b"\x07\x00\x10",
                                     is_extended_id=False), False)
    FrameTap(as_parts).received(1_700_000_000.25, 0x285, b"\x07\x00\x10")
    assert as_parts.read_from(0) == as_message.read_from(0)
    assert isinstance(FrameTap(as_parts), PartsTap)  # so a link hands it the parts (drives/canopen/link.py)


def test_two_threads_tapping_at_once_lose_no_frame() -> None:
    per_thread = 5_000
    ring = Ring(FRAME, 4 * per_thread)
    tap = FrameTap(ring)

    def send(first: int) -> None:
        for n in range(first, first + per_thread):
            tap(can.Message(timestamp=1.0, arbitration_id=n, data=b"", is_extended_id=True), False)

    threads = [threading.Thread(target=send, args=(first,)) for first in (0, per_thread)]
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # the interpreter switches threads as often as it can: races show
    try:
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(timeout=60.0)
    finally:
        sys.setswitchinterval(interval)
    start, chunk = ring.read_from(0)
    assert start == 0 and sorted(frame.arbitration_id for frame in frames(chunk)) == list(range(2 * per_thread))
