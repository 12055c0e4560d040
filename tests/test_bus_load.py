"""The bus-load check before a multi-axis start (issue 22): the bench's worst-case bit-time model,
one SYNC for every axis, refused above 70 % of the bitrate with the load and the smallest T.

Bit counts are exact integers (``55 + 10 n`` per frame); loads and periods are quotients of them.
"""

from __future__ import annotations

import pytest

from drives.canopen.drive import DEFAULT_RPDO, DEFAULT_TPDO, DEFAULT_TPDO_WITH_POSITION, split_into_frames
from haptic_bus.analysis.can_timing import axes_that_fit, bus_load, check_bus_load
from haptic_bus.bench.bus_limit import mapping_budget
from haptic_bus.control.bus_load import PDO_MAPPINGS, axes_bus_load
from haptic_bus.errors import ParameterError


def test_the_mappings_are_the_frames_the_master_maps() -> None:
    assert PDO_MAPPINGS["minimal"].tpdo == tuple(split_into_frames(DEFAULT_TPDO))
    assert PDO_MAPPINGS["with-position"].tpdo == tuple(split_into_frames(DEFAULT_TPDO_WITH_POSITION))
    for mapping in PDO_MAPPINGS.values():
        assert mapping.rpdo == tuple(split_into_frames(DEFAULT_RPDO))
    assert PDO_MAPPINGS["minimal"].frame_bytes() == (6, 4)
    assert PDO_MAPPINGS["with-position"].frame_bytes() == (6, 4, 4)
    # the benchmark's budget counts the same bits: 210 per axis, 55 for the SYNC
    assert mapping_budget("minimal")["bits_per_axis"] == 210 == bus_load([(6, 4)], 1e6, 1e-3).bits - 55


def test_three_axes_fit_at_1_mbit_and_1_ms() -> None:
    load = axes_bus_load(["minimal"] * 3, 1_000_000, 1e-3)
    assert load.bits == 55 + 3 * 210 == 685
    assert load.load == pytest.approx(0.685, rel=1e-15) and load.fits
    assert load.smallest_period == pytest.approx(685 / (0.7 * 1e6), rel=1e-15)
    assert axes_that_fit(210, 1e6, 1e-3) == 3


def test_three_axes_are_refused_at_125_kbit_with_the_load_and_the_smallest_period() -> None:
    with pytest.raises(ParameterError) as refused:
        axes_bus_load(["minimal"] * 3, 125_000, 1e-3)
    message = str(refused.value)
    assert "\n" not in message
    assert "bus load 548.0 % of 125 kbit/s at T = 1 ms (3 axes, 685 bits per cycle" in message
    assert "<= 70 %" in message and "T >= 7.829 ms" in message
    # and the period it names fits
    assert axes_bus_load(["minimal"] * 3, 125_000, 7.829e-3).load == pytest.approx(0.7, rel=1e-4)


def test_position_mappings_and_bad_input() -> None:
    assert axes_bus_load(["minimal", "with-position", "minimal"], 1e6, 2e-3).bits == 685 + 95
    with pytest.raises(ParameterError, match="bus load <= 70 %"):  # 780 bits: 78 % at 1 Mbit/s, 1 ms
        axes_bus_load(["with-position"] * 3, 1e6, 1e-3)
    with pytest.raises(ParameterError, match="'minimal' or 'with-position'"):
        axes_bus_load(["full"], 1e6, 1e-3)
    with pytest.raises(ParameterError, match="bitrate"):
        check_bus_load([(6, 4)], 2e6, 1e-3)
    with pytest.raises(ParameterError, match="period"):
        check_bus_load([(6, 4)], 1e6, 0.0)
