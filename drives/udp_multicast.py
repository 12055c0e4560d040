"""python-can's ``udp_multicast`` bus with its receive filters applied before a frame is decoded.

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
"""

from __future__ import annotations

import time
from typing import Any

import can
import msgpack
from can.interfaces.udp_multicast import UdpMulticastBus
from can.typechecking import CanFilters

_STANDARD_MASK = 0x7FF


class FilteredMulticastBus(UdpMulticastBus):
    """``udp_multicast`` whose ``can_filters`` are applied before decoding (module docstring)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._wanted: tuple[tuple[int, int, bool | None], ...] | None = None
        super().__init__(*args, **kwargs)

    def _apply_filters(self, filters: CanFilters | None) -> None:
        """Keep the filters as ``(can_id & mask, mask, extended or None)`` for the receive path."""
        if not filters:
            self._wanted = None
            return
        self._wanted = tuple((f["can_id"] & f["can_mask"], f["can_mask"], f.get("extended")) for f in filters)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        deadline = None if timeout is None else time.monotonic() + timeout
        left = timeout
        while True:
            result = self._multicast.recv(left)
            if not result:
                return None, True
            data, _, timestamp = result
            try:
                fields = msgpack.unpackb(data, raw=False)
                wanted = self._wanted is None or self._wants(fields["arbitration_id"], fields["is_extended_id"])
                message = can.Message(check=True, **(fields | {"timestamp": timestamp})) if wanted else None
            except Exception as exception:  # what python-can's own unpacking raises for a datagram it cannot use
                raise can.CanOperationError("could not unpack received message") from exception
            if message is not None and (self.protocol is can.CanProtocol.CAN_FD or not message.is_fd):
                return message, True
            if deadline is not None:
                left = deadline - time.monotonic()
                if left <= 0.0:
                    return None, True

    def _wants(self, can_id: int, extended: bool) -> bool:
        return any((only is None or only == extended) and can_id & mask == masked for masked, mask, only in self._wanted or ())


def standard_filters(can_ids: set[int] | frozenset[int]) -> CanFilters:
    """python-can filters that pass exactly the standard (11-bit) ``can_ids``."""
    return [{"can_id": can_id, "can_mask": _STANDARD_MASK, "extended": False} for can_id in sorted(can_ids)]
