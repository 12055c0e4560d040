"""Scenes in space (issue 22): planes, boxes and spheres, their grid, the kinematics beside them,
and the gate that judges them on coupled axes.

Forces are sums of a few products: compared exactly where the arithmetic is the same (grid
against one-by-one: the same objects summed in the same order) and to 1e-15 relative against
the closed forms written out here.
"""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

from haptic_bus.analysis.coupled import coupled_verdict
from haptic_bus.analysis.coupled_loop import plane_wall
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.bench.space_scene_cost import PerObject, space_objects
from haptic_bus.control.gate import GatePolicy
from haptic_bus.control.kinematics import Cartesian, handle_velocity, joint_efforts
from haptic_bus.control.space_gate import SpaceGate, sphere_directions
from haptic_bus.control.space_scene import Box, Plane, Sphere, compile_space_scene
from haptic_bus.errors import ParameterError, Refusal

T = 1e-3
GANTRY = (WallLoop(2.0, 30.0, T, 0, 0, 1, "average"), WallLoop(1.0, 20.0, T, 0, 0, 1, "average"),
          WallLoop(0.5, 10.0, T, 0, 0, 1, "average"))
FLOOR = Plane("floor", (0.0, 0.0, 0.0), (0.0, 0.0, 2.0), 1000.0, 5.0)
BOX = Box("box", (0.02, 0.0, 0.01), (0.01, 0.01, 0.01), 1500.0, 10.0)
BALL = Sphere("ball", (-0.02, 0.0, 0.01), 0.01, 1200.0, 8.0)


def test_each_object_pushes_along_its_penetration_normal() -> None:
    scene = compile_space_scene([FLOOR, BOX, BALL])
    v = np.array([0.01, -0.02, -0.03])
    # the floor, 1 mm deep, moving down at 0.03 m/s: u = -(K d + B 0.03) n
    assert scene.force([0.5, 0.5, -0.001], v) == pytest.approx([0.0, 0.0, -(1.0 + 5.0 * 0.03)], rel=1e-15)
    # the box, nearest face +y at 2 mm: n = (0, 1, 0), n . v = -0.02
    assert scene.force([0.021, 0.008, 0.012], v) == pytest.approx([0.0, -(1500.0 * 0.002 + 10.0 * 0.02), 0.0], rel=1e-15)
    # the ball, 3 mm deep along (3, 4, 0)/5 from its center
    x = np.array([-0.02, 0.0, 0.01]) + 0.007 * np.array([0.6, 0.8, 0.0])
    n = np.array([0.6, 0.8, 0.0])
    assert scene.force(x, v) == pytest.approx(-(1200.0 * 0.003 - 8.0 * float(n @ v)) * n, rel=1e-12)
    assert scene.contacts(x) == ("ball",)
    assert scene.force([0.0, 0.0, 0.05], v) == pytest.approx([0.0, 0.0, 0.0], abs=0.0)
    # at rest the force along the normal is K times the penetration
    at_rest = scene.force([0.5, 0.5, -0.0025], [0.0, 0.0, 0.0])
    assert -at_rest[2] == pytest.approx(1000.0 * 0.0025, rel=1e-15)
    assert scene.stored_energy([0.5, 0.5, -0.0025]) == pytest.approx(0.5 * 1000.0 * 0.0025**2, rel=1e-15)


def test_overlapping_objects_add() -> None:
    sunk = Box("sunk", (0.0, 0.0, 0.0), (0.01, 0.01, 0.005), 800.0, 0.0)
    scene = compile_space_scene([FLOOR, sunk])
    x = [0.0, 0.009, -0.001]  # 1 mm into the floor, 1 mm inside the box's +y face
    assert scene.contacts(x) == ("floor", "sunk")
    assert scene.force(x, [0.0, 0.0, 0.0]) == pytest.approx([0.0, -0.8, -1.0], rel=1e-12)


def test_the_grid_gives_what_testing_every_object_gives() -> None:
    scene = compile_space_scene(space_objects(300))
    assert scene.grid is not None and len(scene.grid.members) > 300
    everyone = PerObject(scene)
    rng = np.random.default_rng(22)
    v = np.array([0.01, -0.02, 0.005])
    touched = 0
    for x in rng.uniform(-0.004, 0.024, (1500, 3)):
        together = scene.force(x, v)
        assert np.array_equal(together, everyone.force(x, v))
        touched += bool(np.any(together))
    assert touched > 300  # the points meet objects, not only empty space
    # a cell lists only a few of the 300 objects: the cost of a cycle does not grow with them
    assert max(len(m) for m in scene.grid.members) < 20


def test_objects_are_checked_with_one_line_errors() -> None:
    with pytest.raises(ParameterError, match="radius"):
        Sphere("s", (0.0, 0.0, 0.0), -1.0, 100.0, 1.0)
    with pytest.raises(ParameterError, match="normal"):
        Plane("p", (0.0, 0.0), (0.0, 0.0), 100.0, 1.0)
    with pytest.raises(ParameterError, match="half"):
        Box("b", (0.0, 0.0, 0.0), (0.1, 0.1), 100.0, 1.0)
    with pytest.raises(ParameterError, match="stiffness"):
        Box("b", (0.0, 0.0), (0.1, 0.1), -100.0, 1.0)
    with pytest.raises(ParameterError, match="one number of coordinates"):
        compile_space_scene([FLOOR, Sphere("flat", (0.0, 0.0), 0.1, 100.0, 1.0)])
    with pytest.raises(ParameterError, match="name"):
        compile_space_scene([BOX, Box("box", (1.0, 0.0, 0.0), (0.1, 0.1, 0.1), 100.0, 1.0)])


class TwoLinkArm:
    """A planar arm (links 0.3 m and 0.2 m, joint angles in rad): the interface fits a non-Cartesian device."""

    size = 2

    def position(self, q: np.ndarray) -> np.ndarray:
        a, b = q
        return np.array([0.3 * math.cos(a) + 0.2 * math.cos(a + b), 0.3 * math.sin(a) + 0.2 * math.sin(a + b)])

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        a, b = q
        return np.array([[-0.3 * math.sin(a) - 0.2 * math.sin(a + b), -0.2 * math.sin(a + b)],
                         [0.3 * math.cos(a) + 0.2 * math.cos(a + b), 0.2 * math.cos(a + b)]])


def test_kinematics_cartesian_and_the_interface() -> None:
    gantry = Cartesian(3)
    q = np.array([0.1, -0.2, 0.03])
    assert np.array_equal(gantry.position(q), q) and np.array_equal(gantry.jacobian(q), np.eye(3))
    assert np.array_equal(joint_efforts(gantry, q, [1.0, -2.0, 3.0]), [1.0, -2.0, 3.0])
    with pytest.raises(ParameterError, match="3 joint coordinates"):
        gantry.jacobian([0.0, 0.0])
    with pytest.raises(ParameterError, match="axes"):
        Cartesian(7)
    # virtual work: F . dx = tau . dq for a small joint step, on a device that is not Cartesian
    arm, q = TwoLinkArm(), np.array([0.4, 0.9])
    force, dq = np.array([3.0, -1.5]), np.array([1e-7, -2e-7])
    dx = arm.position(q + dq) - arm.position(q)
    assert float(force @ dx) == pytest.approx(float(joint_efforts(arm, q, force) @ dq), rel=1e-6)
    assert handle_velocity(arm, q, dq / 1e-3) == pytest.approx(dx / 1e-3, rel=1e-5)


def test_the_gate_judges_every_contact_normal_on_the_coupled_axes() -> None:
    gate = SpaceGate(GANTRY, GatePolicy(safety_margin=0.5))
    decision = gate.admit(compile_space_scene([FLOOR, BOX, BALL]))
    assert [w.objects for w in decision.walls] == [("floor",), ("box",), ("ball",)]  # resting on the floor: no overlap
    box = decision.walls[1]
    assert box.parts[0][2] == (0.0, 0.0, 1.0)  # the worst face: z, the lightest, least damped axis
    assert box.verdict.margin == coupled_verdict(plane_wall(GANTRY, [0, 0, 1], 1500.0, 10.0)).margin
    ball = decision.walls[2]
    sampled = min(gate.wall(((1200.0, 8.0, d),)).margin for d in sphere_directions(3))
    assert ball.verdict.margin <= sampled
    assert len(sphere_directions(3)) == 13 and len(sphere_directions(2)) == 4


def test_the_gate_refuses_with_the_object_and_judges_overlaps_together() -> None:
    gate = SpaceGate(GANTRY)
    stiff = Box("stiff", (0.0, 0.0, 0.1), (0.01, 0.01, 0.01), 40_000.0, 0.0)
    with pytest.raises(Refusal, match="stiff") as refused:
        gate.admit(compile_space_scene([FLOOR, stiff]))
    assert "margin" in str(refused.value) and "allowed: margin >= 0" in str(refused.value)
    sunk = Box("sunk", (0.0, 0.0, 0.0), (0.01, 0.01, 0.005), 800.0, 0.0)
    decision = gate.judge(compile_space_scene([FLOOR, sunk]))
    pair = [w for w in decision.walls if w.objects == ("floor", "sunk")]
    assert len(pair) == 1 and len(pair[0].parts) == 2
    flat = SpaceGate(GANTRY[:2]).judge(compile_space_scene([FLOOR]))
    assert not flat.accepted and "3 coordinates" in flat.reasons[0]


def test_a_pickled_gate_carries_the_verdicts_judged_on_its_axes() -> None:
    """A run hands its gate, pickled, to the judge worker, which judges the running scene at once: the
    verdicts this process holds on the gate's axes go along (the worker does not judge them again: a
    gantry-3d run's worker judged its 36 walls anew, 0.9 s), those on other axes do not."""
    gate = SpaceGate(GANTRY)
    slope = Plane("slope", (0.0, 0.0, 0.0), (1.0, 1.0, 2.0), 1000.0, 5.0)
    decision = gate.judge(compile_space_scene([slope]))
    wall = decision.walls[0]
    carried = gate.__getstate__()["verdicts"]
    assert any(verdict is wall.verdict for verdict in carried.values())
    assert all(axes == GANTRY for axes, _ in carried)
    later = gate.later(1.0)
    assert all(axes == later.axes for axes, _ in later.__getstate__()["verdicts"])
    copy = pickle.loads(pickle.dumps(gate))
    assert (copy.axes, copy.policy) == (gate.axes, gate.policy)
    assert copy.judge(compile_space_scene([slope])) == decision
