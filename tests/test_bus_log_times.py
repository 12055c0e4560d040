"""bus.asc read back gives each frame the time it was logged with (break15b).

python-can's ASCWriter (4.6.1) writes the header's milliseconds without leading zeros: a first frame
at 17:19:10.005 gives ``Begin Triggerblock ... 17:19:10.5 2026``, which ASCReader (and CANoe) read
as 10.500 s, so every frame of a run whose first frame falls in the first 100 ms of a second comes
back up to 0.9 s late against record.csv and run.json (seen in a gantry-3d run: +495 ms).
"""

from __future__ import annotations

import datetime
import struct

import can
import pytest

from haptic_bus.app.bus_log import FRAME, BusLogFile, FrameTap
from haptic_bus.control.ring import Ring


@pytest.mark.parametrize("milliseconds", [5, 50, 99, 100, 505])
def test_bus_log_times_read_back(tmp_path, milliseconds):
    start = datetime.datetime(2026, 12, 7, 17, 19, 10, milliseconds * 1000, tzinfo=datetime.UTC).timestamp()
    ring = Ring(FRAME, 64)
    tap = FrameTap(ring)
    stamps = [start, start + 0.0021, start + 0.0105]
    for n, stamp in enumerate(stamps):
        tap.received(stamp, 0x185, struct.pack("<HI", 0x237, n))
    log = BusLogFile(tmp_path / "bus.asc", ring)
    log.close()
    read = [m.timestamp for m in can.ASCReader(str(tmp_path / "bus.asc"), relative_timestamp=False)]
    assert len(read) == len(stamps)
    for got, logged in zip(read, stamps):
        assert got == pytest.approx(logged, abs=1e-5)  # ASC keeps microseconds


def test_bus_log_keeps_a_remote_frames_dlc(tmp_path):
    """A remote frame asks for dlc bytes and carries none: bus.asc must say ``r 8`` as a logger on the bus
    does (python-can's ASCWriter writes the message's dlc), not ``r 0`` (FrameTap stores len(data))."""
    ring = Ring(FRAME, 64)
    FrameTap(ring)(can.Message(timestamp=1796663950.25, arbitration_id=0x185, is_extended_id=False,
                               is_remote_frame=True, dlc=8), False)
    log = BusLogFile(tmp_path / "bus.asc", ring)
    log.close()
    (read,) = list(can.ASCReader(str(tmp_path / "bus.asc")))
    assert read.is_remote_frame and read.arbitration_id == 0x185
    assert read.dlc == 8
