"""A udp_multicast handle does not receive the frames it sent, as a CAN controller does not.

The kernel loops every datagram on the group back to every socket on the host, the sender's too;
:class:`drives.udp_multicast.FilteredMulticastBus` drops the ones its own sending socket sent.
Two handles in one process (one host address, as two processes on one host) still hear each
other, and a plain python-can handle reads the project's frames.  A run with no drive on the bus
then names no node it heard (it used to name itself, 127), and its bus log holds each frame it
sent once, as Tx.
"""

from __future__ import annotations

import pathlib
import socket

import can
import msgpack
import pytest
from can.interfaces.udp_multicast.utils import pack_message

from drives.bus_config import open_bus
from drives.canopen.drive import CanopenDrive
from drives.udp_multicast import LATE_READS, parts_message, standard_filters
from tests.run_rig import run_cli

WAIT = 5.0  # s: the longest a receive waits for a datagram looped back on this host (microseconds when idle)
END = 0x7FF  # the identifier of the frame a handle of its own sends after the test's frames


def heard(bus: can.BusABC) -> list[int]:
    """The identifiers ``bus`` receives before the :data:`END` frame (at most 10 frames; -1 last if no
    :data:`END` came within :data:`WAIT`).  One thread sends every frame, and the kernel loops each datagram
    back to the host's sockets as it is sent, in that order: a frame ``bus`` would hear comes before the
    :data:`END` sent after it, so what it heard before :data:`END` is all it hears of them (no silence waited out)."""
    ids = []
    for _ in range(10):
        message = bus.recv(WAIT)
        if message is None:
            return [*ids, -1]
        if message.arbitration_id == END:
            return ids
        ids.append(message.arbitration_id)
    return ids


def end(group: str, port: int) -> None:
    """:data:`END` from a handle of its own (whose frame no other handle takes for its own)."""
    with open_bus(interface="udp_multicast", channel=group, port=port) as marker:
        marker.send(can.Message(arbitration_id=END, data=[], is_extended_id=False))


def test_a_handle_hears_the_others_frames_but_not_its_own(multicast: tuple[str, int]) -> None:
    group, port = multicast
    with (open_bus(interface="udp_multicast", channel=group, port=port) as one,
          open_bus(interface="udp_multicast", channel=group, port=port) as other,
          can.Bus(interface="udp_multicast", channel=group, port=port, hop_limit=0) as plain):
        one.send(can.Message(arbitration_id=0x77F, data=[5], is_extended_id=False))
        plain.send(can.Message(arbitration_id=0x185, data=[1, 2], is_extended_id=False))
        end(group, port)
        assert heard(one) == [0x185]
        assert heard(other) == [0x77F, 0x185]
        assert heard(plain) == [0x77F, 0x185]  # python-can's own handle still hears itself


def test_a_poll_returns_the_frame_waiting_behind_a_dropped_one(multicast: tuple[str, int]) -> None:
    """``recv(0)``, the poll a cycle drains its late TPDOs with (:meth:`drives.canopen.sync_cycle.SyncCycle.drain`):
    a frame waiting behind the handle's own looped-back frame, or behind one no filter wants, is returned.  It
    used to be None, as if nothing waited: the drain stopped there, and the next cycle took the previous
    cycle's late TPDO for its own."""
    group, port = multicast
    with (open_bus(interface="udp_multicast", channel=group, port=port) as one,
          open_bus(interface="udp_multicast", channel=group, port=port) as drive,
          open_bus(interface="udp_multicast", channel=group, port=port) as witness):
        one.set_filters(standard_filters({0x185}))
        one.send(can.Message(arbitration_id=0x205, data=[0, 0, 0, 0], is_extended_id=False))  # its own: dropped
        drive.send(can.Message(arbitration_id=0x705, data=[5], is_extended_id=False))  # no filter wants it: dropped
        drive.send(can.Message(arbitration_id=0x185, data=[1, 2], is_extended_id=False))  # the late TPDO
        went_round = [witness.recv(WAIT) for _ in range(3)]  # all three went round the group, in this order
        assert [m.arbitration_id if m is not None else None for m in went_round] == [0x205, 0x705, 0x185]
        late = one.recv(0)
        assert late is not None and late.arbitration_id == 0x185 and bytes(late.data) == b"\x01\x02"
        assert one.recv(0) is None  # nothing else waits


def test_the_cycles_receive_returns_its_frames_bare_and_every_other_as_recv_does(multicast: tuple[str, int]) -> None:
    """``recv_wanted``, the control thread's receive (:func:`drives.canopen.sync_cycle.receive_direct`): a standard
    data frame of ``wanted`` comes as ``(identifier, data)``, a remote or extended frame of the same identifier and a
    frame outside ``wanted`` as the checked, stamped message :meth:`recv` builds; the filters and its own frames
    are dropped as by :meth:`recv`."""
    group, port = multicast
    with (open_bus(interface="udp_multicast", channel=group, port=port) as one,
          open_bus(interface="udp_multicast", channel=group, port=port) as drive):
        one.set_filters([*standard_filters({0x185, 0x186}), {"can_id": 0x185, "can_mask": 0x1FFFFFFF}])
        one.send(can.Message(arbitration_id=0x185, data=[9], is_extended_id=False))  # its own: dropped
        for frame in (can.Message(arbitration_id=0x185, data=[1, 2], is_extended_id=False),
                      can.Message(arbitration_id=0x705, data=[5], is_extended_id=False),  # no filter wants it
                      can.Message(arbitration_id=0x185, is_remote_frame=True, dlc=2, is_extended_id=False),
                      can.Message(arbitration_id=0x185, data=[3], is_extended_id=True),
                      can.Message(arbitration_id=0x186, data=[4], is_extended_id=False)):
            drive.send(frame)
        got = [one.recv_wanted({0x185}, WAIT) for _ in range(4)]  # type: ignore[attr-defined]  # the project's bus
        assert got[0] == (0x185, b"\x01\x02")
        others = got[1:]
        assert all(isinstance(m, can.Message) and m.timestamp > 0 for m in others), others
        assert [(m.arbitration_id, m.is_remote_frame, m.is_extended_id, bytes(m.data)) for m in others] == [  # type: ignore[union-attr]
            (0x185, True, False, b""), (0x185, False, True, b"\x03"), (0x186, False, False, b"\x04")]
        assert one.recv_wanted({0x185}, 0.0) is None  # type: ignore[attr-defined]


@pytest.mark.parametrize("datagram", [b"\xc1", msgpack.packb([1, 2]),
                                      msgpack.packb({"arbitration_id": [1], "is_extended_id": False, "is_remote_frame": False,
                                                     "is_error_frame": False, "is_fd": False, "dlc": 0, "data": b""})],
                         ids=["not-msgpack", "a-list", "id-a-list"])
@pytest.mark.parametrize("receive", ["recv", "recv_wanted"])
def test_a_datagram_that_is_no_frame_is_a_receive_error_either_way(datagram: bytes, receive: str,
                                                                 multicast: tuple[str, int]) -> None:
    group, port = multicast
    with (open_bus(interface="udp_multicast", channel=group, port=port) as one,
          socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as foreign):
        one.set_filters(standard_filters({0x185}))
        foreign.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
        foreign.sendto(datagram, (group, port))
        with pytest.raises(can.CanOperationError, match="could not unpack received message"):
            one.recv(WAIT) if receive == "recv" else one.recv_wanted({0x185}, WAIT)  # type: ignore[attr-defined]


def _packed(**changed: object) -> bytes:
    """python-can's datagram of the standard data frame 0x185 [1..6], ``changed`` as a sender other than python-can
    could pack it (a key absent from python-can's map added)."""
    fields = msgpack.unpackb(pack_message(can.Message(arbitration_id=0x185, data=[1, 2, 3, 4, 5, 6], is_extended_id=False)),
                             raw=False)
    return msgpack.packb(fields | changed, use_bin_type=True)


def _received(receive: object) -> object:
    try:
        return receive() if callable(receive) else None
    except can.CanOperationError as error:
        return error


@pytest.mark.parametrize("changed", [{}, {"data": [1, 2, 3, 4, 5, 6]}, {"data": "abcdef"}, {"data": None, "dlc": 0},
                                     {"data": 6}, {"arbitration_id": 389.0}, {"more": 1}, {"bitrate_switch": True},
                                     {"error_state_indicator": True}, {"channel": "sim-bridge-7f1333880290"},
                                     {"channel": "\u00e9"}, {"dlc": 5}],
                         ids=["python-can's", "data-a-list", "data-a-string", "data-none", "data-an-int", "id-a-float",
                              "a-key-can-Message-refuses", "bitrate-switch-not-fd", "esi-not-fd", "a-channel",
                              "a-channel-not-ascii", "dlc-not-the-length"])
def test_the_cycles_receive_gives_bare_only_the_frame_recv_gives_and_raises_as_recv(changed: dict[str, object],
                                                                                   multicast: tuple[str, int]) -> None:
    """A datagram of a wanted identifier that python-can's sender would not pack: ``recv_wanted`` returns what
    ``recv`` returns (the same frame, or the same receive error), bare only for python-can's own packing of a plain
    frame with no channel or an ASCII one (a list of data returned bare reached the cycle's struct unpack: a
    TypeError that crashed a run without a bus log).
    ``recv_parts``, the cycle's receive with a tap, returns what ``recv`` returns, or for python-can's plain packing
    its parts, of which the message ``recv`` returns is built (``parts_message``: what a tap that takes no parts sees)."""
    group, port = multicast
    with (open_bus(interface="udp_multicast", channel=group, port=port) as by_recv,
          open_bus(interface="udp_multicast", channel=group, port=port) as by_wanted,
          open_bus(interface="udp_multicast", channel=group, port=port) as by_message,
          socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as foreign):
        foreign.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
        foreign.sendto(_packed(**changed), (group, port))
        expected = _received(lambda: by_recv.recv(WAIT))
        got = _received(lambda: by_wanted.recv_wanted({0x185}, WAIT))  # type: ignore[attr-defined]  # the project's bus
        parts = _received(lambda: by_message.recv_parts({0x185}, WAIT))  # type: ignore[attr-defined]
        message = parts_message(*parts) if isinstance(parts, tuple) else parts
        if isinstance(expected, can.CanOperationError):
            for either in (got, message):
                assert isinstance(either, can.CanOperationError) and str(either) == str(expected), (either, expected)
                assert type(either.__cause__) is type(expected.__cause__), (either.__cause__, expected.__cause__)
            return
        assert isinstance(expected, can.Message) and isinstance(message, can.Message), (message, expected)
        assert message.equals(expected, timestamp_delta=None) and message.channel == expected.channel, (message, expected)
        assert type(message.data) is type(expected.data) and message.is_rx == expected.is_rx, (message, expected)
        assert abs(message.timestamp - expected.timestamp) < WAIT, (message, expected)  # each socket's kernel stamp
        plain = not changed or (set(changed) == {"channel"} and str(changed["channel"]).isascii())
        if plain:  # python-can's own packing of a plain frame (no channel, or an ASCII one): bare
            assert got == (0x185, b"\x01\x02\x03\x04\x05\x06"), (got, expected)
            assert isinstance(parts, tuple), (parts, expected)
        else:
            assert isinstance(got, can.Message) and isinstance(parts, can.Message), (got, parts, expected)
            assert got.equals(expected, timestamp_delta=None), (got, expected)


class _Refilled:
    """A socket whose queue a sender refills as fast as it is read: ``dropped`` datagrams no filter wants, then
    ``frame`` (if given) once, then unwanted ones for ever; at most ``bound`` reads (then an error: the receive
    did not return)."""

    def __init__(self, dropped: int, frame: bytes | None, bound: int) -> None:
        self.reads, self.dropped, self.frame, self.bound = 0, dropped, frame, bound
        self.unwanted = pack_message(can.Message(arbitration_id=0x705, data=[5], is_extended_id=False))

    def recvmsg(self, *_: object) -> tuple[bytes, list[object], int, tuple[str, int]]:
        self.reads += 1
        if self.reads > self.bound:
            raise OSError(f"still reading after {self.bound} datagrams")
        data = self.frame if self.reads == self.dropped + 1 and self.frame is not None else self.unwanted
        return data, [], 0, ("192.0.2.1", 9)  # another host's address (TEST-NET-1): not its own frame


@pytest.mark.parametrize("receive", ["recv", "recv_wanted"])
def test_past_its_timeout_a_receive_reads_a_full_queue_but_not_a_flood(receive: str, multicast: tuple[str, int],
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """A poll still returns a frame that waits behind a full queue of dropped ones (10082 of python-can's frames in
    :data:`~drives.udp_multicast.RECEIVE_QUEUE`), but a sender refilling the queue as fast as the handle drops its
    frames no longer keeps it reading: a raw socket's 126000 unwanted frames/s kept ``recv(0.1)`` 3.9 s."""
    group, port = multicast
    with open_bus(interface="udp_multicast", channel=group, port=port) as one:
        one.set_filters(standard_filters({0x185}))
        poll = (lambda: one.recv(0)) if receive == "recv" else (lambda: one.recv_wanted({0x185}, 0))  # type: ignore[attr-defined]
        frame = pack_message(can.Message(arbitration_id=0x185, data=[1, 2], is_extended_id=False))
        behind = _Refilled(10082, frame, 4 * LATE_READS)
        monkeypatch.setattr(one._multicast, "_socket", behind)  # type: ignore[attr-defined]  # the project's bus
        got = poll()
        assert got is not None and behind.reads == 10083, behind.reads
        assert isinstance(got, tuple if receive == "recv_wanted" else can.Message), got
        assert (got if isinstance(got, tuple) else (got.arbitration_id, bytes(got.data))) == (0x185, b"\x01\x02"), got
        flood = _Refilled(0, None, 4 * LATE_READS)
        monkeypatch.setattr(one._multicast, "_socket", flood)
        assert poll() is None
        assert flood.reads == LATE_READS, flood.reads
        monkeypatch.undo()  # the handle's own socket back, for its shutdown to close


def test_a_datagram_with_keys_left_out_is_the_frame_python_can_makes_of_it(multicast: tuple[str, int]) -> None:
    """python-can builds a datagram's frame with :class:`can.Message`'s defaults for the keys it lacks (an
    extended identifier, no data): a plain python-can handle, ``recv`` and ``recv_wanted`` read the same frames,
    and the filters test the frame so built (``{"arbitration_id": 0x185}`` alone is extended: a standard filter
    drops it)."""
    group, port = multicast
    sent = [{"arbitration_id": 0x185, "is_extended_id": False, "data": b"\x07"}, {"arbitration_id": 0x185},
            {"arbitration_id": 0x186, "is_extended_id": False}]
    with (open_bus(interface="udp_multicast", channel=group, port=port) as one,
          open_bus(interface="udp_multicast", channel=group, port=port) as two,
          can.Bus(interface="udp_multicast", channel=group, port=port, hop_limit=0) as plain,
          socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as foreign):
        two.set_filters(standard_filters({0x185, 0x186}))
        foreign.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
        for fields in sent:
            foreign.sendto(msgpack.packb(fields), (group, port))

        def shape(m: object) -> tuple[object, ...]:
            assert isinstance(m, can.Message), m
            return m.arbitration_id, m.is_extended_id, bytes(m.data)

        expected = [(0x185, False, b"\x07"), (0x185, True, b""), (0x186, False, b"")]
        assert [shape(plain.recv(WAIT)) for _ in sent] == [shape(one.recv(WAIT)) for _ in sent] == expected
        got = [two.recv_wanted({0x185}, WAIT) for _ in range(2)]  # type: ignore[attr-defined]
        assert [shape(m) for m in got] == [expected[0], expected[2]]  # not bare: a key python-can packs is missing
        assert two.recv_wanted({0x185}, 0.0) is None  # type: ignore[attr-defined]  # the extended one was filtered


def test_a_handle_left_unread_keeps_eight_times_the_kernels_default_queue(multicast: tuple[str, int]) -> None:
    """2048 frames sent while a handle reads nothing all wait for it: the kernel's default receive queue
    (``net.core.rmem_default``) holds 256 of them here, and an upload client whose notifier waited behind a
    virtual-time run's 8000 frames/s lost its SDO answer (:data:`drives.udp_multicast.RECEIVE_QUEUE`)."""
    needed = 2 << 20  # bytes: 2048 frames at the ~830 the kernel counts for one, with room
    if int(pathlib.Path("/proc/sys/net/core/rmem_max").read_text()) * 2 < needed:
        pytest.skip("net.core.rmem_max caps every socket's receive queue below 2048 frames on this host")
    group, port = multicast
    sent = 2048
    with (open_bus(interface="udp_multicast", channel=group, port=port) as idle,
          open_bus(interface="udp_multicast", channel=group, port=port) as drive):
        for i in range(sent):
            drive.send(can.Message(arbitration_id=0x185, data=i.to_bytes(2, "little"), is_extended_id=False))
        end(group, port)
        received = []
        for _ in range(sent + 1):  # bounded: the frames, then END
            message = idle.recv(WAIT)
            if message is None or message.arbitration_id == END:
                break
            received.append(int.from_bytes(message.data, "little"))
        assert received == list(range(sent))


@pytest.mark.parametrize("scope", ["ff02", "ff15"], ids=["link-local", "site"])
def test_on_an_ipv6_group_too_a_handle_hears_the_others_but_not_itself(scope: str, multicast: tuple[str, int]) -> None:
    # ff02:: is link-local: no socket connects to it without an interface, so the sending socket is
    # bound, not connected, and its looped-back frames carry a link-local source with its scope
    if not socket.has_ipv6:
        pytest.skip("this Python has no IPv6")
    _, port = multicast  # a port unique to this test; the group is IPv6
    group = f"{scope}::{port:x}"
    try:
        plain = can.Bus(interface="udp_multicast", channel=group, port=port, hop_limit=0)
    except (can.CanError, OSError) as error:  # python-can itself cannot: the host has no IPv6 multicast
        pytest.skip(f"no IPv6 multicast on this host: {error}")
    with plain, open_bus(interface="udp_multicast", channel=group, port=port) as one, \
            open_bus(interface="udp_multicast", channel=group, port=port) as other:
        one.send(can.Message(arbitration_id=0x77F, data=[5], is_extended_id=False))
        end(group, port)
        assert heard(one) == []
        assert heard(other) == [0x77F] and heard(plain) == [0x77F]


def test_a_run_with_no_drive_names_no_node_and_logs_its_frames_once(
        multicast: tuple[str, int], tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    # nobody answers: the master's two waits for a drive (its statusword, the boot-up) take 0.1 s each, not the
    # default 1 s; its own frames come back within microseconds on this host if they come at all
    monkeypatch.setitem(CanopenDrive.__init__.__kwdefaults__, "boot_timeout", 0.1)
    group, port = multicast
    result = run_cli(capsys, "run", "cia402-handle", "--interface", "udp_multicast", "--channel", group,
                     "--bus-option", f"port={port}", "--node-id", "5", "--virtual-time", "--out", str(tmp_path))
    assert result.code == 1
    assert "no other node seen on the bus" in result.err
    log = (tmp_path / "bus.asc").read_text().splitlines()
    sent = [line for line in log if " Tx " in line]
    assert sent  # the NMT command and the SDO request it sent
    assert not [line for line in log if " Rx " in line]  # nothing else is on the bus: none of them came back
    # one SDO request (the statusword's, 0x6041): a drive silent to it that sends no boot-up after the NMT reset is
    # not asked again (a third wait made a missing drive take three times the timeout its error names)
    sdo = [line.split()[6:] for line in sent if line.split()[2] == "605"]  # the data bytes of each SDO frame sent
    (request,) = [data for data in sdo if data[0] != "80"]  # canopen's abort after its timeout aside
    assert request[:4] == ["40", "41", "60", "00"]
    assert "no SDO answer within 0.1 s before NMT reset communication and no boot-up within 0.1 s after it" in result.err
