"""The filtered udp_multicast bus keeps exactly the frames python-can's own filters keep.

:class:`drives.udp_multicast.FilteredMulticastBus` decides on a datagram's identifier before it
builds a message: the identifiers that full-mask standard filters name are one set, every other
filter is tested as python-can tests it.  For any filters and any frame its decision is
:meth:`can.BusABC._matches_filters`' (python-can's reference), on datagrams packed as python-can
packs them.
"""

from __future__ import annotations

from collections.abc import Iterator

import can
import msgpack
import pytest
from can.interfaces.udp_multicast.utils import pack_message
from can.typechecking import CanFilter
from hypothesis import given, settings
from hypothesis import strategies as st

from drives.bus_config import open_bus
from drives.errors import DriveError
from drives.udp_multicast import _plain_frame
from haptic_bus.testing.buses import unique_multicast

STANDARD, EXTENDED = 0x7FF, 0x1FFFFFFF
# a pool first, so that frames meet filters often
identifiers = st.one_of(st.sampled_from([0x185, 0x286, 0x705, 0x80]), st.integers(0, STANDARD))


@st.composite
def filters(draw: st.DrawFn) -> list[CanFilter]:
    """A filter list as the project sets them (full-mask standard ids) mixed with masks and extended ids."""
    out: list[CanFilter] = []
    for _ in range(draw(st.integers(1, 6))):
        kind = draw(st.sampled_from(["exact", "masked", "extended", "any"]))
        if kind == "exact":
            out.append({"can_id": draw(identifiers), "can_mask": STANDARD, "extended": False})
        elif kind == "masked":
            masked: CanFilter = {"can_id": draw(identifiers), "can_mask": draw(st.sampled_from([0x780, 0x7F0, 0x07F, STANDARD]))}
            if draw(st.booleans()):  # without the key, a filter takes both kinds of frame; with None, neither
                masked["extended"] = draw(st.sampled_from([True, False, None]))  # type: ignore[typeddict-item]
            out.append(masked)
        elif kind == "extended":
            out.append({"can_id": draw(st.integers(0, EXTENDED)), "can_mask": EXTENDED, "extended": True})
        else:
            out.append({"can_id": draw(identifiers), "can_mask": draw(st.integers(0, EXTENDED)),
                        "extended": draw(st.sampled_from([True, False]))})
    return out


@st.composite
def frames(draw: st.DrawFn) -> can.Message:
    extended = draw(st.booleans())
    can_id = draw(st.one_of(identifiers, st.integers(0, EXTENDED))) if extended else draw(identifiers)
    return can.Message(arbitration_id=can_id, is_extended_id=extended, data=b"\x01\x02")


@pytest.fixture(scope="module")
def bus() -> Iterator[can.BusABC]:
    group, port = unique_multicast()
    with open_bus(interface="udp_multicast", channel=group, port=port) as handle:
        yield handle


@settings(max_examples=100, deadline=None)
@given(wanted=filters(), sent=st.lists(frames(), min_size=1, max_size=8))
def test_a_datagram_passes_exactly_when_python_cans_filters_pass_its_frame(bus: can.BusABC, wanted: list[CanFilter],
                                                                            sent: list[can.Message]) -> None:
    bus.set_filters(wanted)
    for message in sent:
        fields = bus._wanted_fields(pack_message(message))  # type: ignore[attr-defined]  # the project's bus
        assert (fields is not None) == bus._matches_filters(message), (wanted, message)


def test_filters_given_as_an_iterator_are_all_kept(bus: can.BusABC) -> None:
    """Filters read in one pass, as python-can's kernel-filter backends read them: an iterator's masked
    filter is kept beside its exact ones (read twice, the second pass found the iterator empty)."""
    given: list[CanFilter] = [{"can_id": 0x185, "can_mask": STANDARD, "extended": False}, {"can_id": 0x80, "can_mask": 0x780}]
    bus.set_filters(iter(given))  # type: ignore[arg-type]  # typed a sequence; an iterator is what is tested
    kept = {can_id for can_id in (0x185, 0x85, 0x186)
            if bus._wanted_fields(pack_message(can.Message(arbitration_id=can_id, is_extended_id=False))) is not None}  # type: ignore[attr-defined]
    assert kept == {0x185, 0x85}


@pytest.mark.parametrize("wanted", ['[{"can_id": 1, "can_mask": 2047}]', [{"can_id": 0x185}], [0x185],
                                    [{"can_id": "0x185", "can_mask": 0x7FF}]], ids=["text", "no-mask", "int", "text-id"])
def test_filters_python_can_cannot_apply_are_a_bus_error_in_one_line(wanted: object) -> None:
    """``--bus-option can_filters=[...]`` gives a string (python-can would iterate its characters at the first frame):
    opening the bus fails as a bus error the command line prints in one line, not a TypeError's traceback."""
    group, port = unique_multicast()
    with pytest.raises(DriveError, match=r"cannot open the CAN bus: can_filters: each filter a dict") as info:
        open_bus(interface="udp_multicast", channel=group, port=port, can_filters=wanted)
    assert "\n" not in str(info.value)


_KEYS = ["timestamp", "arbitration_id", "is_extended_id", "is_remote_frame", "is_error_frame", "channel", "dlc", "data",
         "is_fd", "bitrate_switch", "error_state_indicator"]  # python-can's pack_message, in its order
_FLAGS = ["is_extended_id", "is_remote_frame", "is_error_frame", "is_fd", "bitrate_switch", "error_state_indicator"]


@st.composite
def datagrams(draw: st.DrawFn) -> tuple[can.Message, bytes]:
    """A standard data frame as python-can packs it (any channel), and that datagram changed or not: a byte
    replaced, bytes cut out or put in."""
    message = can.Message(arbitration_id=draw(identifiers), is_extended_id=False, data=draw(st.binary(max_size=8)),
                          timestamp=draw(st.floats(allow_nan=False)),
                          channel=draw(st.one_of(st.none(), st.text(max_size=40), st.integers(0, 3))))
    packed = bytearray(pack_message(message))
    at = draw(st.integers(0, len(packed) - 1))
    change = draw(st.sampled_from(["none", "replace", "cut", "insert"]))
    if change == "replace":
        packed[at] = draw(st.integers(0, 255))
    elif change == "cut":
        del packed[at:at + draw(st.integers(1, 4))]
    elif change == "insert":
        packed[at:at] = draw(st.binary(min_size=1, max_size=4))
    return message, bytes(packed)


@settings(max_examples=150, deadline=None)  # 0.25 s of CPU; 180000 mutated datagrams checked alike offline
@given(datagrams())
def test_a_frame_read_from_its_bytes_is_what_msgpack_decodes_and_the_cycles_receive_passes(
        case: tuple[can.Message, bytes]) -> None:
    """The cycle's receive reads python-can's datagram of a plain frame from its bytes (``_plain_frame``, no
    msgpack dict): whatever it reads is what msgpack decodes, every check of ``recv_wanted``'s bare path holding
    (each key in order, an int identifier, bytes of ``dlc`` bytes, at most 8, every flag False); any other
    datagram it leaves to msgpack (None).  python-can's own packing of a frame with no channel or a short ASCII
    one it always reads."""
    message, datagram = case
    read = _plain_frame(datagram)
    if datagram == pack_message(message) and (message.channel is None or (isinstance(message.channel, str)
                                              and message.channel.isascii() and len(message.channel) < 32)):
        assert read is not None and read[:2] == (message.arbitration_id, bytes(message.data)), (read, message)
    if read is None:
        return
    fields = msgpack.unpackb(datagram, raw=False)
    assert list(fields) == _KEYS, fields
    assert (fields["arbitration_id"], fields["data"], fields["channel"]) == \
        (read[0], read[1], None if read[2] is None else read[2].decode("ascii")), (fields, read)
    assert type(read[0]) is int and type(read[1]) is bytes and fields["dlc"] == len(read[1]) <= 8, fields
    assert all(fields[flag] is False for flag in _FLAGS), fields
    assert fields["channel"] is None or type(fields["channel"]) is str, fields
    assert type(fields["timestamp"]) is float, fields


def test_a_frame_sent_is_packed_as_python_can_packs_it(bus: can.BusABC) -> None:
    """The bus packs a frame it sends with a packer it keeps: the datagram is python-can's ``pack_message``, byte
    for byte, for every kind of frame."""
    sent: list[bytes] = []

    class Capture:
        def settimeout(self, timeout: float | None) -> None:
            pass

        def sendto(self, data: bytes, address: object) -> int:
            sent.append(data)
            return len(data)

    messages = [can.Message(arbitration_id=0x205, data=bytes(4), is_extended_id=False),
                can.Message(arbitration_id=0x80, data=b"", is_extended_id=False, timestamp=1.5e9),
                can.Message(arbitration_id=0x1ABCDEF, data=[1, 2, 3], is_extended_id=True, channel="x"),
                can.Message(arbitration_id=0x7FF, is_remote_frame=True, dlc=3, is_extended_id=False),
                can.Message(arbitration_id=0x1, is_error_frame=True)]
    real = bus._sender  # type: ignore[attr-defined]  # the project's bus
    bus._sender = Capture()  # type: ignore[attr-defined]
    try:
        for message in messages:
            bus.send(message)
    finally:
        bus._sender = real  # type: ignore[attr-defined]
    assert sent == [pack_message(message) for message in messages]
