"""Worst-case CAN bit times (55 + 10 n), bus load and per-cycle latency."""

from __future__ import annotations

import pytest

from haptic_bus.errors import ParameterError
from sim_drive.bus_timing import BusLoadMeter, cycle_bits, frame_bits, frame_time


def test_frame_lengths() -> None:
    assert [frame_bits(n) for n in (0, 2, 6, 8)] == [55, 75, 115, 135]
    # derivation: 34 + 8n stuffable bits, floor((33 + 8n)/4) stuff bits, 13 fixed-form + IFS bits
    for n in range(9):
        assert frame_bits(n) == 34 + 8 * n + (33 + 8 * n) // 4 + 13
    with pytest.raises(ParameterError, match="data_bytes"):
        frame_bits(9)


@pytest.mark.parametrize("bitrate, cycle_us", [(125_000, 2120.0), (500_000, 530.0), (1_000_000, 265.0)])
def test_cycle_latency_sync_tpdo_rpdo(bitrate: int, cycle_us: float) -> None:
    """SYNC (0 B) + TPDO statusword+velocity (6 B) + RPDO controlword+torque (4 B) = 265 bits."""
    assert cycle_bits((0, 6, 4)) == 265
    assert frame_time(8, 1_000_000) == pytest.approx(135e-6)
    meter = BusLoadMeter(bitrate, 1e-3)
    for _ in range(3):
        meter.sync()
        meter.frame(6)
        meter.frame(4)
    meter.sync()
    assert meter.latencies() == pytest.approx([cycle_us * 1e-6] * 3)
    assert meter.worst_latency() == pytest.approx(cycle_us * 1e-6)
    assert meter.load() == pytest.approx(cycle_us * 1e-6 / 1e-3)  # > 1 at 125 kbit/s: it does not fit


def test_meter_edges() -> None:
    meter = BusLoadMeter(1_000_000, 1e-3)
    meter.frame(8)  # before the first SYNC: not charged
    assert meter.load() == 0.0
    with pytest.raises(ParameterError, match="cycles"):
        meter.worst_latency()
    with pytest.raises(ParameterError, match="bitrate"):
        BusLoadMeter(5_000_000, 1e-3)
