"""One bus handle for every simulated node of a process: a lock-step channel bridged to the bus.

A multi-axis device used to give each node its own bus handle and receive thread.  On
``udp_multicast`` every handle decodes every datagram, so three nodes decoded each frame three
times, and three threads took the GIL in turn to answer one SYNC: measured on this project's
2-core machine, three simulated axes answered a SYNC in 1.2-1.7 ms (median), each TPDO
transmit 140-290 us, where the controller's period was 2 ms.  A drive answers in microseconds.

:class:`BusBridge` is python-can's one-handle shape (canopen's ``Network`` holds every node on one
bus): it opens the bus once and a lock-step channel (:mod:`drives.lockstep_bus`) in the process.
The nodes join the channel, where each frame is handed to every node inline, in the thread that
sends it, in frame order.  The bridge's thread receives from the bus and sends each frame into
the channel, so a SYNC is answered by every node, one after the other, in that one thread, with
no hand-off; whatever a node sends (its TPDOs there, its heartbeat from its timer thread) reaches
the bridge's own handle on the channel, which sends it on the bus at once, in the sending thread (an
outlet of the channel: a node's TPDO is on the bus before the next node is handed the SYNC, not
after every node has answered).  The nodes hear one another on the channel, as on a real bus.

The bus does not give the bridge back its own frames (a CAN controller does not hear itself; on
``udp_multicast``, :class:`drives.udp_multicast.FilteredMulticastBus` drops the datagrams its own
socket sent), so a node's frame reaches the other nodes once, on the channel.

Generic bus infrastructure: nothing here knows CANopen.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from typing import Any

import can

from drives.bus_config import open_bus
from drives.lockstep_bus import LockstepBus

RECV_TIMEOUT = 0.1  # s: how often the bridge's thread looks at its stop flag


class BusBridge:
    """The bus ``bus`` (keyword arguments of :func:`drives.bus_config.open_bus`) joined to a
    lock-step channel of this process (module docstring); the nodes open :attr:`node_bus`.
    ``lost``: called with the error once the bus fails for good (the nodes then hear nothing more)."""

    def __init__(self, bus: Mapping[str, Any], lost: Callable[[BaseException], None]) -> None:
        self._lost = lost
        self.channel = f"sim-bridge-{id(self):x}"
        self._config = dict(bus)
        self._bus: can.BusABC | None = None
        self._local: LockstepBus | None = None
        self._send_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def node_bus(self) -> dict[str, Any]:
        """What each node opens: its handle on the bridged lock-step channel."""
        return {"interface": "lockstep", "channel": self.channel}

    def start(self) -> BusBridge:
        """Open the bus (:class:`~haptic_bus.errors.DriveError` if it cannot be) and the channel, and bridge them."""
        self._bus = open_bus(**self._config)
        self._local = LockstepBus(self.channel, preserve_timestamps=True)  # the bus's receive times, kept
        self._local.set_receiver(self._outward, outlet=True)  # a node's TPDO leaves while the next computes its own
        self._stop.clear()
        self._thread = threading.Thread(target=self._inward, name="sim-bridge", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop bridging; close the channel's handle and the bus."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5 * RECV_TIMEOUT + 1.0)
            self._thread = None
        if self._local is not None:
            self._local.shutdown()
            self._local = None
        if self._bus is not None:
            self._bus.shutdown()
            self._bus = None

    def _outward(self, message: can.Message) -> None:
        """A node's frame, from the channel to the bus."""
        bus = self._bus
        if bus is None:
            return
        with self._send_lock:  # the bridge's thread and the nodes' timer threads send
            bus.send(message)

    def _inward(self) -> None:
        """The bus's frames into the channel (each node answers inline, in this thread) until :meth:`stop`."""
        bus, local = self._bus, self._local
        assert bus is not None and local is not None
        try:
            while not self._stop.is_set():
                message = bus.recv(RECV_TIMEOUT)
                if message is not None:
                    local.send(message)
        except (can.CanError, OSError) as exc:  # the bus is gone
            self._lost(exc)
