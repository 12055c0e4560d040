"""The haptic wall controller: one cycle per period ``T`` over any :class:`drives.base.Drive`.

Each cycle: ``read_inputs`` (on CANopen: SYNC out, the drive's TPDO back) -> integrate the
position exactly as the seed's backward difference does, ``x_k = x_{k-1} + T v_k``, but in
the drive's integer velocity units (an exact integer sum, so ten million cycles add no
rounding) -> the compiled scene's force -> saturate at the profile's limit (counted) ->
torque target in per mille -> ``write_outputs``.  A passivity observer and a bounded record
run beside it.  Wall changes pass the gate first, in the caller's thread, and take effect
whole at the next cycle boundary; a refused change leaves the running scene untouched.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from drives.base import Drive
from drives.cia402 import POSITION_ACTUAL
from drives.errors import DriveError, ParameterError
from haptic_bus.control.clock import VirtualClock
from haptic_bus.control.gate import GateDecision, PassivityGate
from haptic_bus.control.observer import PassivityObserver
from haptic_bus.control.record import RunRecord
from haptic_bus.control.scene import CompiledScene, compile_scene

logger = logging.getLogger(__name__)


def encoder_origin(drive: Drive) -> float:
    """The handle's absolute position (m) from 0x6064, read once, acyclically, before cycling."""
    return drive.read_object(POSITION_ACTUAL) * drive.scaling.position_per_count


class PositionIntegrator:
    """``x_k = x_0 + T * velocity_per_count * sum(v_counts)``: an exact integer sum, one rounding."""

    __slots__ = ("step", "origin", "counts")

    def __init__(self, period: float, velocity_per_count: float, origin: float = 0.0) -> None:
        self.step = period * velocity_per_count  # m per (count * cycle)
        self.origin = origin
        self.counts = 0

    def add(self, velocity_counts: int) -> float:
        """Accumulate one velocity sample (0x606C units); return the position in m."""
        self.counts += velocity_counts
        return self.origin + self.step * self.counts


@dataclass
class RunSummary:
    """What a run did: counts, peaks, energy (J), compute time percentiles (s), and its end."""

    cycles: int
    saturated_cycles: int
    peak_force: float
    wall_energy: float
    interface_energy: float
    observer_active_cycles: int
    observer_flagged: bool
    compute_percentiles: dict[str, float]
    clock: str
    overruns: int
    lateness_percentiles: dict[str, float]
    error: str | None = None
    warnings: list[str] = field(default_factory=list)


class WallController:
    """Renders a gated scene on ``drive`` every ``period`` s.

    ``force_limit`` (N) saturates the wall force; ``clock`` is a :class:`VirtualClock` or
    :class:`RealClock`; ``record_capacity`` bounds the record.
    """

    def __init__(
        self,
        drive: Drive,
        gate: PassivityGate,
        scene: CompiledScene,
        *,
        force_limit: float,
        clock=None,
        record_capacity: int = 200_000,
        origin: float = 0.0,
    ) -> None:
        self.drive = drive
        self.gate = gate
        self.period = gate.device.T
        self.force_limit = force_limit
        self.clock = clock if clock is not None else VirtualClock(self.period)
        self.decision = gate.admit(scene)
        self._scene = scene
        self._latest = scene  # the last accepted upload; the loop adopts it at a cycle boundary
        self._upload_lock = threading.Lock()
        scaling = drive.scaling
        self.integrator = PositionIntegrator(self.period, scaling.velocity_per_count, origin)
        device = gate.device
        self.observer = PassivityObserver(self.period, device.delay, device.m, device.b)
        self.record = RunRecord(record_capacity)
        self.cycles = 0
        self.saturated_cycles = 0
        self.peak_force = 0.0
        self.applied_scenes = 0
        self.stopped_on_error = False

    # ------------------------------------------------------------------ gated changes

    @property
    def scene(self) -> CompiledScene:
        """The scene the loop renders now."""
        return self._scene

    @property
    def latest_scene(self) -> CompiledScene:
        """The scene of the last accepted upload (running, or staged for the next cycle)."""
        return self._latest

    def upload_scene(self, scene: CompiledScene) -> GateDecision:
        """Gate ``scene`` and stage it for the next cycle boundary; raise GateRefusal if refused."""
        with self._upload_lock:
            decision = self.gate.admit(scene)
            self._latest = scene
            return decision

    def set_wall(self, name: str, stiffness: float, damping: float) -> GateDecision:
        """Change one object's ``K`` (N/m) and ``B`` (N s/m) together, through the gate."""
        return self.set_walls({name: (stiffness, damping)})

    def set_walls(self, changes: dict[str, tuple[float, float]]) -> GateDecision:
        """Change several objects' ``(K, B)`` as one upload: all pass the gate, or none applies."""
        with self._upload_lock:
            base = self._latest
            objects = base.by_name()
            unknown = sorted(set(changes) - set(objects))
            if unknown:
                raise ParameterError("object", unknown[0], f"one of {sorted(objects)}", "scene")
            changed = [obj.with_parameters(*changes[obj.name]) if obj.name in changes else obj for obj in base.objects]
            scene = compile_scene(changed)
            decision = self.gate.admit(scene)
            self._latest = scene
            return decision

    # ------------------------------------------------------------------ the cycle

    def step(self) -> None:
        """One cycle: inputs, position, force, saturation, torque out, observer, record."""
        latest = self._latest  # one read: the whole accepted scene, never half of one
        if latest is not self._scene:  # nothing is cleared, so no upload can be lost
            self._scene = latest
            self.applied_scenes += 1
        inputs = self.drive.read_inputs()
        started = time.perf_counter()
        scaling = self.drive.scaling
        v = inputs.velocity * scaling.velocity_per_count
        x = self.integrator.add(inputs.velocity)
        force = self._scene.force(x, v)
        limit = self.force_limit
        if force > limit or force < -limit:
            force = limit if force > 0 else -limit
            self.saturated_cycles += 1
        torque = scaling.torque_permille(-force)  # the motor pushes against the wall force
        self.drive.write_outputs(torque)
        compute = time.perf_counter() - started
        energy = self.observer.update(v, force)
        if abs(force) > self.peak_force:
            self.peak_force = abs(force)
        self.record.append(self.cycles * self.period, v, x, force, torque, energy, compute)
        self.cycles += 1

    def run(self, cycles: int, stop: threading.Event | None = None,
            on_cycle: Callable[["WallController"], None] | None = None) -> RunSummary:
        """Run up to ``cycles`` cycles (or until ``stop`` is set); a drive error ends the run
        with torque zero and the drive disabled, the record kept, and the error in the summary."""
        error = None
        try:
            for _ in range(cycles):
                if stop is not None and stop.is_set():
                    break
                self.clock.wait_next(self.cycles)
                self.step()
                if on_cycle is not None:
                    on_cycle(self)
        except DriveError as exc:
            error = str(exc)
            self.stopped_on_error = True
            logger.error("run stopped: %s", exc)
            self._make_safe()
        return self.summary(error)

    def _make_safe(self) -> None:
        try:
            self.drive.disable()
        except DriveError as exc:  # the drive may be gone; its own trip already zeroed torque
            logger.error("could not disable the drive: %s", exc)

    def summary(self, error: str | None = None) -> RunSummary:
        """The summary of everything run so far."""
        compute = self.record.column("compute_s")
        late = self.clock.lateness()
        return RunSummary(
            cycles=self.cycles,
            saturated_cycles=self.saturated_cycles,
            peak_force=self.peak_force,
            wall_energy=self.observer.wall_energy,
            interface_energy=self.observer.interface_energy,
            observer_active_cycles=self.observer.active_cycles,
            observer_flagged=self.observer.flagged,
            compute_percentiles=_percentiles(compute),
            clock=self.clock.name,
            overruns=self.clock.overruns,
            lateness_percentiles=_percentiles(late),
            error=error,
            warnings=list(self.decision.warnings),
        )


def _percentiles(values: np.ndarray) -> dict[str, float]:
    if values.size == 0:
        return {}
    p50, p99, p999 = np.percentile(values, [50, 99, 99.9])
    return {"p50": float(p50), "p99": float(p99), "p99.9": float(p999), "max": float(values.max())}
