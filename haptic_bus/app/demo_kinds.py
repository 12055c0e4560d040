"""What the demo (:mod:`~haptic_bus.app.demo`) does differently for one axis and for several.

One axis: the simulated CiA-402 drive with the profile's operator (:func:`~haptic_bus.app.rig.simulated_canopen`,
enabled as it connects); the demo reads the steady penetration against ``F/K`` and the port's
energy against the drive's exact ledger.  Several axes: the simulated device with the profile's
hand in space (:func:`~haptic_bus.app.rig.simulated_axes`, enabled right before the first cycle);
the demo reads the steady state at the end of each target's dwell
(:mod:`~haptic_bus.app.steady_state`).  Units SI: m, N, N/m, J, s.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from haptic_bus.app.profiles import AxesProfile, Profile
from haptic_bus.app.rig import simulated_axes, simulated_canopen
from haptic_bus.app.steady_state import SteadyState, dwell_ends, steady_state, tour_seconds
from haptic_bus.control.controller import WallController
from haptic_bus.control.cycle_loop import RunSummary

ONE_AXIS_SECONDS = 2.0  # s of virtual time a one-axis demo runs by default


@dataclass
class Findings:
    """What the demo read against the simulated truth: the exact energies (J), and either the
    steady penetration (m) beside ``F/K`` (one axis) or the steady states (several axes)."""

    operator_energy: float
    port_energy: float
    penetration: float | None = None
    expected_penetration: float | None = None
    steady: list[SteadyState] | None = None  # None: one axis (no steady states read)


@dataclass
class OneAxisDemo:
    """The one-axis demo of ``profile``."""

    profile: Profile

    def seconds(self) -> float:
        """The default length (s of virtual time)."""
        return ONE_AXIS_SECONDS

    def link(self) -> dict[str, Any]:
        """What ``run.json``'s ``link`` adds for this kind: nothing."""
        return {}

    def simulated(self) -> AbstractContextManager[tuple[Any, Any]]:
        """The simulated drive and its master, enabled."""
        return simulated_canopen(self.profile)

    def enable(self, drive: Any) -> None:
        """Nothing: the master is enabled as it connects."""

    def on_cycle(self, sim: Any, cycles: int, seconds: float) -> Callable[[WallController[Any, Any]], None] | None:
        """Nothing read while it cycles."""
        return None

    def findings(self, sim: Any, controller: WallController[Any, Any], origin: float, cycles: int) -> Findings:
        """The exact energies (the port's as the simulated drive's ledger has it: the walls' energy at the
        start plus b int v^2 dt minus the motor's work) and, under a constant push, the steady penetration."""
        port = controller.scene.stored_energy(origin) + sim.drive.viscous_energy + sim.drive.wall_energy
        found = Findings(sim.drive.operator_energy, port)
        record = controller.record
        model = self.profile.operator_model
        push = model.get("level") if model.get("model") == "constant" else None
        surfaces = [obj.position for obj in self.profile.scene if hasattr(obj, "position")]
        contact = _contact_stiffness(controller) if record.total else None
        if isinstance(push, (int, float)) and contact is not None and surfaces:
            final_x = float(np.mean(record.column("position_m")[-max(1, cycles // 20):]))
            surface = min(surfaces, key=lambda s: abs(s - final_x))
            found.penetration, found.expected_penetration = abs(final_x - surface), abs(push) / contact
        return found

    def lines(self, controller: WallController[Any, Any], summary: RunSummary, found: Findings) -> Iterator[str]:
        """The summary's lines for this kind."""
        s, profile = summary, self.profile
        walls = ", ".join(f"{'+'.join(w.objects)} margin {w.verdict.margin:.3g} N s/m" for w in controller.decision.walls)
        yield (f"profile: {profile.name} ({profile.loop.timing} timing, delay {profile.loop.delay} sample(s), "
               f"T = {profile.loop.period * 1e3:g} ms)")
        yield f"gate: passed ({walls})" + (f"; warnings: {'; '.join(s.warnings)}" if s.warnings else "")
        yield f"cycles: {s.cycles} in virtual time; force saturated in {s.saturated_cycles}"
        yield f"peak force: {s.peak_force:.4g} N"
        if found.penetration is not None and found.expected_penetration is not None:
            error = (found.penetration - found.expected_penetration) / found.expected_penetration
            yield (f"steady penetration: {found.penetration * 1e3:.4f} mm vs F/K = "
                   f"{found.expected_penetration * 1e3:.4f} mm ({error:+.2%})")
        yield (f"energy: operator put in {found.operator_energy * 1e3:.4g} mJ (exact, simulated drive); port: "
               f"observer {s.energy * 1e3:.4g} mJ from positions (least {s.least_energy * 1e3:.4g} mJ, counts "
               f"rounding within {s.rounding_bound * 1e3:.2g} mJ) vs {found.port_energy * 1e3:.4g} mJ exact "
               f"({(s.energy - found.port_energy) / found.port_energy:+.2%})")
        yield f"passivity layer: {s.layer}, lowered {s.layer_interventions} of {s.cycles} targets"
        p = s.compute_percentiles
        if p:
            yield (f"cycle compute, TPDO in to RPDO sent (position, scene, conversion, encode, send): "
                   f"p50 {p['p50'] * 1e6:.1f} us, p99 {p['p99'] * 1e6:.1f} us, max {p['max'] * 1e6:.1f} us")


def _contact_stiffness(controller: WallController[Any, Any]) -> float | None:
    """The summed K acting where the handle ended (N/m), or None if nothing acts there."""
    x = float(controller.record.column("position_m")[-1])
    scene = controller.scene
    k = scene.stiffness[bisect.bisect_right(scene.breaks, x)]
    return k if k > 0 else None


@dataclass
class AxesDemo:
    """The multi-axis demo of ``profile``."""

    profile: AxesProfile
    steady: list[SteadyState] = field(default_factory=list)

    def seconds(self) -> float:
        """The default length: the hand's whole tour (s, :func:`~haptic_bus.app.steady_state.tour_seconds`)."""
        return tour_seconds(self.profile)

    def link(self) -> dict[str, Any]:
        """What ``run.json``'s ``link`` adds: the axes' node ids."""
        return {"node_ids": [a.node_id for a in self.profile.axes]}

    def simulated(self) -> AbstractContextManager[tuple[Any, Any]]:
        """The simulated device and the multi-axis master, not enabled."""
        return simulated_axes(self.profile)

    def enable(self, drive: Any) -> None:
        """Every axis enabled in the same cycle, right before the first."""
        drive.enable()

    def on_cycle(self, sim: Any, cycles: int, seconds: float) -> Callable[[WallController[Any, Any]], None] | None:
        """Read the steady state at the end of each target's dwell and at the end."""
        ends = dwell_ends(self.profile, seconds, cycles)

        def read_steady(running: WallController[Any, Any]) -> None:
            if running.cycles - 1 in ends and (state := steady_state(running, sim)) is not None:
                self.steady.append(state)

        return read_steady

    def findings(self, sim: Any, controller: WallController[Any, Any], origin: Any, cycles: int) -> Findings:
        """The hand's exact energy balance, the drives' exact port energy and the steady states."""
        port = math.fsum(node.drive.viscous_energy + node.drive.wall_energy for node in sim.nodes)
        return Findings(sim.hand.energy_balance(), port, steady=list(self.steady))

    def lines(self, controller: WallController[Any, Any], summary: RunSummary, found: Findings) -> Iterator[str]:
        """The summary's lines for this kind."""
        s, profile = summary, self.profile
        decision = controller.decision
        yield (f"profile: {profile.name} ({len(profile.axes)} axes, nodes {', '.join(str(a.node_id) for a in profile.axes)}, "
               f"one SYNC every {profile.period * 1e3:g} ms)")
        yield (f"gate (coupled): passed, least margin {decision.worst_margin:.3g} N s/m over "
               + ", ".join("+".join(w.objects) for w in decision.walls))
        yield f"cycles: {s.cycles} in virtual time; force saturated in {s.saturated_cycles}; peak |F| {s.peak_force:.4g} N"
        for state in found.steady or []:
            yield (f"steady at t = {state.time_s:.3f} s on {state.obj}: K d = {state.stiffness * state.penetration:.9g} N "
                   f"(d = {state.penetration * 1e3:.6f} mm measured), asked along the normal {state.normal_force:.9g} N "
                   f"(relative difference {state.relative_error:.1e}); the drives apply {state.applied:.9g} N "
                   f"({'/'.join(map(str, state.torques))} per mille), the hand pushes {state.push:.9g} N; "
                   f"K x true depth {state.stiffness * state.true_penetration:.6g} N (per-mille rounding "
                   f"<= {state.quantum * 1e3:.3g} mN)")
        exact = found.port_energy
        yield (f"energy: the hand put in {found.operator_energy * 1e3:.4g} mJ (exact); port E = sum E_i "
               f"{s.energy * 1e3:.4g} mJ from positions (least {s.least_energy * 1e3:.4g} mJ) vs {exact * 1e3:.4g} mJ "
               f"exact")
        yield f"passivity layer: {s.layer} per axis, lowered {s.layer_interventions} targets"


DemoKind = OneAxisDemo | AxesDemo


def demo_kind(profile: Profile | AxesProfile) -> DemoKind:
    """The demo of ``profile``: one axis, or several (``[[axes]]``)."""
    return AxesDemo(profile) if isinstance(profile, AxesProfile) else OneAxisDemo(profile)
