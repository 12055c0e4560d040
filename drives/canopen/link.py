"""The canopen Network the master talks through: who owns it, and who reads the bus.

Three ways a master gets its network, and what closing gives back:

- it opened the bus itself (``interface``/``channel``/... or python-can's configuration
  chain): closing stops the notifier and shuts the bus down;
- the caller gave a :class:`can.BusABC`: the master builds a Network on it; closing stops the
  notifier it started and leaves the bus open;
- the caller gave a :class:`canopen.Network`: closing leaves it as it was found (its notifier
  running again if the master paused it).

While the master cycles it reads the bus itself in the calling thread
(:mod:`drives.canopen.sync_cycle`), so canopen's notifier thread is paused (:meth:`NetworkLink.read_directly`) and
restarted for SDO (:meth:`NetworkLink.read_by_notifier`).

Every frame this process sends on the link goes out through :meth:`NetworkLink.send`: the
cycle's SYNC and RPDOs, the controller's heartbeat, and canopen's own frames (SDO client and
server, NMT: the network's ``send_message`` is routed here while the link holds it).  The
link's :attr:`~NetworkLink.tap`, when set, sees each of them (``sent`` True) and every frame
received on the bus, whoever reads it (the control thread's direct receive, or canopen's
notifier outside the cyclic phase).  Unset, it costs one ``is not None`` test per frame.  It is
called in whichever thread sends or receives (the control thread while it cycles; canopen's
notifier, the heartbeat thread or the upload verdicts' thread outside it), so it must be quick,
never block and be safe from several threads; and it must copy what it keeps of a sent frame:
the cycle reuses its SYNC and RPDO messages, packing each cycle's values into them in place.  A
sent frame's ``timestamp`` is the time it was handed to the bus (stamped only while a tap is set),
a received one's the bus' own.  A tap that also takes a received standard data frame as its parts
(:class:`PartsTap`, the bus log's) gets the cycle's TPDOs that way on ``udp_multicast``: no
:class:`can.Message` is built for them (about 2 us a frame, six frames a cycle for three axes).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

import can
import canopen

from drives.bus_config import open_bus
from drives.errors import DriveError
from drives.os_threads import show_name
from drives.udp_multicast import standard_filters

logger = logging.getLogger(__name__)

NOTIFIER_CYCLE = 0.005  # s: how long canopen's notifier blocks in recv, so that pausing it is quick: the enable's
# 0x6061 read hands the bus to it, and the walk's first step waits for it to pause, RPDOs stopped meanwhile (20 ms
# made the gap after pre-flight 22 ms of the 30 ms RPDO deadline at T = 1 ms); 200 empty receives/s outside the cycle
Tap = Callable[[can.Message, bool], None]  # (frame, sent by this process)
Parts = Callable[[float, int, bytes], None]  # a received standard data frame: (Unix time s, identifier, data)


@runtime_checkable
class PartsTap(Protocol):
    """A :data:`Tap` that also takes a received standard data frame as its parts (module docstring)."""

    def __call__(self, msg: can.Message, sent: bool, /) -> None:
        """See ``msg`` (``sent``: by this process)."""

    def received(self, stamp: float, can_id: int, data: bytes, /) -> None:
        """See a received standard data frame: its Unix time (s), identifier and data."""


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
        """Keep the first receive error, count every one; log the 1st, 10th, 100th, .. (a bus closed
        under the notifier fails every receive at once: 1590 lines in 0.4 s when each was logged)."""
        self.count += 1
        if self.error is None:
            self.error = exc
        if _power_of_ten(self.count):
            logger.warning("%s: CAN receive failed: %r%s", self.name or "notifier", exc,
                           "" if self.count == 1 else f" ({self.count} receive errors so far)")


def _power_of_ten(n: int) -> bool:
    """Whether ``n`` is 1, 10, 100, ..."""
    while n % 10 == 0:
        n //= 10
    return n == 1


class _LinkListener(ReceiveErrors):
    """The link's listener on canopen's notifier: receive errors kept (:class:`ReceiveErrors`), and
    every frame the notifier receives shown to the link's tap."""

    def __init__(self, link: NetworkLink) -> None:
        super().__init__(link.name)
        self._link = link

    def on_message_received(self, msg: can.Message) -> None:
        """The tap sees the frame (canopen's own listener dispatches it)."""
        tap = self._link.tap
        if tap is not None:
            tap(msg, False)


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
        _show_notifier_names(network)


def _show_notifier_names(network: canopen.Network) -> None:
    """The OS sees canopen's notifier thread as ``canopen-notify`` (:mod:`drives.os_threads`)."""
    notifier = network.notifier
    for thread in getattr(notifier, "_readers", ()):
        if isinstance(thread, threading.Thread):
            thread.name = "canopen-notify"
            show_name(thread)


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
        self._tap: Tap | None = None  # sees every frame sent or received on this link (module docstring)
        self.tap_parts: Parts | None = None  # the tap's receive of a frame's parts, where it has one
        self._errors = _LinkListener(self)
        self._send: Callable[[can.Message], None] = self._closed

    @property
    def tap(self) -> Tap | None:
        """What sees every frame sent or received on this link (module docstring); None: nothing."""
        return self._tap

    @tap.setter
    def tap(self, tap: Tap | None) -> None:
        self._tap = tap
        self.tap_parts = tap.received if isinstance(tap, PartsTap) else None

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
                bus = open_bus(interface=interface, channel=channel, bitrate=bitrate, **kwargs)
            network = canopen.Network(bus)
        network.NOTIFIER_CYCLE = NOTIFIER_CYCLE
        if self._errors not in network.listeners:
            network.listeners.append(self._errors)  # type: ignore[arg-type]  # a can.Listener, as python-can wants
        if network.notifier is None or network.notifier.stopped:
            network.connect()
            _show_notifier_names(network)
        network.send_message = self.send_message  # type: ignore[method-assign]  # canopen's frames go out tapped
        self.network = network
        self.bus = network.bus
        self._send = self._sender(network)
        return network

    def _sender(self, network: canopen.Network) -> Callable[[can.Message], None]:
        """How a frame goes out, resolved once: under the network's send lock (shared with canopen's SDO
        and NMT), unless the bus says its ``send`` is safe from several threads at once
        (``concurrent_send``, e.g. the lock-step bus, whose ``send`` runs the receiving node inline:
        holding the lock through that for most of every cycle starves any other sender)."""
        bus = network.bus
        if bus is None:
            return self._closed
        if getattr(bus, "concurrent_send", False):
            return bus.send
        lock, send = network.send_lock, bus.send

        def locked(msg: can.Message) -> None:
            with lock:
                send(msg)
        return locked

    def _closed(self, msg: can.Message) -> None:
        raise DriveError(self.name, "the bus is closed")

    def send(self, msg: can.Message) -> None:
        """Send ``msg`` on the bus (then show it to the tap, ``msg.timestamp`` the Unix time it was
        handed to the bus: before any answer to it can have arrived); python-can's errors as it
        raises them, DriveError "the bus is closed" when the link is not open."""
        tap = self.tap
        if tap is None:
            self._send(msg)
            return
        msg.timestamp = time.time()
        self._send(msg)
        tap(msg, True)

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        """canopen's :meth:`canopen.Network.send_message`, through :meth:`send` (so tapped)."""
        self.send(can.Message(is_extended_id=can_id > 0x7FF, arbitration_id=can_id, data=data, is_remote_frame=remote))

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
        self._send = self._closed
        if "send_message" in vars(network):
            del network.send_message  # canopen's own again (a network the caller gave lives on)
        if self._errors in network.listeners:
            network.listeners.remove(self._errors)  # type: ignore[arg-type]  # see open()
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
