"""No frame can silence either side: 10 000 random frames at a running drive and a running controller.

Frames of every id class the drive owns (NMT, SYNC, its EMCY, TPDOs, RPDOs, SDO both ways,
heartbeat) plus random ids, lengths 0..8, random bytes, from a seeded generator, while the
controller cycles against the drive; and receive errors injected on the bus.  Afterwards the
drive still answers SDO and still beats; the controller either kept cycling or stopped with a
typed :class:`~drives.errors.DriveError` (torque zero, its record kept).  The same holds for
the command ``haptic-bus run`` against the simulated drive in another process: exit 0 or 1, the summary
printed, record.csv and run.json written.  Bounded in time; the seed is fixed.
"""

from __future__ import annotations

import json
import os
import random
import signal
import socket
import struct
import threading
import time

import can
import msgpack
import pytest

from drives.bus_config import open_bus
from drives.errors import DriveError
from haptic_bus.app.cli import main
from haptic_bus.app.run_options import exit_status
from tests.conftest import SDO_WAIT
from tests.raw_bus import FailingBus

NODE = 5
SEED = 20261130
FRAMES = 10_000


def random_frame(rng: random.Random) -> can.Message:
    """A frame of an id class the drive owns (or any id), of any length 0..8."""
    kind = rng.randrange(10)
    if kind == 0:
        can_id = 0x000  # NMT
    elif kind == 1:
        can_id = 0x080  # SYNC
    elif kind == 2:
        can_id = 0x080 + NODE  # its EMCY
    elif kind == 3:
        can_id = rng.choice((0x180, 0x280, 0x380, 0x480)) + NODE  # its TPDOs
    elif kind == 4:
        can_id = rng.choice((0x200, 0x300, 0x400, 0x500)) + NODE  # its RPDOs
    elif kind == 5:
        can_id = rng.choice((0x580, 0x600)) + NODE  # SDO both ways
    elif kind == 6:
        can_id = 0x700 + rng.choice((NODE, 127, rng.randrange(1, 128)))  # heartbeats
    else:
        can_id = rng.randrange(0x800)
    length = rng.randrange(9)
    return can.Message(arbitration_id=can_id, data=bytes(rng.randrange(256) for _ in range(length)), is_extended_id=False)


def test_ten_thousand_random_frames_silence_neither_side(channel) -> None:
    from drives.canopen.drive import CanopenDrive
    from drives.cia402 import State
    from drives.safety import SafetySettings
    from haptic_bus.app.profiles import load_profile
    from haptic_bus.control.controller import WallController
    from sim_drive.canopen.slave import CanopenSimDrive
    from sim_drive.eds import eds_path
    from sim_drive.parameters import DeviceParameters

    profile = load_profile("cia402-handle")
    sim_bus = FailingBus(channel, lambda call: call % 997 == 0, "could not unpack received message")  # a bad datagram
    sim = CanopenSimDrive(sim_bus, NODE, parameters=DeviceParameters(**profile.sim_device_parameters())).start()
    drive = CanopenDrive(NODE, interface="virtual", channel=channel, eds=eds_path(), period=profile.loop.period,
                         scaling=profile.scaling(), safety=SafetySettings().for_virtual_time(profile.loop.period),
                         sdo_timeout=SDO_WAIT)
    fuzzer = can.Bus(interface="virtual", channel=channel)
    outcome: dict[str, object] = {}
    try:
        drive.connect()
        drive.enable()
        controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit)
        stop = threading.Event()

        def control() -> None:
            outcome["summary"] = controller.run(10_000_000, stop)

        thread = threading.Thread(target=control, daemon=True)
        thread.start()
        for _ in range(3000):  # the frames come while the loop runs: from its first cycle on (at most 30 s)
            if controller.cycles or not thread.is_alive():
                break
            time.sleep(0.01)
        rng = random.Random(SEED)
        deadline = time.monotonic() + 60.0
        for sent in range(FRAMES):
            fuzzer.send(random_frame(rng))
            if sent % 200 == 0:
                time.sleep(0.001)  # let both sides read: a flood the kernel would drop tests nothing
            assert time.monotonic() < deadline, "the fuzz run took too long"
        stop.set()
        thread.join(timeout=30.0)
        assert not thread.is_alive(), "the controller did not stop"
        summary = outcome["summary"]
        assert summary.exit_reason in ("stopped", "drive error"), summary
        if summary.exit_reason == "drive error":
            assert summary.error and drive.tripped is not None and isinstance(drive.tripped, DriveError)
        assert controller.record.total == summary.cycles > 0  # the record is kept either way
        assert sim.serving and sim_bus.raised > 0  # receive errors were injected and survived
        # the drive still answers SDO and still beats
        fuzzer.shutdown()
        with can.Bus(interface="virtual", channel=channel) as probe:
            read_device_type = struct.pack("<BHB4x", 0x40, 0x1000, 0)  # SDO upload request for 0x1000:00
            probe.send(can.Message(arbitration_id=0x600 + NODE, data=read_device_type, is_extended_id=False))
            answers, beats, end = [], 0, time.monotonic() + 1.0
            while time.monotonic() < end and not (answers and beats):
                message = probe.recv(0.05)
                if message is None:
                    continue
                if message.arbitration_id == 0x580 + NODE:
                    answers.append(bytes(message.data))
                beats += message.arbitration_id == 0x700 + NODE
        assert answers and answers[0][0] == 0x43 and struct.unpack_from("<I", answers[0], 4)[0] == 0x00020192
        assert beats >= 1
        assert sim.drive.state in tuple(State)  # a defined CiA-402 state, whatever the frames did
    finally:
        drive.close()
        sim.stop()
        sim_bus.shutdown()
        if fuzzer is not None:
            fuzzer.shutdown()


def _bad_datagram(rng: random.Random) -> bytes:
    """A udp_multicast datagram python-can cannot turn into a frame (DLC and data disagree)."""
    return msgpack.packb({"arbitration_id": rng.randrange(0x800), "is_extended_id": False, "dlc": 8,
                          "data": bytes(rng.randrange(4)), "timestamp": 0.0}, use_bin_type=True)


@pytest.mark.slow
def test_haptic_bus_run_under_fuzz_exits_0_or_1_with_its_record(multicast, sim_process, tmp_path, capfd) -> None:
    """The simulated drive its own process; the run the command's ``main`` in this process' main thread (its
    output read at the file descriptors), the fuzzer a thread of this test that ends the run with SIGTERM, as a
    user's ``kill`` does: a second interpreter for the run would only import and start its workers again."""
    group, port = multicast
    bus_args = ["--interface", "udp_multicast", "--channel", group, "--bus-option", f"port={port}"]
    sim = sim_process(*bus_args, "--node-id", str(NODE), "--profile", "cia402-handle")
    out = tmp_path / "run"
    ended = threading.Event()
    tpdos: list[int] = []

    def fuzz() -> None:
        """Once the run cycles, 2 000 random frames and some undecodable datagrams; then SIGTERM to this process."""
        rng = random.Random(SEED + 1)
        fuzzer = open_bus(interface="udp_multicast", channel=group, port=port)
        raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        raw.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)  # this host only
        try:
            deadline, seen = time.monotonic() + 40.0, 0
            while seen < 500 and time.monotonic() < deadline and not ended.is_set():
                message = fuzzer.recv(0.2)  # wait until it cycles: its TPDOs flow (the enable walk sends a few)
                seen += message is not None and message.arbitration_id == 0x180 + NODE
            tpdos.append(seen)
            for sent in range(2_000 if seen >= 500 else 0):
                fuzzer.send(random_frame(rng))
                if sent % 100 == 50:
                    raw.sendto(_bad_datagram(rng), (group, port))
                if sent % 100 == 0:
                    time.sleep(0.001)
                if ended.is_set():
                    break
        finally:
            raw.close()
            fuzzer.shutdown()
            if not ended.is_set():
                os.kill(os.getpid(), signal.SIGTERM)  # the run's handler stops it (or, once it returned, the test's)

    previous = signal.signal(signal.SIGTERM, lambda signum, frame: None)  # a SIGTERM after the run returned: nothing
    fuzzing = threading.Thread(target=fuzz, name="test-fuzzer", daemon=True)
    try:
        fuzzing.start()
        code = main(["run", "cia402-handle", *bus_args, "--node-id", str(NODE), "--virtual-time", "--duration", "600",
                     "-q", "--no-plots", "--out", str(out)])
    finally:
        ended.set()
        fuzzing.join(timeout=60.0)
        signal.signal(signal.SIGTERM, previous)
    stdout, stderr = capfd.readouterr()
    assert tpdos == [500], (tpdos, stderr, sim.log()[-2000:])
    assert code in (0, 1), stderr
    assert "Traceback" not in stderr
    assert stdout == "" and (out / "record.csv").is_file()  # -q: errors only; how it ended is in run.json
    assert exit_status(json.loads((out / "run.json").read_text())["exit_reason"]) == code
    if code == 1:
        assert len(stderr.strip().splitlines()) == 1 and "drive error" in stderr
    assert sim.process.poll() is None, sim.log()[-2000:]  # the drive lives on, and serves:
    with open_bus(interface="udp_multicast", channel=group, port=port) as probe:
        probe.send(can.Message(arbitration_id=0x600 + NODE, data=struct.pack("<BHB4x", 0x40, 0x1000, 0), is_extended_id=False))
        end, answered = time.monotonic() + 2.0, False
        while time.monotonic() < end and not answered:
            message = probe.recv(0.1)
            answered = message is not None and message.arbitration_id == 0x580 + NODE
    assert answered
