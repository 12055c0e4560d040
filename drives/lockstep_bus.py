"""python-can interface ``lockstep``: an in-process CAN bus that delivers each frame synchronously.

python-can's ``virtual`` bus deep-copies every frame into a ``queue.Queue`` per receiver and
hands it to the receiver's thread.  On this bus a receiver is one of two kinds:

- a **queue** (the default): ``recv`` returns the frames in order, as on any python-can bus
  (canopen's notifier, a master that reads the bus itself, a sniffer);
- an **inline receiver** (:meth:`LockstepBus.set_receiver`): a callable the frame is handed to
  in the *sender's* thread before ``send`` returns;
- an **outlet** (``set_receiver(..., outlet=True)``): an inline receiver that never sends on the
  channel (a bridge to another bus), handed each frame in the sender's thread at once, even while
  another thread delivers to the inline receivers.

So a node that serves frames inline (the simulated drive) has answered a SYNC before the
master's ``send`` returns, and the master's next ``recv`` finds the TPDO without a thread
hand-off: both sides run in one thread, in frame order, deterministically.

Inline receivers of one channel never run concurrently and never recursively: a frame sent
while another thread (or the same thread, from inside a receiver) is delivering is queued on
the channel and delivered by that thread, in order, before it returns.  No sender ever
blocks on another node's lock, so two nodes that send to each other from their own threads
cannot deadlock; a node whose receiver takes a lock that the node also holds while it sends
must make it re-entrant (``threading.RLock``), since the sending thread may be the one that
delivers the answer to it.  An outlet is the exception: it answers nothing on the channel, so
nothing it does can come back to the nodes, and it need not wait in the channel's line: a node's
answer to a SYNC leaves through it while the next node is still being handed that SYNC, as on a
real bus, where each drive's TPDO is on the wire while the others compute theirs.  Its frames
arrive in the order of the ``send`` calls of each thread; frames sent from several threads at
once reach it concurrently (it makes its own sends thread-safe).  A receiver that raises is counted and logged on its bus
(:attr:`LockstepBus.receive_errors`); the sender and the other receivers carry on.

Every receiver gets its own copy of the frame (the sender may reuse its ``can.Message``),
stamped with ``time.time()`` at sending unless ``preserve_timestamps``.  Registered for
python-can as ``interface="lockstep"`` (entry point group ``can.interface``)::

    bus = can.Bus(interface="lockstep", channel="axis-1")

Generic bus infrastructure: nothing here knows CANopen.
"""

from __future__ import annotations

import collections
import logging
import queue
import threading
import time
from collections.abc import Callable
from typing import Any

import can
from can.typechecking import AutoDetectedConfig

logger = logging.getLogger(__name__)

Receiver = Callable[[can.Message], None]


class _Channel:
    """The buses on one channel name and the frames waiting for their inline receivers."""

    def __init__(self, name: Any) -> None:
        self.name = name
        self.buses: tuple[LockstepBus, ...] = ()
        self.pending: collections.deque[tuple[LockstepBus, can.Message]] = collections.deque()
        self.delivering = threading.Lock()  # held by the one thread delivering to inline receivers

    def deliver(self) -> None:
        """Hand every pending frame to its inline receiver, unless another thread is doing it."""
        pending = self.pending
        while pending:
            if not self.delivering.acquire(blocking=False):
                return  # the thread that holds it delivers what we queued
            try:
                while pending:
                    bus, message = pending.popleft()
                    bus._hand_over(message)
            finally:
                self.delivering.release()
            # a frame queued between our last look and the release is ours to deliver: loop


_channels: dict[Any, _Channel] = {}
_channels_lock = threading.Lock()


class LockstepBus(can.BusABC):
    """One node's bus handle on the lock-step channel ``channel`` (any hashable name).

    ``receive_own_messages``: also receive the frames this bus handle sends.
    ``preserve_timestamps``: keep the sender's ``timestamp`` instead of the time of sending.
    """

    concurrent_send = True
    """:meth:`send` may be called from several threads at once, no lock needed (see the module docstring)."""

    def __init__(self, channel: Any = "lockstep", receive_own_messages: bool = False,
                 preserve_timestamps: bool = False, **kwargs: Any) -> None:
        self.channel_info = f"lock-step in-process bus, channel {channel!r}"
        self.receive_own_messages = receive_own_messages
        self.preserve_timestamps = preserve_timestamps
        self.receive_errors = 0
        self._queue: queue.SimpleQueue[can.Message] = queue.SimpleQueue()
        self._receiver: Receiver | None = None
        self._outlet = False
        self._open = True
        super().__init__(channel=channel, **kwargs)
        with _channels_lock:
            self._channel = _channels.setdefault(channel, _Channel(channel))
            self._channel.buses += (self,)

    # ------------------------------------------------------------------ receiving

    def set_receiver(self, receiver: Receiver | None, outlet: bool = False) -> None:
        """Hand every frame for this bus handle to ``receiver`` in the sender's thread (None: queue them
        for :meth:`recv` again).  ``receiver`` should not raise; if it does, the error is counted.
        ``outlet``: ``receiver`` never sends on this channel and is thread-safe, so it is handed each frame
        at once rather than in the channel's line (module docstring)."""
        self._outlet = outlet and receiver is not None
        self._receiver = receiver

    def _hand_over(self, message: can.Message) -> None:
        receiver = self._receiver
        if receiver is None or not self._open:
            self._queue.put(message)
            return
        try:
            receiver(message)
        except Exception:  # a receiver's failure is its node's, never the sender's
            self.receive_errors += 1
            logger.exception("%s: the inline receiver failed on frame 0x%X", self.channel_info, message.arbitration_id)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        self._check_open()
        if timeout is not None and timeout <= 0.0 and self._queue.empty():
            return None, False  # the common poll of an empty queue, without raising queue.Empty
        try:
            return self._queue.get(True, timeout if timeout is None or timeout > 0.0 else 0.0), False
        except queue.Empty:
            return None, False

    # ------------------------------------------------------------------ sending

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Put a copy of ``msg`` into every other bus handle's queue, or hand it to its inline
        receiver before returning (see the module docstring for ordering)."""
        self._check_open()
        stamp = msg.timestamp if self.preserve_timestamps else time.time()
        channel = self._channel
        inline = []
        outlets = []
        for bus in channel.buses:
            if bus is self and not self.receive_own_messages:
                continue
            copy = can.Message(timestamp=stamp, arbitration_id=msg.arbitration_id, is_extended_id=msg.is_extended_id,
                               is_remote_frame=msg.is_remote_frame, is_error_frame=msg.is_error_frame,
                               channel=channel.name, dlc=msg.dlc, data=bytearray(msg.data), is_fd=msg.is_fd,
                               is_rx=bus is not self, bitrate_switch=msg.bitrate_switch,
                               error_state_indicator=msg.error_state_indicator)
            if bus._receiver is None:
                bus._queue.put(copy)
            elif bus._outlet:
                outlets.append((bus, copy))
            else:
                inline.append((bus, copy))
        # Only now may an inline receiver see the frame: a thread delivering concurrently could
        # otherwise hand it over, and queue the answers, before a queue later in the list had it
        # (measured: a sniffer saw a drive's TPDOs before the SYNC they answered, 1 run in 30).
        for bus, copy in outlets:  # nothing comes back from an outlet: it need not wait in line
            bus._hand_over(copy)
        if inline:
            channel.pending.extend(inline)
            channel.deliver()

    # ------------------------------------------------------------------ lifecycle

    def _check_open(self) -> None:
        if not self._open:
            raise can.CanOperationError("the lock-step bus is closed")

    def shutdown(self) -> None:
        """Leave the channel (frames sent later do not reach this bus handle)."""
        super().shutdown()
        if not self._open:
            return
        self._open = False
        self._receiver = None
        with _channels_lock:
            channel = self._channel
            channel.buses = tuple(bus for bus in channel.buses if bus is not self)
            if not channel.buses and _channels.get(channel.name) is channel:
                del _channels[channel.name]

    @staticmethod
    def _detect_available_configs() -> list[AutoDetectedConfig]:
        with _channels_lock:
            return [{"interface": "lockstep", "channel": name} for name in _channels]
