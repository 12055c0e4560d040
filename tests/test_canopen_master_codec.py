"""Unit tests of the master's building blocks: PDO codecs, EMCY decoding, bus configuration, who runs the cycle."""

from __future__ import annotations

import struct

import pytest
from canopen.emcy import EmcyError

from drives.bus_config import resolve_bus_config
from drives.canopen.drive import CanopenDrive, split_into_frames
from drives.canopen.events import describe_emcy
from drives.canopen.link import NetworkLink
from drives.canopen.pdo_codec import PdoCodec
from drives.canopen.sync_cycle import SyncCycle
from drives.cia301 import describe_emcy_code, is_restricted_cob_id
from drives.cia402 import (
    CONTROLWORD,
    MODES_OF_OPERATION,
    POSITION_ACTUAL,
    STATUSWORD,
    TARGET_TORQUE,
    TORQUE_ACTUAL,
    VELOCITY_ACTUAL,
    DataType,
    ObjectSpec,
)
from drives.errors import DriveError, DriveProtocolError, ParameterError


def test_default_tpdo_layout_and_mapping_words():
    codec = PdoCodec([STATUSWORD, VELOCITY_ACTUAL], name="TPDO1")
    assert codec.size == 6
    assert codec.struct.format == "<Hi"
    assert codec.mapping_words == (0x60410010, 0x606C0020)


def test_rpdo_layout_and_mapping_words_from_indices():
    codec = PdoCodec([0x6040, 0x6071])  # indices known to drives.cia402 work too
    assert codec.entries == (CONTROLWORD, TARGET_TORQUE)
    assert codec.size == 4
    assert codec.mapping_words == (0x60400010, 0x60710010)


@pytest.mark.parametrize(
    "values",
    [(0x0237, -(1 << 31)), (0xFFFF, (1 << 31) - 1), (0, 0), (0x0027, -1)],
)
def test_tpdo_round_trip_at_type_limits(values):
    codec = PdoCodec([STATUSWORD, VELOCITY_ACTUAL])
    frame = codec.encode(*values)
    assert len(frame) == 6
    assert codec.decode(frame) == values
    assert codec.decode(bytearray(frame)) == values
    assert codec.decode(memoryview(frame)) == values


@pytest.mark.parametrize("torque", [-32768, -1, 0, 1, 32767])
def test_rpdo_signed_torque_round_trip_and_wire_bytes(torque):
    codec = PdoCodec([CONTROLWORD, TARGET_TORQUE])
    frame = codec.encode(0x000F, torque)
    assert frame[:2] == b"\x0f\x00"  # little endian controlword
    assert int.from_bytes(frame[2:], "little", signed=True) == torque
    assert codec.decode(frame) == (0x000F, torque)


def test_signed_and_unsigned_views_of_the_same_bytes_differ():
    unsigned = PdoCodec([STATUSWORD])
    signed = PdoCodec([ObjectSpec(0x6077, "Torque actual value", DataType.INTEGER16, "ro")])
    assert unsigned.decode(b"\xff\xff") == (0xFFFF,)
    assert signed.decode(b"\xff\xff") == (-1,)
    int8 = PdoCodec([MODES_OF_OPERATION])
    assert int8.decode(b"\xf6") == (-10,)
    assert int8.encode(10) == b"\x0a"


def test_encode_into_reuses_the_buffer():
    codec = PdoCodec([CONTROLWORD, TARGET_TORQUE])
    buffer = bytearray(4)
    codec.encode_into(buffer, 0x0006, -300)
    assert bytes(buffer) == struct.pack("<Hh", 6, -300)
    with pytest.raises(DriveProtocolError, match="frame of 5 bytes, mapping needs exactly 4"):
        codec.encode_into(bytearray(5), 0, 0)


@pytest.mark.parametrize("length", [0, 1, 5, 7, 8])
def test_wrong_length_is_rejected_not_decoded(length):
    codec = PdoCodec([STATUSWORD, VELOCITY_ACTUAL], name="TPDO1 of node 5")
    with pytest.raises(DriveProtocolError) as info:
        codec.decode(bytes(length))
    assert str(info.value) == f"TPDO1 of node 5: frame of {length} bytes, mapping needs exactly 6"


@pytest.mark.parametrize(
    ("values", "match"),
    [((0x10000, 0), "0x6040"), ((-1, 0), "0x6040"), ((0, 32768), "0x6071"), ((0, -32769), "0x6071")],
)
def test_out_of_range_values_name_the_object(values, match):
    codec = PdoCodec([CONTROLWORD, TARGET_TORQUE])
    with pytest.raises(ValueError, match=match):
        codec.encode(*values)


def test_mapping_longer_than_a_can_frame_is_refused():
    with pytest.raises(ValueError, match="at most 8"):
        PdoCodec([STATUSWORD, VELOCITY_ACTUAL, POSITION_ACTUAL])


def test_unknown_index_needs_an_object_spec():
    with pytest.raises(ValueError, match="0x2345"):
        PdoCodec([0x2345])


def test_index_of():
    codec = PdoCodec([STATUSWORD, VELOCITY_ACTUAL])
    assert codec.index_of(0x606C) == 1
    with pytest.raises(ValueError, match="0x6064"):
        codec.index_of(0x6064)


def test_objects_are_split_into_can_frames_in_order():
    assert split_into_frames([STATUSWORD, VELOCITY_ACTUAL]) == [(STATUSWORD, VELOCITY_ACTUAL)]
    assert split_into_frames([STATUSWORD, VELOCITY_ACTUAL, POSITION_ACTUAL]) == [
        (STATUSWORD, VELOCITY_ACTUAL),
        (POSITION_ACTUAL,),
    ]
    assert split_into_frames([STATUSWORD, VELOCITY_ACTUAL, TORQUE_ACTUAL]) == [
        (STATUSWORD, VELOCITY_ACTUAL, TORQUE_ACTUAL)
    ]


@pytest.mark.parametrize(
    ("code", "text"),
    [
        (0x8130, "heartbeat"),
        (0x8240, "SYNC data length"),
        (0x2310, "over-current"),
        (0x3210, "over-voltage"),
        (0x4310, "temperature"),
        (0x5530, "memory"),
        (0xFF00, "manufacturer"),
        (0xFF42, "code 0x42"),
        (0x8111, "CAN overrun"),  # unknown leaf falls back to the 0xFFF0 class
        (0x2399, "output side"),  # ... then to the 0xFF00 class
        (0x4999, "Temperature"),  # ... then to the 0xF000 class
    ],
)
def test_emcy_codes_are_decoded(code, text):
    assert text.lower() in describe_emcy_code(code).lower()


def test_emcy_text_names_code_description_and_register():
    text = describe_emcy(EmcyError(0x2310, 0x02, b"\x01\x02\x03\x04\x05", 1.5))
    assert text == "EMCY 0x2310 (Continuous over-current), error register 0x02"


@pytest.mark.parametrize(("cob_id", "restricted"), [
    (0x000, True), (0x07F, True), (0x080, False), (0x085, False), (0x100, False), (0x101, True), (0x180, True),
    (0x181, False), (0x57F, False), (0x585, True), (0x605, True), (0x680, False), (0x6E0, True), (0x705, True),
    (0x780, True), (0x7FF, True),
])
def test_restricted_cob_ids_of_cia301(cob_id, restricted):
    assert is_restricted_cob_id(cob_id) is restricted


def test_bus_config_explicit_arguments(monkeypatch):
    for name in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        monkeypatch.delenv(name, raising=False)
    config = resolve_bus_config("virtual", "ch", 500000, config_file="/nonexistent/can.conf")
    assert (config["interface"], config["channel"], config["bitrate"]) == ("virtual", "ch", 500000)


def test_bus_config_from_environment(monkeypatch):
    monkeypatch.setenv("CAN_INTERFACE", "virtual")
    monkeypatch.setenv("CAN_CHANNEL", "from-env")
    config = resolve_bus_config(config_file="/nonexistent/can.conf")
    assert (config["interface"], config["channel"]) == ("virtual", "from-env")


def test_bus_config_from_file(monkeypatch, tmp_path):
    for name in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        monkeypatch.delenv(name, raising=False)
    path = tmp_path / "can.conf"
    path.write_text("[default]\ninterface = virtual\nchannel = from-file\nbitrate = 250000\n")
    config = resolve_bus_config(config_file=str(path))
    assert (config["interface"], config["channel"], config["bitrate"]) == ("virtual", "from-file", 250000)


def test_bus_config_missing_or_unknown_interface_is_a_readable_error(monkeypatch):
    for name in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr("can.rc", {})
    with pytest.raises(ParameterError, match=r"^bus: interface is missing; allowed: --interface NAME and --channel "):
        resolve_bus_config(config_file="/nonexistent/can.conf")  # no bus given: invalid input, exit 2
    with pytest.raises(ParameterError, match="interface = 'nonesuch' is invalid; allowed: one of python-can's: "):
        resolve_bus_config("nonesuch", config_file="/nonexistent/can.conf")  # the user's typo: exit 2


def test_a_cycle_serves_several_drives_only_when_shared_and_a_drive_takes_its_bus_from_it():
    """Drives are built without touching the bus: a cycle of one drive refuses a second, a shared one
    takes each in axis order, and a drive on a cycle takes no bus of its own besides."""
    link = NetworkLink("nodes 5, 6", bus_args=("lockstep", "unused", None, {}), shared=True)
    alone = SyncCycle("node 5", link, 0.05)
    CanopenDrive(5, cycle=alone)
    with pytest.raises(DriveError, match="CANopen node 6 needs a shared cycle"):
        CanopenDrive(6, cycle=alone)
    shared = SyncCycle("nodes 5, 6", link, 0.05, shared=True)
    drives = [CanopenDrive(node, cycle=shared) for node in (5, 6)]
    assert shared.exchanges == tuple(drive.exchange for drive in drives) and drives[1].link is link
    with pytest.raises(ParameterError, match="cycle"):
        CanopenDrive(7, cycle=shared, interface="lockstep")
