"""Benchmark 3: the controller's compute per cycle against the number of scene objects.

No bus: :class:`CannedDrive` is an in-memory :class:`drives.base.Drive` whose ``read_inputs``
returns precomputed samples and whose ``write_outputs`` does what the CANopen master's does
short of the bus (saturate at the torque limit, ``struct.pack_into`` the RPDO).  The
controller (:class:`haptic_bus.control.controller.WallController`, the product's) times its own
cycle from after ``read_inputs`` to after ``write_outputs`` (position, scene force,
saturation, per-mille conversion, encode) with ``time.perf_counter``; the median of those is
the compute per cycle, taken over 5 runs (median, min-max).

Scenes for N objects: one wall ahead of the handle plus ``N - 1`` non-overlapping detents
spread over 20 mm behind it (all ``K = 1500 N/m``, ``B = 10 N s/m``: the contact walls the gate
judges are the same, so the gate runs once).  The canned velocities sweep the handle across
the whole scene.  Compared: the compiled scene (:class:`haptic_bus.control.scene.CompiledScene`, one
``bisect`` and one affine law) against :class:`NaiveScene`, the same objects evaluated one by
one each cycle ("without culling"); both give the same force (checked before timing).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any, cast

import numpy as np

from drives.base import CyclicInputs, Drive, DriveScaling, TorqueClamp
from drives.canopen.drive import DEFAULT_RPDO
from drives.canopen.pdo_codec import PdoCodec
from drives.cia402 import ObjectSpec, OperationMode
from drives.cia402_master import CyclicStats
from haptic_bus.analysis.loop import DeviceLoop
from haptic_bus.bench.size import Size
from haptic_bus.bench.timing import REPEATS, Spread, time_per_call
from haptic_bus.control.clock import VirtualClock
from haptic_bus.control.controller import WallController
from haptic_bus.control.gate import GatePolicy, PassivityGate
from haptic_bus.control.scene import CompiledScene, Detent, Wall, compile_scene

SIZES = (1, 10, 100, 1_000, 10_000)
SMOKE_SIZES = (1, 100, 1_000)  # one wall and the 1 000 objects of the target: the per-object loop costs seconds at 10 000
STIFFNESS, DAMPING = 1500.0, 10.0
SPAN = 0.02  # m the detents occupy
SCALING = DriveScaling(velocity_per_count=1.1984224905356573e-07, position_per_count=1.1984224905356573e-07,
                       rated_torque=0.32, force_per_torque=50.0, max_torque_permille=2000)
DEVICE = DeviceLoop(m=1.0, b=20.0, T=1e-3, delay=1)  # the cia402-handle profile's loop
FORCE_LIMIT = 30.0


class CannedDrive(Drive):
    """A drive in memory: canned velocity samples in, RPDO bytes out (no bus, no thread)."""

    name = "canned in-memory drive"

    def __init__(self, velocities: list[int], scaling: DriveScaling = SCALING) -> None:
        self.scaling = scaling
        counts_per_step = DEVICE.T * scaling.velocity_per_count / scaling.position_per_count  # 0x6064 per 0x606C*T
        positions = np.round(np.cumsum(velocities) * counts_per_step).astype(int).tolist()
        self._inputs = [CyclicInputs(0x0237, v, p) for v, p in zip(velocities, positions)]  # the port observer reads 0x6064
        self._next = 0
        codec = PdoCodec(DEFAULT_RPDO, name="RPDO1")
        self._pack_into = codec.struct.pack_into
        self._frame = bytearray(codec.size)
        self.clamp = TorqueClamp(scaling.max_torque_permille, CyclicStats())

    def connect(self) -> None:
        """Nothing to reach."""

    def enable(self, mode: OperationMode = OperationMode.CYCLIC_SYNCHRONOUS_TORQUE) -> None:
        """Always enabled."""

    def select_mode(self, mode: OperationMode = OperationMode.CYCLIC_SYNCHRONOUS_TORQUE) -> None:
        """Always in cyclic synchronous torque."""

    def read_object(self, spec: ObjectSpec | int) -> int:
        """Every object reads 0."""
        return 0

    def read_inputs(self) -> CyclicInputs:
        """The next canned sample (cycling)."""
        inputs = self._inputs[self._next]
        self._next = (self._next + 1) % len(self._inputs)
        return inputs

    def _send_torque(self, target_torque: int) -> None:
        """Encode RPDO1 (controlword, saturated torque) as the CANopen master does, minus the send."""
        self._pack_into(self._frame, 0, 0x000F, target_torque)

    def disable(self) -> None:
        """Nothing to stop."""

    def fault_reset(self) -> None:
        """No faults."""

    def close(self) -> None:
        """Nothing to release."""


class NaiveScene:
    """The compiled scene's objects, evaluated one by one every cycle (no culling, no sweep).

    ``contacts`` is the compiled scene's, so the gate judges the same walls.
    """

    def __init__(self, compiled: CompiledScene) -> None:
        self.compiled = compiled
        self.contacts = compiled.contacts
        self.stored_energy = compiled.stored_energy
        self.objects = compiled.objects
        self.pieces = [piece for obj in compiled.objects for piece in obj.pieces()]

    def force(self, x: float, v: float) -> float:
        """Sum over every object whose support holds ``x`` of ``K (x - anchor) + B v`` (N)."""
        total = 0.0
        for start, end, k, anchor, b in self.pieces:
            if start <= x < end:
                total += k * (x - anchor) + b * v
        return total


def scene_objects(n: int) -> list:
    """One wall 1 mm ahead and ``n - 1`` detents over 20 mm behind the start (SI units)."""
    objects: list = [Wall("end-stop", 0.001, -1, STIFFNESS, DAMPING)]
    spacing = SPAN / max(n - 1, 1)
    for i in range(n - 1):
        objects.append(Detent(f"detent-{i}", -SPAN + (i + 0.5) * spacing, 0.4 * spacing, STIFFNESS, DAMPING))
    return objects


def canned_velocities(cycles: int, seed: int = 6) -> list[int]:
    """Velocity counts whose running sum sweeps the handle over the scene (-21 mm .. +3 mm)."""
    rng = np.random.default_rng(seed)
    t = np.arange(cycles + 1) * DEVICE.T
    period = 0.5  # s per sweep
    x = -0.009 + 0.012 * np.sin(2 * math.pi * t / period + rng.uniform(0, 2 * math.pi))
    counts = np.round(np.diff(x) / DEVICE.T / SCALING.velocity_per_count).astype(int)
    return [int(c) for c in counts]


def controller_compute(scene: CompiledScene, velocities: list[int], cycles: int) -> np.ndarray:
    """Per-cycle compute (s) of :class:`WallController` rendering ``scene`` on a canned drive."""
    gate = PassivityGate(DEVICE, GatePolicy())
    controller = WallController(CannedDrive(velocities), gate, scene, force_limit=FORCE_LIMIT,
                                clock=VirtualClock(DEVICE.T), record_capacity=cycles)
    controller.run(min(200, cycles))  # warm-up, then the timed cycles replace it in the ring buffer
    controller.run(cycles)
    return controller.record.column("compute_s")


def _check_same_force(compiled: CompiledScene, naive: NaiveScene) -> None:
    xs = np.linspace(-0.022, 0.004, 2001)
    for x in xs:
        a, b = compiled.force(float(x), 0.01), naive.force(float(x), 0.01)
        if not math.isclose(a, b, rel_tol=1e-12, abs_tol=1e-12):
            raise AssertionError(f"compiled and naive scenes disagree at x = {x}: {a} vs {b}")


def run(size: Size, tick: Callable[[str], None] = lambda _: None) -> dict:
    """Benchmark 3; returns its section of ``bench.json``."""
    cycles = size.pick(500, 2_000, 40_000)
    velocities = canned_velocities(cycles)
    xs = [float(x) for x in np.linspace(-0.021, 0.003, 257)]
    rows: list[dict[str, Any]] = []

    def sweep(scene: CompiledScene | NaiveScene) -> None:
        force = scene.force
        for x in xs:
            force(x, 0.01)

    controller_compute(compile_scene(scene_objects(1)), velocities, min(cycles, 2_000))  # warm-up, discarded
    for n in size.pick(SMOKE_SIZES, SIZES, SIZES):
        compiled = compile_scene(scene_objects(n))
        naive = NaiveScene(compiled)
        _check_same_force(compiled, naive)
        naive_cycles = max(200, min(cycles, cycles * 100 // n))
        c_runs = [controller_compute(compiled, velocities, cycles) for _ in range(REPEATS)]
        stand_in = cast(CompiledScene, naive)  # the controller uses force(), contacts and stored_energy(): NaiveScene has them
        n_runs = [controller_compute(stand_in, velocities, naive_cycles) for _ in range(REPEATS)]
        c_p50 = Spread.of([float(np.median(r)) for r in c_runs])
        n_p50 = Spread.of([float(np.median(r)) for r in n_runs])

        c_force = time_per_call(functools.partial(sweep, compiled)).scaled(1.0 / len(xs))
        n_force = time_per_call(functools.partial(sweep, naive), min_ns=1_000_000).scaled(1.0 / len(xs))
        rows.append({
            "objects": n, "intervals": len(compiled.breaks) + 1,
            "compiled_cycle_p50_s": c_p50.median, "compiled_cycle_p50": c_p50.to_dict(),
            "compiled_cycle_p99_s": float(np.percentile(np.concatenate(c_runs), 99)),
            "naive_cycle_p50_s": n_p50.median, "naive_cycle_p50": n_p50.to_dict(),
            "naive_cycle_p99_s": float(np.percentile(np.concatenate(n_runs), 99)),
            "compiled_force_s": c_force.median, "compiled_force": c_force.to_dict(),
            "naive_force_s": n_force.median, "naive_force": n_force.to_dict(),
            "naive_over_compiled_cycle": n_p50.median / c_p50.median,
        })
        tick(f"scene: {n} objects")
    one = rows[0]["compiled_cycle_p50_s"]
    for row in rows:
        row["compiled_cycle_ratio_to_one_object"] = row["compiled_cycle_p50_s"] / one
    thousand = next(r for r in rows if r["objects"] == 1000)
    return {
        "description": "controller compute per cycle (WallController.step between read_inputs and write_outputs, "
                       "canned in-memory drive) vs number of scene objects: compiled scene vs per-object loop",
        "cycles": cycles,
        "rows": rows,
        "target": {
            "one_wall_p50_s": one, "one_wall_target_s": 5e-6, "one_wall_met": one <= 5e-6,
            "thousand_over_one": thousand["compiled_cycle_p50_s"] / one, "thousand_over_one_target": 1.5,
            "thousand_met": thousand["compiled_cycle_p50_s"] / one <= 1.5,
        },
        "note": "compute_s is measured by the controller itself with time.perf_counter (one call's overhead, "
                "~50-100 ns, included)",
    }
