"""The canopen Network the master talks through: who owns it, and who reads the bus.

Three ways a master gets its network, and what closing gives back:

- it opened the bus itself (``interface``/``channel``/... or python-can's configuration
  chain): closing stops the notifier and shuts the bus down;
- the caller gave a :class:`can.BusABC`: the master builds a Network on it; closing stops the
  notifier it started and leaves the bus open;
- the caller gave a :class:`canopen.Network`: closing leaves it as it was found (its notifier
  running again if the master paused it).

While the master cycles in ``direct`` receive mode it reads the bus itself in the calling
thread, so canopen's notifier thread is paused (:meth:`NetworkLink.read_directly`) and
restarted for SDO (:meth:`NetworkLink.read_by_notifier`).

``NetworkLink.tap`` (None: none) is called with every frame the link receives (``sent``
False) or sends (``sent`` True), in the thread that handled it: the cycle's frames
(:func:`~drives.canopen.exchange.receive_direct`, :meth:`~drives.canopen.exchange.CanopenExchange.send`),
what canopen's notifier receives, and what canopen sends (SDO, NMT) on a network the link
built.  A run's bus log is such a tap (it copies each frame into a ring a writer process
drains).  Frames another thread sends on the bus directly (the heartbeat producer's) pass it by.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import can
import canopen

from drives.bus_config import open_bus
from drives.errors import DriveError
from drives.udp_multicast import standard_filters

logger = logging.getLogger(__name__)

NOTIFIER_CYCLE = 0.02  # s: how long canopen's notifier blocks in recv, so pausing it is quick


class ReceiveErrors(can.Listener):
    """Keeps the first exception a canopen notifier's receive raised, and counts them all, so that
    the notifier thread lives on (python-can ends it, with a traceback on stderr, when no listener
    handles the error).  The master turns the error into a :class:`~drives.errors.DriveError` at
    its next exchange; a node that only serves SDO logs it and goes on."""

    def __init__(self, name: str = "") -> None:
        self.name = name
        self.error: BaseException | None = None
        self.count = 0

    def on_message_received(self, msg: can.Message) -> None:
        """Frames are canopen's business."""

    def on_error(self, exc: Exception) -> None:
        """Keep the first receive error, count every one."""
        self.count += 1
        if self.error is None:
            self.error = exc
        logger.warning("%s: CAN receive failed: %r", self.name or "notifier", exc)


Tap = Callable[[can.Message, bool], None]
"""Called with a frame and whether this process sent it (True) or received it (False)."""


class FrameTap(can.Listener):
    """Hands every frame canopen's notifier receives to its link's tap."""

    def __init__(self, link: NetworkLink) -> None:
        self.link = link

    def on_message_received(self, msg: can.Message) -> None:
        """The link's tap, if set, with the frame (received)."""
        tap = self.link.tap
        if tap is not None:
            tap(msg, False)


class TappedNetwork(canopen.Network):
    """canopen's Network whose own sends (SDO, NMT) also go to its link's tap."""

    def __init__(self, bus: can.BusABC, link: NetworkLink) -> None:
        super().__init__(bus)
        self.link = link

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        """Send as canopen does, then hand the frame to the link's tap (sent)."""
        super().send_message(can_id, data, remote)
        tap = self.link.tap
        if tap is not None:
            tap(can.Message(arbitration_id=can_id, data=data, is_extended_id=can_id > 0x7FF, is_remote_frame=remote), True)


def shut_down(network: canopen.Network, name: str) -> None:
    """Stop ``network``'s notifier and shut its bus down, never raising (canopen's own
    ``disconnect()`` re-raises a receive error its notifier once met, long after it was handled)."""
    try:
        if network.notifier is not None:
            network.notifier.stop(timeout=5.0)
        if network.bus is not None:
            network.bus.shutdown()
    except (can.CanError, OSError) as exc:
        logger.warning("%s: closing the bus: %s", name, exc)
    finally:
        network.notifier = None
        network.bus = None


def _restart_notifier(network: canopen.Network) -> None:
    """A fresh canopen notifier reading ``network``'s bus (for SDO, heartbeat and EMCY)."""
    if network.bus is not None:
        network.notifier = can.Notifier(network.bus, network.listeners, network.NOTIFIER_CYCLE)


class NetworkLink:
    """The master's canopen Network (see the module docstring for ownership)."""

    def __init__(
        self,
        name: str,
        *,
        network: canopen.Network | None = None,
        bus: can.BusABC | None = None,
        bus_args: tuple[str | None, Any, int | None, dict[str, Any]] = (None, None, None, {}),
        shared: bool = False,
    ) -> None:
        self.name = name
        self.shared = shared  # several drives use it (one bus): only its owner closes it
        self._given_network = network
        self._given_bus = bus
        self._bus_args = bus_args
        self.network: canopen.Network | None = None
        self.bus: can.BusABC | None = None
        self._passed: set[int] = set()  # the identifiers the bus's receive filters let through (empty: all)
        self.direct = False  # True while the master reads the bus itself
        self._errors = ReceiveErrors(name)
        self._tap_listener = FrameTap(self)
        self.tap: Tap | None = None  # every frame received or sent (module docstring)

    def open(self) -> canopen.Network:
        """The network, connected and with its notifier reading the bus (the same one again if
        already open: several drives on one bus share one link)."""
        if self.network is not None:
            return self.network
        if self._given_network is not None:
            network = self._given_network
        else:
            bus = self._given_bus
            if bus is None:
                interface, channel, bitrate, kwargs = self._bus_args
                bus = open_bus(interface, channel, bitrate, **kwargs)
            network = TappedNetwork(bus, self)
        network.NOTIFIER_CYCLE = NOTIFIER_CYCLE
        for listener in (self._errors, self._tap_listener):
            if listener not in network.listeners:
                network.listeners.append(listener)  # type: ignore[arg-type]  # a can.Listener, as python-can wants
        if network.notifier is None or network.notifier.stopped:
            network.connect()
        self.network = network
        self.bus = network.bus
        return network

    def read_directly(self, wanted: frozenset[int] = frozenset()) -> None:
        """Pause canopen's notifier: from now on the caller reads the bus itself.  On a bus the link
        opened, receive only the standard identifiers ``wanted`` (added to those of earlier calls,
        e.g. one drive's then every axis') and those canopen subscribes to (python-can's filters: on
        ``udp_multicast`` applied before a frame is decoded, on SocketCAN in the kernel); a bus the
        caller gave is left as it is."""
        if self.network is None:
            return
        if not self.direct:
            notifier = self.network.notifier
            if notifier is not None and not notifier.stopped:
                notifier.stop(timeout=5.0)
            failure = self.receive_failure()
            if failure is not None:
                raise DriveError(self.name, f"CAN receive failed: {failure!r}")
            self.direct = True
        needed = wanted | set(self.network.subscribers)
        if self._owns_bus and self.bus is not None and not needed <= self._passed:
            self._passed |= needed
            self.bus.set_filters(standard_filters(self._passed))

    def read_by_notifier(self) -> None:
        """Give the bus back to a fresh canopen notifier (SDO needs it), every frame received again."""
        if not self.direct or self.network is None:
            return
        self.direct = False
        if self._owns_bus and self.bus is not None and self._passed:
            self._passed = set()
            self.bus.set_filters(None)
        _restart_notifier(self.network)

    @property
    def _owns_bus(self) -> bool:
        """Whether the link opened the bus (then its receive filters are the link's to set)."""
        return self._given_bus is None and self._given_network is None

    def receive_failure(self) -> BaseException | None:
        """The first exception the notifier's receive raised, if one did."""
        notifier = self.network.notifier if self.network is not None else None
        return self._errors.error or (None if notifier is None else notifier.exception)

    def close(self) -> None:
        """Release what this link took (see the module docstring); never raises."""
        network = self.network
        if network is None:
            return
        self.network = None
        for listener in (self._errors, self._tap_listener):
            if listener in network.listeners:
                network.listeners.remove(listener)  # type: ignore[arg-type]  # see open()
        try:
            if self._given_network is not None:
                if self.direct:
                    self.direct = False
                    _restart_notifier(network)
                return
            notifier = network.notifier
            if notifier is not None and not notifier.stopped:
                notifier.stop(timeout=5.0)
            network.notifier = None
            if self._given_bus is None and network.bus is not None:
                network.bus.shutdown()
            network.bus = None
        except (can.CanError, OSError) as exc:
            logger.warning("%s: closing the bus: %s", self.name, exc)
        finally:
            self.bus = None
            self.direct = False
