"""The lock-step bus (drives.lockstep_bus): python-can discovers it, it delivers each frame in the
sender's thread, in order, to copies; the simulated drive and the controller run on it in one
thread, bit-identical to python-can's threaded virtual bus and deterministic run to run."""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager
from typing import Any

import can
import numpy as np
import pytest

from drives.cia402 import State, decode_statusword
from drives.lockstep_bus import LockstepBus

TRAJECTORY = ("time_s", "position_m", "velocity_m_per_s", "force_n", "torque_permille", "energy_j", "scene_id", "scale")
JOIN = 10.0  # s: the longest any helper thread of these tests is waited for (they finish in milliseconds)


def frame(can_id: int, data: bytes = b"") -> can.Message:
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=False)


@pytest.fixture
def pair(channel: str) -> Iterator[tuple[LockstepBus, LockstepBus]]:
    """Two bus handles on one fresh lock-step channel."""
    a, b = LockstepBus(channel=channel), LockstepBus(channel=channel)
    yield a, b
    a.shutdown()
    b.shutdown()


# ----------------------------------------------------------------------------- the interface

def test_python_can_discovers_the_interface_through_its_entry_point(channel: str) -> None:
    assert "lockstep" in can.interfaces.VALID_INTERFACES
    bus = can.Bus(interface="lockstep", channel=channel)
    try:
        assert isinstance(bus, LockstepBus)
        assert {"interface": "lockstep", "channel": channel} in can.detect_available_configs(["lockstep"])
    finally:
        bus.shutdown()


def test_queued_frames_arrive_in_order_as_copies(pair: tuple[LockstepBus, LockstepBus]) -> None:
    a, b = pair
    sent = frame(0x181, b"\x01\x02")
    a.send(sent)
    sent.data[0] = 0xFF  # the sender reuses its message: the receiver's copy must not change
    a.send(frame(0x182, b"\x03"))
    first, second = b.recv(0.0), b.recv(0.0)
    assert first is not None and second is not None
    assert (first.arbitration_id, bytes(first.data)) == (0x181, b"\x01\x02")
    assert (second.arbitration_id, bytes(second.data)) == (0x182, b"\x03")
    assert first.is_rx and first is not sent
    assert b.recv(0.0) is None and a.recv(0.0) is None  # nobody hears itself by default


def test_an_inline_receiver_runs_in_the_senders_thread_before_send_returns(pair: tuple[LockstepBus, LockstepBus]) -> None:
    a, b = pair
    seen: list[tuple[int, int]] = []
    b.set_receiver(lambda msg: seen.append((msg.arbitration_id, threading.get_ident())))
    a.send(frame(0x080))
    assert seen == [(0x080, threading.get_ident())]
    b.set_receiver(None)  # back to the queue
    a.send(frame(0x081))
    queued = b.recv(0.0)
    assert seen == [(0x080, threading.get_ident())] and queued is not None and queued.arbitration_id == 0x081


def test_a_frame_sent_from_a_receiver_is_delivered_after_it_returns_in_order(pair: tuple[LockstepBus, LockstepBus],
                                                                             channel: str) -> None:
    a, b = pair
    channel_c = LockstepBus(channel=channel)
    order: list[str] = []
    try:
        def on_b(msg: can.Message) -> None:
            order.append(f"b got {msg.arbitration_id:#x}")
            if msg.arbitration_id == 0x080:
                b.send(frame(0x185))  # an answer from inside the receiver
                order.append("b answered")

        b.set_receiver(on_b)
        channel_c.set_receiver(lambda msg: order.append(f"c got {msg.arbitration_id:#x}"))
        a.send(frame(0x080))
        # no recursion: c gets the SYNC before b's answer, which waits until b's receiver returned
        assert order == ["b got 0x80", "b answered", "c got 0x80", "c got 0x185"]
        answer = a.recv(0.0)  # the queued bus handle has the answer before send returned
        assert answer is not None and answer.arbitration_id == 0x185
    finally:
        channel_c.shutdown()


def test_an_outlet_is_handed_an_answer_at_once_while_the_others_wait_in_line(pair: tuple[LockstepBus, LockstepBus],
                                                                            channel: str) -> None:
    a, b = pair
    bridge = LockstepBus(channel=channel)
    order: list[str] = []
    try:
        def on_b(msg: can.Message) -> None:
            order.append(f"b got {msg.arbitration_id:#x}")
            if msg.arbitration_id == 0x080:
                b.send(frame(0x185, b"\x07"))
                order.append("b answered")

        b.set_receiver(on_b)
        bridge.set_receiver(lambda msg: order.append(f"bridge got {msg.arbitration_id:#x} {bytes(msg.data).hex()} "
                                                     f"rx {msg.is_rx} on {msg.channel}"), outlet=True)
        a.send(frame(0x080))
        # the outlet (a bridge to a bus) is handed each frame in the send, before the inline receivers' line
        # goes on: b's answer inside b's send, a copy like any receiver's; the inline receivers' order is unchanged
        assert order == ["bridge got 0x80  rx True on " + channel, "b got 0x80", "bridge got 0x185 07 rx True on " + channel,
                         "b answered"]
        answer = a.recv(0.0)
        assert answer is not None and answer.arbitration_id == 0x185
        bridge.set_receiver(None)  # no longer an outlet: its frames are queued again
        a.send(frame(0x081))
        queued = bridge.recv(0.0)
        assert queued is not None and queued.arbitration_id == 0x081 and not bridge._outlet
    finally:
        bridge.shutdown()


def test_own_messages_and_a_failing_receiver(pair: tuple[LockstepBus, LockstepBus], channel: str) -> None:
    a, b = pair
    echo = LockstepBus(channel=channel, receive_own_messages=True)
    try:
        echo.send(frame(0x100))
        own = echo.recv(0.0)
        assert own is not None and own.arbitration_id == 0x100 and not own.is_rx

        def broken(msg: can.Message) -> None:
            raise ValueError("a receiver's bug")

        b.set_receiver(broken)
        a.send(frame(0x101))  # the sender is not hurt
        assert b.receive_errors == 1
        other = echo.recv(0.0)  # and the other bus handles still got it
        assert other is not None and other.arbitration_id == 0x101
    finally:
        echo.shutdown()


def test_a_closed_bus_handle_leaves_the_channel(pair: tuple[LockstepBus, LockstepBus]) -> None:
    a, b = pair
    b.shutdown()
    a.send(frame(0x181))  # nobody left to receive: no error
    with pytest.raises(can.CanOperationError):
        b.send(frame(0x181))


def test_two_nodes_answering_each_other_from_their_own_threads_do_not_deadlock(pair: tuple[LockstepBus, LockstepBus]) -> None:
    """Each handle's receiver answers under its own node lock; two threads start ping-pongs at once."""
    a, b = pair
    rounds = 2_000
    counts = {"a": 0, "b": 0}
    locks = {"a": threading.RLock(), "b": threading.RLock()}  # re-entrant, as the module asks (and the drive's is)

    def answering(name: str, bus: can.BusABC) -> Callable[[can.Message], None]:
        def receive(msg: can.Message) -> None:
            with locks[name]:  # like the simulated drive's lock around its handlers
                counts[name] += 1
                if msg.data[0] < 200:
                    bus.send(frame(0x300, bytes([msg.data[0] + 1])))
        return receive

    a.set_receiver(answering("a", a))
    b.set_receiver(answering("b", b))

    def start(name: str, bus: can.BusABC) -> None:
        for _ in range(rounds // 200):
            with locks[name]:
                bus.send(frame(0x300, b"\x00"))

    threads = [threading.Thread(target=start, args=("a", a)), threading.Thread(target=start, args=("b", b))]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(JOIN)
    assert not any(thread.is_alive() for thread in threads), "deadlocked"
    assert counts["a"] + counts["b"] == 2 * (rounds // 200) * 201  # every frame of every ping-pong delivered


class SlowToTakeSync(queue.Queue):
    """A receive queue that takes 0.4 s to accept a SYNC (0x080)."""

    def put(self, item: can.Message, block: bool = True, timeout: float | None = None) -> None:
        if item.arbitration_id == 0x080:
            threading.Event().wait(0.4)
        super().put(item, block, timeout)


def test_every_queue_has_a_frame_before_any_inline_receiver_can_answer_it(channel: str) -> None:
    """The order a sniffer sees is the order of cause and effect, even while another thread is
    delivering on the channel: a drive (inline) answers SYNC 0x080 with TPDO 0x185; a slow node
    (inline) keeps a second thread inside its receiver for 0.2 s; the sniffer (a queue) takes
    0.4 s to accept the SYNC.  The drive may only see the SYNC once the sniffer has it."""
    drive, slow, sniffer, master = (LockstepBus(channel=channel) for _ in range(4))
    inside = threading.Event()
    drive.set_receiver(lambda msg: drive.send(frame(0x185)) if msg.arbitration_id == 0x080 else None)
    slow.set_receiver(lambda msg: (inside.set(), threading.Event().wait(0.2)) if msg.arbitration_id == 0x700 else None)
    sniffer._queue = SlowToTakeSync()  # type: ignore[assignment]
    try:
        busy = threading.Thread(target=master.send, args=(frame(0x700, b"\x05"),))  # delivered by this thread, slowly
        busy.start()
        assert inside.wait(JOIN)
        master.send(frame(0x080))  # the busy thread delivers it to the drive when the slow node returns
        busy.join(JOIN)
        for _ in range(100):  # the drive's answer, bounded
            if sniffer._queue.qsize() >= 3:
                break
            threading.Event().wait(0.01)
        assert [sniffer.recv(0.0).arbitration_id for _ in range(3)] == [0x700, 0x080, 0x185]  # type: ignore[union-attr]
    finally:
        for bus in (drive, slow, sniffer, master):
            bus.shutdown()


# ----------------------------------------------------------------------------- drive and controller on it

def _trajectory(interface: str, cycles: int) -> np.ndarray:
    from haptic_bus.app.profiles import load_profile
    from haptic_bus.app.rig import simulated_canopen
    from haptic_bus.control.controller import WallController

    profile = load_profile("cia402-handle")
    with simulated_canopen(profile, interface=interface) as (_, drive):
        controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit)
        summary = controller.run(cycles)
        assert summary.exit_reason == "completed", summary.error
        return np.column_stack([controller.record.column(name) for name in TRAJECTORY])


def test_the_drive_serves_the_controller_in_the_controllers_thread() -> None:
    from haptic_bus.app.profiles import load_profile
    from haptic_bus.app.rig import simulated_canopen
    from haptic_bus.control.controller import WallController

    profile = load_profile("cia402-handle")
    with simulated_canopen(profile) as (sim, drive):
        threads: set[int] = set()
        plant_sync = sim.drive.sync

        def observed_sync() -> None:
            threads.add(threading.get_ident())
            plant_sync()

        sim.drive.sync = observed_sync  # type: ignore[method-assign]
        controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit)
        assert controller.run(200).exit_reason == "completed"
    assert threads == {threading.get_ident()}


def test_a_drive_may_be_handed_a_sync_by_the_thread_that_sends_for_it(channel: str) -> None:
    """The simulated drive's timer thread sends its heartbeat under the node's send lock; on this
    bus that send may deliver the master's pending SYNC to the same node, which answers with its
    TPDO from inside the send.  The lock must let it (a plain Lock deadlocked that thread)."""
    from sim_drive.canopen.slave import CanopenSimDrive

    master = LockstepBus(channel=channel)
    sim = CanopenSimDrive({"interface": "lockstep", "channel": channel}, 5).start()
    try:
        master.send(frame(0x000, bytes([0x01, 5])))  # NMT start: its synchronous TPDOs answer SYNCs
        done = threading.Event()

        def send_under_the_nodes_lock() -> None:
            with sim._network.send_lock:  # type: ignore[union-attr]  # what its heartbeat holds
                master.send(frame(0x080))  # delivered in this thread: the node answers inside
            done.set()

        threading.Thread(target=send_under_the_nodes_lock, daemon=True).start()
        assert done.wait(JOIN), "the node's send deadlocked"
        assert 0x185 in [m.arbitration_id for m in iter(lambda: master.recv(0.0), None)]
    finally:
        sim.stop()
        master.shutdown()


def test_trajectories_are_bit_identical_to_the_threaded_virtual_bus_and_run_to_run() -> None:
    # The same plant, controller and frames; only who carries the frames differs: == , no tolerance.
    # 1000 cycles: the hand's 3 N push reaches the wall at cycle 46 and the handle has settled by about
    # cycle 1000 (within 70 nm from there on, measured over 3000); the frames of every later cycle are
    # of the same kinds, carried the same way (3000 cycles here cost 1 s of CPU more)
    lockstep = _trajectory("lockstep", 1_000)
    assert np.array_equal(lockstep, _trajectory("virtual", 1_000))
    assert np.array_equal(lockstep, _trajectory("lockstep", 1_000))
    assert np.ptp(lockstep[:, 1]) > 1e-3  # it did something: the handle moved by more than a millimetre


def test_a_short_soak_keeps_the_position_an_exact_integer_sum() -> None:
    from haptic_bus.app.profiles import load_profile
    from haptic_bus.app.rig import simulated_canopen
    from haptic_bus.bench.soak import observe_inputs
    from haptic_bus.control.controller import WallController
    from sim_drive.operator import operator_from_table

    profile = load_profile("cia402-handle")
    operator = operator_from_table({"model": "sinusoid", "amplitude": 5.0, "frequency": 2.0, "offset": 2.0})
    with simulated_canopen(profile, operator=operator) as (_, drive):
        controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit)
        total = [0, 0]

        def add(inputs: Any) -> None:  # every input the controller gets, summed apart from it
            total[0] += inputs.velocity
            total[1] += abs(inputs.velocity)

        observe_inputs(drive, add)
        assert controller.run(10_000).exit_reason == "completed"
    assert controller.integrators[0].counts == total[0]  # integers: exact, no tolerance
    last = controller.record.latest()
    assert last is not None and last["position_m"] == controller.integrators[0].origin + controller.integrators[0].step * total[0]
    assert total[1] > 10_000 * 1_000  # the handle kept moving (|v| well above one count per cycle)


def test_the_drive_still_keeps_its_timers_on_a_lockstep_bus(canopen_rig: Callable[..., AbstractContextManager[Any]],
                                                            frames: Any) -> None:
    """Commissioning over lock-step frames; then heartbeats come from the drive's timer thread
    (0x1017 = 100 ms, written at commissioning) with nobody sending it anything."""
    with canopen_rig("lockstep") as rig:
        rig.drive.enable()
        assert decode_statusword(rig.drive.read_inputs().statusword) is State.OPERATION_ENABLED
        with rig.spec.open() as listener:
            assert frames.recv_id(listener, 0x700 + frames.node, timeout=5 * frames.wait) is not None
