"""A wall in space the coupled gate refuses names, as the 1-D gate's refusal does, the passive K at
its B and the passive B at its K along the normal it was refused on (breaker11a: a gantry-3d
profile edited to an unsafe ball said only "allowed: margin >= 2 N s/m", no range of K)."""

from __future__ import annotations

import re

import haptic_bus as hb
from haptic_bus.analysis.limits import passive_limits
from haptic_bus.control.space_gate import SpaceGate
from haptic_bus.control.space_scene import Plane, compile_space_scene


def _gate() -> SpaceGate:
    gate = hb.load_profile("gantry-3d").gate()
    assert isinstance(gate, SpaceGate)
    return gate


def _largest_k(reason: str) -> float:
    found = re.search(r"along that normal, passive K at this B: \[0, ([0-9.e+]+)\] N/m; passive B at this K: ", reason)
    assert found is not None, reason
    return float(found.group(1))


def test_an_axis_aligned_wall_names_the_one_axis_limits() -> None:
    gate = _gate()
    floor = Plane("floor", (0.0, 0.0, 0.01), (0.0, 0.0, -1.0), 50000.0, 5.0)  # z only: the 1-D loop of axis z
    (reason,) = gate.judge(compile_space_scene([floor])).reasons
    stiffness, damping = passive_limits(gate.axes[2].with_wall(50000.0, 5.0))
    assert reason.startswith("floor (K = 50000 N/m, B = 5 N s/m along (0, 0, -1)) is unstable")
    assert reason.endswith(f"passive K at this B: {stiffness.describe('N/m', 6)}; "
                           f"passive B at this K: {damping.describe('N s/m', 6)}")
    assert _largest_k(reason) == 4228.21  # the profile's comment: 4228 N/m along z at B = 5 N s/m


def test_an_oblique_wall_names_where_the_coupled_margin_crosses_zero() -> None:
    gate = _gate()
    normal = (-2.0, -2.0, -1.0)  # gantry-3d's slope, coupling all three axes
    slope = Plane("slope", (0.01, 0.01, 0.005), normal, 60000.0, 5.0)
    (reason,) = gate.judge(compile_space_scene([slope])).reasons
    largest = _largest_k(reason)
    # the stated end, rounded to 6 digits (relative 5e-6), lies between a passive and an active wall
    # of the coupled gate's own verdicts: 1e-4 either side is 20 times the rounding
    assert gate.wall(((largest * (1 - 1e-4), 5.0, normal),)).margin >= 0.0
    assert gate.wall(((largest * (1 + 1e-4), 5.0, normal),)).margin < 0.0


def test_two_objects_refused_together_name_no_single_normal() -> None:
    gate = _gate()
    a = Plane("a", (0.0, 0.0, 0.01), (0.0, 0.0, -1.0), 3000.0, 5.0)
    b = Plane("b", (0.0, 0.0, 0.01), (0.0, -1.0, -1.0), 3000.0, 5.0)
    reasons = gate.judge(compile_space_scene([a, b])).reasons
    pair = [r for r in reasons if r.startswith("a+b ")]
    assert pair and all("along that normal" not in r for r in pair)
