"""The Modbus register map: pure encode/decode in both word orders, signed 32-bit values, the
cyclic block codecs, and the server-side register bank against the simulated drive (no network)."""

from __future__ import annotations

import math

import pytest

from drives.cia402 import CONTROLWORD, POSITION_ACTUAL, TARGET_TORQUE, VELOCITY_ACTUAL
from drives.errors import ParameterError
from drives.modbus.register_map import (
    INPUT_BLOCK,
    INPUT_BLOCK_COUNT,
    MAP_IDENTITY,
    OUTPUT_BLOCK,
    REGISTER_BY_NAME,
    REGISTERS,
    InputBlockCodec,
    decode_value,
    describe_range,
    encode_value,
    register_at,
    register_for_object,
)
from drives.modbus.timing import SAFETY_FACTOR, assumed_delay
from sim_drive.device import SimulatedDrive
from sim_drive.modbus import RegisterBank

VELOCITY = register_for_object(VELOCITY_ACTUAL)


@pytest.mark.parametrize(
    ("value", "big", "little"),
    [
        (0, [0x0000, 0x0000], [0x0000, 0x0000]),
        (1, [0x0000, 0x0001], [0x0001, 0x0000]),
        (-1, [0xFFFF, 0xFFFF], [0xFFFF, 0xFFFF]),
        (0x12345678, [0x1234, 0x5678], [0x5678, 0x1234]),
        (-0x12345678, [0xEDCB, 0xA988], [0xA988, 0xEDCB]),
        (-(1 << 31), [0x8000, 0x0000], [0x0000, 0x8000]),
        ((1 << 31) - 1, [0x7FFF, 0xFFFF], [0xFFFF, 0x7FFF]),
        (-65536, [0xFFFF, 0x0000], [0x0000, 0xFFFF]),
    ],
)
def test_signed_32_bit_in_both_word_orders(value: int, big: list[int], little: list[int]) -> None:
    assert encode_value(VELOCITY, value, "big") == big
    assert encode_value(VELOCITY, value, "little") == little
    assert decode_value(VELOCITY, big, "big") == value
    assert decode_value(VELOCITY, little, "little") == value
    # the same registers read with the other order are a different number (unless symmetric)
    if big != little:
        assert decode_value(VELOCITY, big, "little") != value


def test_every_mapped_value_round_trips_at_its_limits() -> None:
    for spec in REGISTERS:
        for order in ("big", "little"):
            if spec.range is None:
                samples = [0.0, -1.5e-7, math.pi, 1e300]
            else:
                low, high = spec.range
                samples = [low, high, 0 if low <= 0 else low]
            for value in samples:
                words = encode_value(spec, value, order)
                assert len(words) == spec.count and all(0 <= w <= 0xFFFF for w in words)
                assert decode_value(spec, words, order) == value


def test_out_of_range_and_bad_order_are_refused_with_the_register_named() -> None:
    with pytest.raises(ValueError, match=r"0x0001 \(0x606C Velocity actual value\) = 2147483648 .*-2147483648\.\.2147483647"):
        encode_value(VELOCITY, 1 << 31)
    with pytest.raises(ValueError, match="0x6060"):
        encode_value(REGISTER_BY_NAME["modes_of_operation"], 200)
    with pytest.raises(ValueError, match="word_order"):
        encode_value(VELOCITY, 1, "middle")
    with pytest.raises(ValueError, match="needs 2 registers"):
        decode_value(VELOCITY, [1])
    with pytest.raises(ValueError, match="INTEGER8"):
        decode_value(REGISTER_BY_NAME["modes_of_operation"], [0x0100])


def test_integer8_mode_is_sign_extended() -> None:
    modes = REGISTER_BY_NAME["modes_of_operation"]
    assert encode_value(modes, 10) == [10]
    assert encode_value(modes, -1) == [0xFFFF]
    assert decode_value(modes, [0xFFFE]) == -2


@pytest.mark.parametrize("order", ["big", "little"])
@pytest.mark.parametrize("with_position", [True, False])
def test_input_block_codec(order: str, with_position: bool) -> None:
    codec = InputBlockCodec(order, with_position)
    sw, vel, pos = 0x1237, -123_456_789, 2_000_000_001
    registers = codec.encode(sw, vel, pos)
    assert len(registers) == codec.count == (5 if with_position else 3)
    # the block is the concatenation of the individual registers of the map
    expected = [sw, *encode_value(VELOCITY, vel, order)]
    if with_position:
        expected += encode_value(register_for_object(POSITION_ACTUAL), pos, order)
    assert registers == expected
    assert codec.decode(registers) == (sw, vel, pos if with_position else None)


def test_block_layout() -> None:
    # one contiguous block each: inputs 0x0000..0x0004, outputs 0x0010..0x0011
    assert [register_at(a).obj for a in range(INPUT_BLOCK, INPUT_BLOCK + INPUT_BLOCK_COUNT)] == [
        register_at(0).obj, VELOCITY_ACTUAL, VELOCITY_ACTUAL, POSITION_ACTUAL, POSITION_ACTUAL]
    assert [register_at(OUTPUT_BLOCK + i).obj for i in range(2)] == [CONTROLWORD, TARGET_TORQUE]
    assert describe_range(OUTPUT_BLOCK, 2) == ("registers 0x0010..0x0011: "
                                                "0x0010 (0x6040 Controlword), 0x0011 (0x6071 Target torque)")
    assert describe_range(7, 1) == "register 0x0007: 0x0007 (unmapped)"


@pytest.mark.parametrize("order", ["big", "little"])
def test_register_bank_reads_writes_and_refuses(order: str) -> None:
    drive = SimulatedDrive(timing="ideal")
    bank = RegisterBank(drive, order)
    drive.sync()
    assert decode_value(REGISTER_BY_NAME["map_identity"], bank.read(0x30, 2), order) == MAP_IDENTITY
    assert bank.read(0x0001, 1) == 0x02  # half of the velocity
    assert bank.read(0x0005, 1) == 0x02  # unmapped
    assert bank.read(0x0000, 4) == 0x02  # cuts the position
    assert bank.write(0x0000, [0]) == 0x02  # read-only statusword
    assert bank.write(0x0020, [0x0100]) == 0x03  # mode 256 is no INTEGER8
    assert bank.write(0x0029, [9]) == 0x03  # quick stop option code 0..8
    # 0x6007 (0x002B) 9 refused with the quick stop option code and the watchdog before it: none applied
    assert bank.write(0x0029, [6, 200, 9]) == 0x03
    assert (drive.quick_stop_option_code, bank.watchdog_ms, drive.abort_connection_option_code) == (2, 0, 1)
    assert bank.write(0x0024, encode_value(REGISTER_BY_NAME["motor_rated_torque"], 0, order)) == 0x03
    assert bank.write(0x0024, [0]) == 0x02  # half of the rated torque
    assert drive.parameters.rated_torque_mnm == 200
    # a controlword write alone runs the state machine without advancing the plant
    assert bank.write(0x0010, [6]) == 0 and drive.sync_count == 1 and bank.cycles == 0
    # the whole output block closes a cycle: one SYNC
    assert bank.write(0x0010, [6, 0]) == 0 and drive.sync_count == 2 and bank.cycles == 1
    assert decode_value(REGISTER_BY_NAME["sim_time"], bank.read(0x54, 4), order) == pytest.approx(1e-3)


def test_assumed_delay_is_the_p99_round_trip_over_the_period_with_its_safety_factor() -> None:
    T = 1e-3
    assert SAFETY_FACTOR == 1.5
    assert assumed_delay(0.0, T) == 0.0
    assert assumed_delay(250e-6, T) == pytest.approx(0.375, rel=1e-15)  # a quarter sample, not rounded up to 1
    assert assumed_delay(1e-3, T) == pytest.approx(1.5, rel=1e-15)
    assert assumed_delay(2.5e-3, T) == pytest.approx(3.75, rel=1e-15)
    for bad in (-1e-6, math.nan, math.inf):
        with pytest.raises(ParameterError, match=r"round_trip_p99 = .* is invalid; allowed: a finite real >= 0 s$"):
            assumed_delay(bad, T)
    with pytest.raises(ParameterError, match=r"T = 0 is invalid; allowed: a finite real > 0 s$"):
        assumed_delay(1e-4, 0)
