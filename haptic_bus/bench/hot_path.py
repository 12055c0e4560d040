"""Benchmark helpers for the CANopen master's cyclic hot path (a library, not a timed test).

:func:`bench_pdo_codecs` measures, on the same frames, what one cycle's PDO work costs

* on the master's hot path: length check + one precompiled ``struct.unpack`` of the TPDO,
  one ``struct.pack_into`` of the RPDO into a reused buffer (what
  :class:`drives.canopen.drive.CanopenDrive` does per cycle), and
* on canopen's generic PDO path: ``PdoMap.on_message`` (what canopen's notifier does per
  received TPDO), then ``.raw`` of each mapped TPDO variable, then ``.raw = ...`` of each
  RPDO variable and ``bytes(map.data)``,

and returns the ratio generic/hot.  No bus is involved: it isolates the encode/decode cost.
:func:`bench_closed_loop` measures whole closed-loop cycles per second on a connected,
enabled drive (bus, drive and simulation included).  :func:`bench_echo_floor` is the floor a
threaded in-process bus sets: python-can's own ``virtual`` bus with a responder thread that
answers each SYNC with a TPDO, the caller sending SYNC, reading the TPDO and sending an RPDO
(no CANopen library, no drive, no controller: frames and thread hand-offs only).
``haptic-bus bench`` calls all three.

Usage::

    from haptic_bus.bench.hot_path import bench_pdo_codecs
    result = bench_pdo_codecs(frames=20000)
    print(result)   # ... ratio generic/hot = 25.3
"""

from __future__ import annotations

import random
import threading
import time
import uuid
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import can
import canopen

from drives.base import Drive
from drives.canopen.master_dictionary import minimal_cia402_od
from drives.canopen.pdo_codec import PdoCodec, object_spec
from drives.cia402 import CONTROLWORD, STATUSWORD, TARGET_TORQUE, VELOCITY_ACTUAL, ObjectSpec
from haptic_bus.bench.timing import REPEATS, Spread, timed_once


@dataclass(frozen=True)
class CodecBenchResult:
    """Seconds per cycle (decode one TPDO + encode one RPDO) on both paths (spreads over repeats)."""

    frames: int
    hot_path: Spread
    generic: Spread

    @property
    def ratio(self) -> float:
        """How many times slower canopen's generic PDO path is than the hot path (medians)."""
        return self.generic.median / self.hot_path.median

    def __str__(self) -> str:
        return (
            f"{self.frames} frames: hot path {self.hot_path.median * 1e9:.0f} ns/cycle, "
            f"canopen generic PDO {self.generic.median * 1e9:.0f} ns/cycle, ratio generic/hot = {self.ratio:.1f}"
        )


def _frames(codec: PdoCodec, count: int, seed: int) -> list[bytearray]:
    rng = random.Random(seed)
    frames = []
    for _ in range(count):
        values = [rng.randint(*spec.data_type.range) for spec in codec.entries]
        frames.append(bytearray(codec.encode(*values)))
    return frames


def _generic_maps(tpdo: Sequence[ObjectSpec], node_id: int) -> tuple[Any, Any]:
    node = canopen.RemoteNode(node_id, minimal_cia402_od())
    assert node.tpdo.map is not None and node.rpdo.map is not None  # canopen builds both maps with the node
    tmap = node.tpdo.map[1]
    tmap.clear()
    for spec in tpdo:
        tmap.add_variable(spec.index, spec.subindex)
    tmap.cob_id = 0x180 + node_id
    tmap.enabled = True
    rmap = node.rpdo.map[1]
    rmap.clear()
    rmap.add_variable(CONTROLWORD.index)
    rmap.add_variable(TARGET_TORQUE.index)
    rmap.cob_id = 0x200 + node_id
    return tmap, rmap


def bench_pdo_codecs(
    frames: int = 20000,
    tpdo_objects: Sequence[ObjectSpec | int] = (STATUSWORD, VELOCITY_ACTUAL),
    repeat: int = REPEATS,
    seed: int = 1,
) -> CodecBenchResult:
    """Per-cycle cost (s) of hot-path vs canopen generic PDO decode+encode on the same frames."""
    if frames < 1 or repeat < 1:
        raise ValueError(f"frames = {frames!r}, repeat = {repeat!r}; both must be >= 1")
    tpdo = [object_spec(o) for o in tpdo_objects]
    tcodec = PdoCodec(tpdo, name="TPDO1")
    rcodec = PdoCodec((CONTROLWORD, TARGET_TORQUE), name="RPDO1")
    data = _frames(tcodec, frames, seed)
    torques = [(i * 7919) % 6001 - 3000 for i in range(frames)]
    node_id = 5
    cob = 0x180 + node_id

    def hot() -> tuple[int, int]:
        size = tcodec.size
        unpack = tcodec.struct.unpack
        pack_into = rcodec.struct.pack_into
        out = bytearray(rcodec.size)
        checksum = 0
        for frame, torque in zip(data, torques):
            if len(frame) != size:
                continue
            values = unpack(frame)
            pack_into(out, 0, 0x000F, torque)
            checksum += values[0]
        return checksum, out[2]

    tmap, rmap = _generic_maps(tpdo, node_id)
    tvars = list(tmap.map)
    cw_var, torque_var = rmap.map

    def generic() -> tuple[int, int]:
        checksum = 0
        out = b""
        for frame, torque in zip(data, torques):
            tmap.on_message(cob, frame, 0.0)
            values = [var.raw for var in tvars]
            cw_var.raw = 0x000F
            torque_var.raw = torque
            out = bytes(rmap.data)
            checksum += values[0]
        return checksum, out[2]

    if hot() != generic():  # both paths must see the same numbers before they are timed
        raise AssertionError("hot path and canopen's generic path disagree on the benchmark frames")
    hot_s = Spread.of([timed_once(hot)[0] for _ in range(repeat)]).scaled(1.0 / frames)
    generic_s = Spread.of([timed_once(generic)[0] for _ in range(repeat)]).scaled(1.0 / frames)
    return CodecBenchResult(frames, hot_s, generic_s)


@dataclass(frozen=True)
class LoopBenchResult:
    """Closed-loop cycles (read_inputs + write_outputs) and the wall time they took."""

    cycles: int
    seconds: float

    @property
    def cycles_per_second(self) -> float:
        """Closed-loop cycles per wall-clock second."""
        return self.cycles / self.seconds

    def __str__(self) -> str:
        return f"{self.cycles} cycles in {self.seconds:.3f} s: {self.cycles_per_second:.0f} cycles/s"


def bench_closed_loop(drive: Drive, cycles: int = 2000, damping_permille_per_count: float = 0.0) -> LoopBenchResult:
    """Run ``cycles`` closed-loop cycles on a connected, enabled ``drive``; time them.

    The law is a pure damper in drive units (torque = -gain * velocity counts, rounded) so the
    handle stays at rest unless pushed; gain 0 sends zero torque.
    """
    if cycles < 1:
        raise ValueError(f"cycles = {cycles!r}; must be >= 1")
    read, write = drive.read_inputs, drive.write_outputs
    gain = damping_permille_per_count
    start = time.perf_counter()
    for _ in range(cycles):
        inputs = read()
        write(-round(gain * inputs.velocity))
    return LoopBenchResult(cycles, time.perf_counter() - start)


def bench_echo_floor(cycles: int = 2000, interface: str = "virtual") -> LoopBenchResult:
    """``cycles`` SYNC -> TPDO -> RPDO exchanges with a responder thread on a fresh ``interface`` channel."""
    channel = f"echo-{uuid.uuid4().hex[:12]}"
    master, drive = can.Bus(interface=interface, channel=channel), can.Bus(interface=interface, channel=channel)
    stop = threading.Event()
    tpdo = can.Message(arbitration_id=0x185, data=bytes(6), is_extended_id=False)

    def respond() -> None:
        while not stop.is_set():
            msg = drive.recv(0.05)
            if msg is not None and msg.arbitration_id == 0x080:
                drive.send(tpdo)

    responder = threading.Thread(target=respond, name="echo-responder", daemon=True)
    responder.start()
    sync = can.Message(arbitration_id=0x080, data=b"", is_extended_id=False)
    rpdo = can.Message(arbitration_id=0x205, data=bytes(4), is_extended_id=False)
    try:
        start = time.perf_counter()
        for _ in range(cycles):
            master.send(sync)
            while (msg := master.recv(1.0)) is not None and msg.arbitration_id != 0x185:
                pass
            if msg is None:
                raise RuntimeError("the echo responder did not answer a SYNC within 1 s")
            master.send(rpdo)
        seconds = time.perf_counter() - start
    finally:
        stop.set()
        responder.join(1.0)
        master.shutdown()
        drive.shutdown()
    return LoopBenchResult(cycles, seconds)
