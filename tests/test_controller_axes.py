"""One controller at every axis count: the scalar path and the path for several axes render the
same physics, and the start ramp and gated uploads hold on three coupled axes (the derate:
``test_coupled_derate.py``).

Everything runs in this process in virtual time on the lock-step bus: the simulated drives are
real CANopen slaves, the masters the run's own (:mod:`haptic_bus.app.rig`).
"""

from __future__ import annotations

import dataclasses
import math
from concurrent.futures.process import BrokenProcessPool

import numpy as np
import pytest

from haptic_bus.analysis.coupled import coupled_verdict
from haptic_bus.analysis.coupled_limits import passive_along
from haptic_bus.analysis.coupled_loop import plane_wall
from haptic_bus.analysis.limits import passive_scales
from haptic_bus.app.profiles import AxesProfile, load_profile
from haptic_bus.app.rig import simulated_axes, simulated_canopen
from haptic_bus.control.controller import WallController
from haptic_bus.control.joints import encoder_origin, encoder_origins
from haptic_bus.control.kinematics import Cartesian
from haptic_bus.control.record import COLUMNS
from haptic_bus.control.space_gate import SpaceDecision, SpaceGate
from haptic_bus.control.space_scene import Plane, compile_space_scene
from haptic_bus.errors import ParameterError, Refusal
from haptic_bus.node.controller_node import ControllerNode
from haptic_bus.node.verdicts import judge_pool
from sim_drive.operator import ConstantPush

DIAGONAL = (1.0, 1.0, 0.0)  # the slab's outward normal (normalised by the plane): x and y coupled


def slab(profile: AxesProfile) -> AxesProfile:
    """gantry-3d with one oblique plane the handle starts 2.83 mm inside (at the origin) and no hand."""
    plane = Plane("slab", (0.002, 0.002, 0.0), DIAGONAL, 1500.0, 5.0)
    return dataclasses.replace(profile, space=(plane,), operator_model={"model": "none"})


@pytest.fixture(scope="module")
def gantry() -> AxesProfile:
    """gantry-3d, loaded (its scene judged by the coupled gate, about 0.5 s) once for the module: a frozen
    profile the tests only read or copy with ``dataclasses.replace``."""
    return load_profile("gantry-3d")


def test_the_scalar_and_the_axes_path_render_one_wall_alike() -> None:
    """One axis, one wall, two ways: a 1-D compiled wall through the scalar path, and the same wall as
    a plane in a one-coordinate space through the path for several axes (kinematics, arrays).  The
    forces differ only by the order of float operations (``K x - K p + B v`` against
    ``K (x - p) + B v``): a few ulps of ``K (|x| + |p|) + B |v|``, never enough to move a torque's
    per-mille rounding here, so the torques sent and hence the whole trajectories are the same to the bit."""
    profile = load_profile("cia402-handle")
    wall = profile.scene[0]
    runs = []
    for coupled in (False, True):
        with simulated_canopen(profile, operator=ConstantPush(3.0)) as (_, drive):
            if coupled:
                gate = SpaceGate((profile.gate().device.wall(0.0, 0.0),), profile.gate().policy)
                scene = compile_space_scene([Plane(wall.name, (wall.position,), (-1.0,), wall.stiffness, wall.damping)])
                controller: WallController = WallController(drive, gate, scene, force_limit=profile.force_limit,
                                                            origin=encoder_origin(drive))
            else:
                controller = WallController(drive, profile.gate(), profile.compiled_scene(),
                                            force_limit=profile.force_limit, origin=encoder_origin(drive))
            assert controller.scalar is not coupled
            summary = controller.run(1000)  # the push meets the wall at cycle 46 and has settled by about 1000
            assert summary.exit_reason == "completed"
            runs.append(controller.record.array())
    scalar, axes = runs
    for name in ("position_m", "velocity_m_per_s", "torque_permille", "energy_j"):
        i = COLUMNS.index(name)
        assert np.array_equal(scalar[:, i], axes[:, i]), name
    x, v = scalar[:, COLUMNS.index("position_m")], scalar[:, COLUMNS.index("velocity_m_per_s")]
    ulps = 8 * np.finfo(float).eps * (wall.stiffness * (np.abs(x) + abs(wall.position)) + wall.damping * np.abs(v))
    force = COLUMNS.index("force_n")
    assert np.all(np.abs(scalar[:, force] - axes[:, force]) <= ulps)
    assert scalar[:, force].max() > 1.0  # it touched the wall: 3 N pushed into it


def test_the_scale_family_along_a_normal_is_the_coupled_verdict_on_every_scale(gantry: AxesProfile) -> None:
    """``passive_along(.., "scale")``: along an axis it is the 1-D ramp proof exactly; along a diagonal
    every scale inside an interval has a coupled margin >= 0 and every scale outside one < 0 (checked
    on 20 scales, every 0.05, and 2e-3 either side of each interval end inside (0, 1), none within 1e-3
    of an end: the ends are refined roots, the margins there ~0).  The intervals here are (0, 1) and
    (0, 0.403): the grid sees each one's inside and outside, the brackets its end, closer than the 41
    scales every 0.025 this checked before did (at 23 ms of CPU a coupled verdict)."""
    loops = gantry.gate().axes
    along_x = passive_along(loops, (1.0, 0.0, 0.0), 1500.0, 5.0, "scale")
    assert along_x.intervals == passive_scales(loops[0].with_wall(1500.0, 5.0)).intervals
    for K, B in ((1500.0, 5.0), (20000.0, 0.5)):
        scales = passive_along(loops, DIAGONAL, K, B, "scale")
        ends = [end for interval in scales.intervals for end in interval if 0.0 < end < 1.0]
        grid = [*np.linspace(0.0, 1.0, 21)[1:], *(end + side * 2e-3 for end in ends for side in (-1, 1))]
        checked = 0
        for s in grid:
            if any(abs(s - end) < 1e-3 for interval in scales.intervals for end in interval):
                continue
            margin = coupled_verdict(plane_wall(loops, np.array(DIAGONAL) / math.sqrt(2), s * K, s * B)).margin
            inside = any(lo <= s <= hi for lo, hi in scales.intervals)
            assert (margin >= 0.0) == inside, (K, B, s, margin, scales.intervals)
            checked += 1
        assert checked >= 19 + 2 * len(ends)
    assert passive_along(loops, DIAGONAL, 1500.0, 5.0, "scale").intervals == ((0.0, 1.0),)
    assert passive_along(loops, DIAGONAL, 20000.0, 0.5, "scale").intervals != ((0.0, 1.0),)  # too stiff on the way


def test_three_axes_start_inside_a_plane_and_ramp_the_force_in_along_its_normal(gantry: AxesProfile) -> None:
    profile = slab(gantry)
    gate, scene = profile.gate(), profile.compiled_scene()
    proof = gate.proves_ramp(scene)
    assert proof.proven and proof.reason == ""
    ramp_time = 0.1  # s: 50 cycles at T = 2 ms
    with simulated_axes(profile) as (_, axes):
        origin = encoder_origins(axes)
        assert scene.contacts(origin) == ("slab",)
        controller = WallController(axes, gate, scene, names=[a.name for a in profile.axes],
                                    force_limit=[a.force_limit for a in profile.axes], origin=origin,
                                    ramp_time=ramp_time, passivity=profile.passivity)
        axes.enable()
        summary = controller.run(400)
    assert summary.exit_reason == "completed"
    ramp_cycles = round(ramp_time / profile.period)
    scale = controller.records[0].column("scale")
    assert scale[:ramp_cycles].tolist() == [(k + 1) / ramp_cycles for k in range(ramp_cycles)]
    assert np.all(scale[ramp_cycles:] == 1.0)
    forces = np.column_stack([record.column("force_n") for record in controller.records])
    depth = 0.004 / math.sqrt(2)  # m: (p - 0) . n, p = (2, 2, 0) mm, n = (1, 1, 0)/sqrt 2
    # the first cycle: the wall force at 1/50 of its scale, all along the normal (u = -(K d) n: x and y alike, z none)
    first = forces[0]
    assert first[2] == 0.0 and first[0] == pytest.approx(first[1], rel=1e-12)
    assert math.hypot(*first) == pytest.approx(1500.0 * depth / ramp_cycles, rel=1e-3)  # the enabling walk moved it < 1 um
    # pushed out along the normal: out of the slab by the end, the port's energy never below zero
    assert scene.contacts(controller.kinematics.position([r.column("position_m")[-1] for r in controller.records])) == ()
    assert summary.least_energy >= 0.0 and not summary.observer_flagged
    # the least of the whole port's energy is one it had: the energy stored in the slab at the start, or a cycle's sum
    # (break15: the several-axes path said 0 J where the run began with 3 mJ stored and never went below 2.4 mJ)
    stored = sum(controller._stored_energies(scene, list(origin)))
    port = np.sum([record.column("energy_j") for record in controller.records], axis=0)
    assert stored > 0.0
    assert summary.least_energy == pytest.approx(min(stored, float(port.min())), rel=1e-9)
    assert [a["axis"] for a in controller.axis_summaries()] == ["x", "y", "z"]
    assert summary.energy == pytest.approx(sum(a["energy_j"] for a in controller.axis_summaries()), rel=1e-12)


def test_the_ramp_is_refused_where_a_scaled_wall_is_active_on_the_way(gantry: AxesProfile) -> None:
    plane = Plane("stiff", (0.002, 0.002, 0.0), DIAGONAL, 20000.0, 0.5)
    proof = gantry.gate().proves_ramp(compile_space_scene([plane]))
    assert not proof.proven and proof.reason.startswith("stiff scaled by s along (0.707, 0.707, 0)")


def test_three_axes_take_uploads_through_the_coupled_gate_whole_at_a_cycle_boundary(gantry: AxesProfile) -> None:
    profile = dataclasses.replace(gantry, operator_model={"model": "none"})
    gate, first = profile.gate(), profile.compiled_scene()
    # the slope, whose normal (2, 2, 1)/3 couples all three axes: judged along it (0.1 s of CPU), where a change
    # to the ball is a sphere's direction search (1 s each)
    too_stiff, softer = {"slope": (1e6, 5.0)}, {"slope": (1000.0, 5.0)}
    for change in (too_stiff, softer):  # judged once before the drives run: the uploads below hit the verdict cache,
        gate.judge(first.with_walls(change))  # so the drives' RPDO deadlines never wait on the coupled criterion
    seen: dict[str, object] = {}

    def upload(running: WallController) -> None:
        if running.cycles != 5:
            return
        with pytest.raises(Refusal, match="slope") as refused:
            running.set_walls(too_stiff)  # far beyond the 8590 N/m its normal allows at B = 5 N s/m
        seen["refused"] = str(refused.value)
        seen["untouched"] = running.scene is first and running.latest_scene is first
        seen["decision"] = running.set_walls(softer)
        seen["staged"] = running.scene is first and running.latest_scene is not first

    with simulated_axes(profile) as (_, axes):
        controller = WallController(axes, gate, first, names=[a.name for a in profile.axes],
                                    force_limit=[a.force_limit for a in profile.axes], origin=encoder_origins(axes))
        axes.enable()
        assert controller.run(10, on_cycle=upload).exit_reason == "completed"
    assert seen["untouched"] and seen["staged"]
    decision = seen["decision"]
    assert isinstance(decision, SpaceDecision) and decision.accepted
    assert decision.worst_margin is not None and decision.worst_margin >= profile.gate_policy.safety_margin
    assert controller.scene.by_name()["slope"].stiffness == 1000.0 and controller.applied_scenes == 1
    assert controller.records[2].column("scene_id").tolist() == [0.0] * 5 + [1.0] * 5  # whole, at a boundary, every axis
    assert [e.kind for e in controller.events.events] == ["refused", "upload"]
    assert [entry.to_dict()["objects"][0]["kind"] for entry in controller.scenes.history] == ["sphere", "sphere"]


def test_a_1d_scene_is_refused_for_several_drives(gantry: AxesProfile) -> None:
    one_axis = load_profile("cia402-handle")
    with simulated_axes(gantry) as (_, axes):
        with pytest.raises(ParameterError, match="one Drive for a 1-D scene"):
            WallController(axes, one_axis.gate(), one_axis.compiled_scene(), force_limit=10.0)


def test_a_controller_node_detached_at_once_gives_up_its_warm_up_judgement(gantry: AxesProfile) -> None:
    """The node hands the judge worker the running scene at attach (a sphere: a direction search,
    0.3-1.8 s) and waits for it nowhere; a run stopped in its first second detaches the node then, and
    the interpreter's exit waited for that judgement (1.4-2.5 s after Ctrl-C).  Detaching gives it up
    with the worker: nothing handed to the pool is still running (or the warm-up had already ended)."""
    profile = dataclasses.replace(gantry, operator_model={"model": "none"})
    with simulated_axes(profile) as (_, axes):
        controller = WallController(axes, profile.gate(), profile.compiled_scene(), names=[a.name for a in profile.axes],
                                    force_limit=[a.force_limit for a in profile.axes], origin=encoder_origins(axes))
        with ControllerNode(controller, 42).attached(axes.link.network) as node:
            warming = node._warming  # the node's own hand-off, which only this test looks at
        assert warming is not None and warming.done()  # not cancelled: killed with the worker, or judged
        failure = warming.exception()
        assert failure is None or isinstance(failure, BrokenProcessPool)
    assert judge_pool().submit(abs, -3).result(timeout=60.0) == 3  # a new worker for the next run (it starts in 1-2 s)


class _Kinematics:
    """Cartesian's ``x = q``, ``J = I`` behind a class of its own: the controller cannot tell it is the
    identity, so it takes the path for any kinematics (``J q_dot``, ``J^T u`` as matrix products)."""

    def __init__(self, size: int) -> None:
        self._cartesian = Cartesian(size)
        self.size = size

    def position(self, q: object) -> np.ndarray:
        return self._cartesian.position(q)  # type: ignore[arg-type]

    def jacobian(self, q: object) -> np.ndarray:
        return self._cartesian.jacobian(q)  # type: ignore[arg-type]


def test_a_cartesian_device_renders_as_any_kinematics_with_its_jacobian_would(gantry: AxesProfile) -> None:
    """The Cartesian path passes the joints to the scene and takes its force as the joint efforts; the path
    for any other kinematics multiplies by ``J`` and ``J^T``.  With ``J = I`` (finite forces) each product
    is the entry itself plus zeros: through the ramp and out of the slab, every column but the clocks'
    is the same to the bit on both paths."""
    profile = slab(gantry)
    records = []
    for kinematics in (None, _Kinematics(3)):
        with simulated_axes(profile) as (_, axes):
            controller = WallController(axes, profile.gate(), profile.compiled_scene(), names=[a.name for a in profile.axes],
                                        force_limit=[a.force_limit for a in profile.axes], origin=encoder_origins(axes),
                                        ramp_time=0.1, passivity=profile.passivity, kinematics=kinematics)
            assert controller._identity is (kinematics is None)
            axes.enable()
            assert controller.run(200).exit_reason == "completed"
        records.append([record.array() for record in controller.records])
    clocks = [COLUMNS.index(name) for name in ("wall_clock_s", "monotonic_s", "compute_s", "lateness_s")]
    kept = [i for i in range(len(COLUMNS)) if i not in clocks]
    for cartesian, general in zip(*records):
        assert cartesian.shape == general.shape == (200, len(COLUMNS))
        assert np.array_equal(cartesian[:, kept], general[:, kept])
    forces = np.column_stack([axis[:, COLUMNS.index("force_n")] for axis in records[0]])
    assert np.abs(forces[:, :2]).max() > 0.05 and np.all(forces[:, 2] == 0.0)  # the slab pushed along x and y
