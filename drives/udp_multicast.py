"""python-can's ``udp_multicast`` bus with its receive filters applied before a frame is decoded,
and without its own frames.

On ``udp_multicast`` every bus handle receives every frame on the group, its own included, and
python-can turns each datagram into a :class:`can.Message` (msgpack, then the message's
validation) before its software filters look at the identifier: about 30 us a frame here, so a
process with three bus handles on a 1 kHz loop (the master, the controller node, the bus log) spends
a third of a core decoding frames most of which it drops.  :class:`FilteredMulticastBus` is the
same interface with the filters applied where python-can lets a backend apply them
(``_apply_filters``, like a kernel or adapter filter): the datagram's identifier is read from
the msgpack map and a frame no filter wants is dropped before a message is built
(``already_filtered``).  Frames that pass are built exactly as python-can builds them, checked.

:func:`drives.bus_config.open_bus` opens every ``udp_multicast`` bus of the project with it;
without filters it behaves as python-can's.

**Its own frames.**  The kernel loops every datagram on the group back to every socket on this
host, the sender's included, so a python-can ``udp_multicast`` handle receives each frame it sent
(a CAN controller does not: a frame is heard by the other nodes).  A process then counts itself
among the nodes it hears (commissioning's "nodes seen on the bus: ... 127") and its bus log holds
each sent frame twice, as Tx and as Rx.  The sender's address does not tell them apart in
python-can's shape: every handle sends from the socket bound to the group's port, so every
process on a host sends from the same address.  :class:`FilteredMulticastBus` sends from a socket
of its own instead, bound to an ephemeral port (unique on this host for its address family) and not
connected (Linux connects no socket to an IPv6 link-local group such as ``ff02::`` without an
interface; python-can sends there), and drops a received datagram that comes from that port and
from an address of this host.  Another process's handle sends from another port; another host's,
from an address that is not this host's; so their frames still arrive.  What goes on the wire is
python-can's datagram, unchanged: plain python-can handles read it.

**Its receive queue.**  The kernel queues a socket's datagrams up to ``SO_RCVBUF``: on this
host's default (208 KiB, ``net.core.rmem_default``) 256 of python-can's frames (measured), 50 ms
of a one-axis 1 kHz cycle's traffic and 32 ms of a virtual-time run's (8000 frames/s measured);
past that every datagram is dropped, an SDO answer too.  A handle whose thread waits behind
others (a command's canopen notifier on a loaded machine) lost the answer it waited for:
``haptic-bus upload`` beside a virtual-time run reported "no SDO answer" while its socket had
dropped 5344 datagrams in half a second.  :class:`FilteredMulticastBus` asks for
:data:`RECEIVE_QUEUE` bytes, which the kernel caps at ``net.core.rmem_max`` (4 MiB here: 10082
frames queued, measured, 1.2 s of the virtual-time run's traffic).

A receive that drops such a datagram (or one no filter wants) goes on reading what already waits,
even once its timeout is over: ``recv(0)`` -- a poll, as a cycle's drain of late frames makes --
returns a frame that waits behind a dropped one, not None as if nothing waited.  Past its timeout
it reads at most :data:`LATE_READS` datagrams, more than a full queue holds: everything that waited
when the timeout ended is still read, but a sender that refills the queue as fast as the handle
drops its frames no longer holds the receive for as long as it sends (a raw socket sending 126000
unwanted frames/s from another process kept a ``recv(0.1)`` 3.9 s, until it stopped).
"""

from __future__ import annotations

import select
import socket
import struct
import time
from collections.abc import Container
from typing import Any

import can
import msgpack
from can.interfaces.udp_multicast import UdpMulticastBus
from can.interfaces.udp_multicast.bus import SO_TIMESTAMPNS
from can.typechecking import CanFilters

_STANDARD_MASK = 0x7FF
# python-can's datagram of a classic standard data frame (pack_message: an 11-key map, in its order), piece by
# piece around the timestamp (float64), the identifier (msgpack's int), the channel, the dlc and the data (bin 8)
_PLAIN_HEAD = b"\x8b\xa9timestamp\xcb"
_PLAIN_ID = b"\xaearbitration_id"
_PLAIN_FLAGS = b"\xaeis_extended_id\xc2\xafis_remote_frame\xc2\xaeis_error_frame\xc2\xa7channel"
_PLAIN_DLC = b"\xa3dlc"
_PLAIN_DATA = b"\xa4data\xc4"
_PLAIN_TAIL = b"\xa5is_fd\xc2\xaebitrate_switch\xc2\xb5error_state_indicator\xc2"
_AT_ID = len(_PLAIN_HEAD) + 8 + len(_PLAIN_ID)  # where the identifier's msgpack int starts
_PLAIN_LEAST = (_AT_ID + 1 + len(_PLAIN_FLAGS) + 1 + len(_PLAIN_DLC) + 1 + len(_PLAIN_DATA) + 1
                + len(_PLAIN_TAIL))  # a 1-byte identifier, no channel, no data
_TIMESPEC = struct.Struct("@ll")  # struct timespec: seconds, nanoseconds
RECEIVE_QUEUE = 4 << 20
"""bytes of datagrams the kernel may queue for a handle (``SO_RCVBUF``; capped at ``net.core.rmem_max``)."""
LATE_READS = 16384
"""datagrams a receive reads at most once its timeout is over (module docstring): a full :data:`RECEIVE_QUEUE`
holds 10082 of python-can's frames (measured), and about 100 ms of dropping them here."""


class FilteredMulticastBus(UdpMulticastBus):
    """``udp_multicast`` whose ``can_filters`` are applied before decoding, and which does not
    receive the frames it sent (module docstring)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._wanted: frozenset[int] | None = None  # standard identifiers a filter names exactly
        self._masked: tuple[tuple[int, int, bool | None], ...] = ()  # every other filter
        self._late = 0  # datagrams this receive read past its timeout (module docstring)
        super().__init__(*args, **kwargs)
        group = self._multicast
        group._socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_QUEUE)  # module docstring
        ipv4 = group.ip_version == 4
        self._family = socket.AF_INET if ipv4 else socket.AF_INET6
        sender = socket.socket(self._family, socket.SOCK_DGRAM)
        try:
            sender.setsockopt(socket.IPPROTO_IP if ipv4 else socket.IPPROTO_IPV6,
                              socket.IP_MULTICAST_TTL if ipv4 else socket.IPV6_MULTICAST_HOPS,
                              struct.pack("@I", group.hop_limit))
            sender.bind(("0.0.0.0" if ipv4 else "::", 0))
        except OSError as exc:
            sender.close()
            super().shutdown()  # python-can's socket, and the bus marked shut down
            raise can.CanInitializationError(f"could not open a sending socket on the group: {exc}") from exc
        self._sender = sender
        self._group = (group.group, group.port)
        self._own_port = sender.getsockname()[1]  # the ephemeral port receivers see as the sender's
        self._local: dict[tuple[Any, ...], bool] = {}  # source address (and scope) -> one of this host's?
        self._send_timeout: float | None = None
        self._pack = msgpack.Packer(use_bin_type=True).pack  # msgpack.packb's options, without a packer made a frame

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send ``msg`` from this handle's own socket (module docstring); ``timeout`` in s, as python-can's."""
        if msg.is_fd and self.protocol is not can.CanProtocol.CAN_FD:  # the frame's flag first: no property read a frame
            raise can.CanOperationError("cannot send FD message over bus with CAN FD disabled")
        data = self._pack({  # python-can's pack_message (its keys, in its order), with one packer kept
            "timestamp": msg.timestamp,
            "arbitration_id": msg.arbitration_id,
            "is_extended_id": msg.is_extended_id,
            "is_remote_frame": msg.is_remote_frame,
            "is_error_frame": msg.is_error_frame,
            "channel": msg.channel,
            "dlc": msg.dlc,
            "data": msg.data,
            "is_fd": msg.is_fd,
            "bitrate_switch": msg.bitrate_switch,
            "error_state_indicator": msg.error_state_indicator,
        })
        if timeout != self._send_timeout:
            self._send_timeout = timeout
            self._sender.settimeout(timeout)
        try:
            if self._sender.sendto(data, self._group) < len(data):
                raise TimeoutError()
        except TimeoutError:
            raise can.CanTimeoutError() from None
        except OSError as error:
            raise can.CanOperationError("failed to send via socket") from error

    def shutdown(self) -> None:
        """Close the sending socket and python-can's receiving one."""
        self._sender.close()
        super().shutdown()

    def _apply_filters(self, filters: CanFilters | None) -> None:
        """Keep the filters for the receive path: the standard identifiers that filters with the full
        11-bit mask and ``extended`` False name (a set: a frame's test does not grow with the drives on
        the bus), every other filter as ``(can_id & mask, mask, extended or None)``."""
        if not filters:
            self._wanted, self._masked = None, ()
            return
        exact: set[int] = set()
        masked: list[tuple[int, int, bool | None]] = []
        try:
            for f in filters:  # once: python-can's other backends take filters given as an iterator too
                if "extended" in f and f["extended"] not in (True, False):  # None: equal to no frame's kind, so
                    continue  # python-can never matches it (absent, the key takes both kinds)
                if f["can_mask"] == _STANDARD_MASK and f.get("extended") is False:
                    exact.add(f["can_id"] & _STANDARD_MASK)
                else:
                    masked.append((f["can_id"] & f["can_mask"], f["can_mask"], f.get("extended")))
        except (KeyError, TypeError) as exc:  # a filter python-can could not apply either (it would fail at a receive)
            raise ValueError(f"can_filters: each filter a dict of integers can_id and can_mask (and extended), "
                             f"not {filters!r} ({type(exc).__name__}: {exc})") from exc
        self._wanted, self._masked = frozenset(exact), tuple(masked)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        deadline = None if timeout is None else time.perf_counter() + timeout
        self._late = 0
        while (datagram := self._next_datagram(deadline)) is not None:
            message = self._decoded(*datagram)
            if message is not None:
                return message, True
        return None, True

    def recv_wanted(self, wanted: Container[int], timeout: float) -> tuple[int, bytes] | can.Message | None:
        """The next frame that passes the filters within ``timeout`` (s; 0 takes only what already
        waits): a standard data frame whose identifier is in ``wanted``, in python-can's own packing
        (:func:`_plain_frame`), as ``(identifier, data)``, read from the datagram's bytes without the
        :class:`can.Message` that :meth:`recv` builds, checks and stamps (a cycle's TPDOs: 5.4-8.0 us a
        frame where :meth:`recv` takes 10.5-18.4 and an unchecked message 8.2-10.9, 5000 frames five
        times on a loaded machine); any other frame as :meth:`recv` returns it; None if none came.
        Raises as :meth:`recv`."""
        deadline = time.perf_counter() + timeout
        self._late = 0
        while (datagram := self._next_datagram(deadline)) is not None:
            plain = self._plain_wanted(datagram[0], wanted)
            if plain is not None:
                return plain[0], plain[1]
            message = self._decoded(*datagram)
            if message is not None:
                return message
        return None

    def recv_parts(self, wanted: Container[int], timeout: float) -> tuple[int, bytes, float, str | None] | can.Message | None:
        """The frame :meth:`recv` returns within ``timeout`` (s; 0 takes only what already waits), or None if
        none came; raises as :meth:`recv`.  A frame :meth:`recv_wanted` would return bare comes as its parts,
        ``(identifier, data, timestamp, channel)``: the Unix time (s) :meth:`recv` stamps it with and its channel's
        name (or None), the rest :class:`can.Message`'s defaults; any other frame as :meth:`recv` returns it.  The
        cycle's receive when every frame is shown to a tap (the bus log): the tap takes the parts, or a message
        built of them without the check (every field is one it passes)."""
        deadline = time.perf_counter() + timeout
        self._late = 0
        while (datagram := self._next_datagram(deadline)) is not None:
            data, ancillary = datagram
            plain = self._plain_wanted(data, wanted)
            if plain is not None:
                can_id, payload, name = plain
                try:
                    stamp = _timestamp(ancillary)
                except Exception as exception:  # as _message raises it
                    raise can.CanOperationError("could not unpack received message") from exception
                return can_id, payload, stamp, None if name is None else name.decode("ascii")
            message = self._decoded(data, ancillary)
            if message is not None:
                return message
        return None

    def _plain_wanted(self, data: bytes, wanted: Container[int]) -> tuple[int, bytes, bytes | None] | None:
        """:func:`_plain_frame` of ``data`` if its identifier is a standard one in ``wanted`` that the
        filters pass, else None."""
        plain = _plain_frame(data)
        if plain is None or plain[0] not in wanted or plain[0] > _STANDARD_MASK:
            return None
        exact = self._wanted
        return plain if exact is None or self._wants(exact, plain[0], False) else None

    def _decoded(self, data: bytes, ancillary: list[tuple[int, int, bytes]]) -> can.Message | None:
        """The checked message of datagram ``data`` as :meth:`recv` returns it, or None if no filter wants it
        (or it is an FD frame on a bus that is not FD)."""
        fields = self._wanted_fields(data)
        return None if fields is None else self._message(fields, ancillary)

    def _next_datagram(self, deadline: float | None) -> tuple[bytes, list[tuple[int, int, bytes]]] | None:
        """The next datagram on the group that this handle did not send, as ``(data, ancillary)``: one
        that already waits is taken at once, else the socket is waited on until ``deadline``
        (``time.perf_counter()`` s; None: for ever).  None once ``deadline`` passed with nothing
        waiting, or with :data:`LATE_READS` datagrams read past it in this receive."""
        group = self._multicast
        sock = group._socket
        while True:
            if deadline is not None and time.perf_counter() >= deadline:
                if self._late >= LATE_READS:
                    return None
                self._late += 1
            try:
                data, ancillary, _, sender = sock.recvmsg(group.max_buffer, group.received_ancillary_buffer_size,
                                                          socket.MSG_DONTWAIT)
            except BlockingIOError:
                pass
            except OSError as exc:
                raise can.CanOperationError(f"failed to receive from the IP/UDP socket: {exc}") from exc
            else:
                if sender[1] == self._own_port and self._is_local(sender):  # its own frame, looped back
                    continue
                return data, ancillary
            left = None if deadline is None else deadline - time.perf_counter()
            if left is not None and left <= 0.0:
                return None
            try:
                if not select.select([sock], [], [], left)[0]:
                    return None
            except OSError as exc:  # the interface went down, the socket closed
                raise can.CanOperationError(f"failed to wait for the IP/UDP socket: {exc}") from exc

    def _is_local(self, sender: tuple[Any, ...]) -> bool:
        """Whether the datagram's ``sender`` address (IPv6: with its scope, a link-local one's interface)
        is one of this host's: a socket binds to it; asked once per address."""
        key = (sender[0], *sender[3:4])
        local = self._local.get(key)
        if local is None:
            with socket.socket(self._family, socket.SOCK_DGRAM) as probe:
                try:
                    probe.bind((sender[0], 0, *sender[2:4]))
                    local = True
                except OSError:
                    local = False
            self._local[key] = local
        return local

    def _wanted_fields(self, data: bytes) -> dict[str, Any] | None:
        """The frame's fields as python-can packs them in datagram ``data``, or None if no filter
        wants the frame (all do without filters)."""
        try:
            fields = msgpack.unpackb(data, raw=False)
            if type(fields) is not dict:
                raise TypeError(f"not a frame's fields: {fields!r:.80}")
            exact = self._wanted  # a key left out is can.Message's default, as python-can builds the frame it filters
            return fields if exact is None or self._wants(exact, fields.get("arbitration_id", 0),
                                                          fields.get("is_extended_id", True)) else None
        except Exception as exception:  # what python-can's own unpacking raises for a datagram it cannot use
            raise can.CanOperationError("could not unpack received message") from exception

    def _message(self, fields: dict[str, Any], ancillary: list[tuple[int, int, bytes]]) -> can.Message | None:
        """The checked :class:`can.Message` of ``fields``, stamped from the datagram's ``ancillary``
        data (the kernel's receive time, as python-can's; without it, now); None for an FD frame on a
        bus that is not FD, as python-can drops it."""
        try:
            message = can.Message(check=True, **(fields | {"timestamp": _timestamp(ancillary)}))
        except Exception as exception:
            raise can.CanOperationError("could not unpack received message") from exception
        return message if self.protocol is can.CanProtocol.CAN_FD or not message.is_fd else None

    def _wants(self, exact: frozenset[int], can_id: int, extended: bool) -> bool:
        # == as python-can compares a filter's "extended" with the frame's (0 is False there, None is not)
        if extended == False and can_id & _STANDARD_MASK in exact:  # noqa: E712
            return True
        return any((only is None or only == extended) and can_id & mask == masked for masked, mask, only in self._masked)


def _plain_frame(data: bytes) -> tuple[int, bytes, bytes | None] | None:
    """``(identifier, data, channel)`` (the channel's ASCII bytes, or None) of a datagram that is exactly
    python-can's packing of a classic standard data frame (``pack_message``: every key, in its order, a float
    timestamp, flags False, no channel or an ASCII one of at most 31 characters, ``dlc`` the data's length, at
    most 8), read from its bytes; None for any other datagram (it may still be such a frame packed otherwise: the
    receive then decodes it with msgpack).  Whatever it returns, msgpack's decoding gives the same fields, so the
    receive's checks pass them as they are."""
    if not (len(data) >= _PLAIN_LEAST and data.startswith(_PLAIN_HEAD) and data.startswith(_PLAIN_ID, 20)
            and data.endswith(_PLAIN_TAIL)):
        return None
    at = _AT_ID
    first = data[at]
    if first < 0x80:  # positive fixint
        can_id, at = first, at + 1
    elif first == 0xCC:  # uint 8
        can_id, at = data[at + 1], at + 2
    elif first == 0xCD:  # uint 16, big-endian
        can_id, at = data[at + 1] << 8 | data[at + 2], at + 3
    else:
        return None
    if not data.startswith(_PLAIN_FLAGS, at):
        return None
    at += len(_PLAIN_FLAGS)
    channel = data[at]
    name: bytes | None = None
    if channel == 0xC0:  # nil
        at += 1
    elif 0xA0 <= channel <= 0xBF and (name := data[at + 1:at + 1 + (channel & 0x1F)]).isascii():  # a fixstr
        at += 1 + (channel & 0x1F)
    else:
        return None
    if not data.startswith(_PLAIN_DLC, at):
        return None
    at += len(_PLAIN_DLC)
    if at + 1 + len(_PLAIN_DATA) + 1 + len(_PLAIN_TAIL) > len(data) or not data.startswith(_PLAIN_DATA, at + 1):
        return None
    dlc = data[at]
    at += 1 + len(_PLAIN_DATA)
    size = data[at]
    at += 1
    if dlc != size or size > 8 or at + size + len(_PLAIN_TAIL) != len(data):
        return None
    return can_id, data[at:at + size], name


def _timestamp(ancillary: list[tuple[int, int, bytes]]) -> float:
    """Unix time (s) of the kernel's ``SO_TIMESTAMPNS`` in a datagram's ancillary data (python-can asks
    for it where the platform has it), else now."""
    if len(ancillary) != 1:
        return time.time()
    level, kind, stamp = ancillary[0]
    if level != socket.SOL_SOCKET or kind != SO_TIMESTAMPNS or len(stamp) != _TIMESPEC.size:
        raise can.CanOperationError("received control message type that was not requested")
    seconds, nanoseconds = _TIMESPEC.unpack(stamp)
    if not 0 <= nanoseconds < 1_000_000_000:
        raise can.CanOperationError(f"timestamp nanoseconds field out of range: {nanoseconds}")
    return seconds + nanoseconds * 1e-9


def parts_message(can_id: int, data: bytes, stamp: float, channel: str | None) -> can.Message:
    """The :class:`can.Message` :meth:`FilteredMulticastBus.recv` returns for a frame that
    :meth:`~FilteredMulticastBus.recv_parts` gave as its parts (every other field can.Message's default)."""
    return can.Message(timestamp=stamp, arbitration_id=can_id, is_extended_id=False, data=data, channel=channel)


def standard_filters(can_ids: set[int] | frozenset[int]) -> CanFilters:
    """python-can filters that pass exactly the standard (11-bit) ``can_ids``."""
    return [{"can_id": can_id, "can_mask": _STANDARD_MASK, "extended": False} for can_id in sorted(can_ids)]
