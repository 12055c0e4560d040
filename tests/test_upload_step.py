"""An upload may not jump a wall onto the handle, as a run may not start inside one: an upload
that would put the handle inside an object it is not inside now (a wall moved or added onto it,
or one whose K was 0) is refused, one line naming the object, the force step and what to do, the
running walls kept (:meth:`~haptic_bus.control.controller.WallController.entered_step`).  A wall
the handle already presses, stiffened or moved, and walls moved away go through, judged by the
gate as before.  On one axis through the API and over SDO (``haptic-bus upload``), on three
coupled axes.

Real components: the simulated drives are CANopen slaves in this process (lock-step or python-can's
virtual bus), virtual time; the controller node answers the real upload client.
"""

from __future__ import annotations

import dataclasses
import math
import uuid

import pytest

from haptic_bus.app.cli import main
from haptic_bus.app.profiles import load_profile
from haptic_bus.app.rig import simulated_axes, simulated_canopen
from haptic_bus.control.controller import WallController
from haptic_bus.control.joints import encoder_origin, encoder_origins
from haptic_bus.control.scene import Wall, compile_scene
from haptic_bus.control.space_scene import Plane, compile_space_scene
from haptic_bus.errors import Refusal
from haptic_bus.node.controller_node import ControllerNode
from sim_drive.operator import ConstantPush

PUSH = 3.0  # N: the hand pressing into cia402-handle's end-stop (K 1500 N/m, 3 mm ahead)
SETTLE = 1500  # cycles (1.5 s) to rest in the wall: its step response is over in well under 1 s
END_STOP = 0.003  # m: the end-stop's surface


def refusal(names: str, before: float, after: float) -> str:
    """The start of the refusal for a handle put inside ``names``, its force stepping from ``before`` to ``after`` N."""
    return f"the handle would be inside {names} at once (its force would step from {before:.3g} N to {after:.3g} N, "


def test_one_axis_refuses_a_wall_added_onto_the_handle_and_takes_one_it_already_presses() -> None:
    profile = load_profile("cia402-handle")
    with simulated_canopen(profile, operator=ConstantPush(PUSH)) as (_, drive):
        controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit,
                                    origin=encoder_origin(drive))
        controller.run(SETTLE)
        x = controller.handle_position()
        assert x - END_STOP == pytest.approx(PUSH / 1500.0, rel=0.01)  # at rest: half a per-mille count over K
        end_stop = Wall("end-stop", END_STOP, -1, 1500.0, 10.0)
        bump = Wall("bump", x - 0.001, -1, 100.0, 1.0)  # its surface 1 mm behind the handle: inside it at once
        with pytest.raises(Refusal) as added:
            controller.upload_scene(compile_scene([end_stop, bump]))
        pressing = 1500.0 * (x - END_STOP)
        assert str(added.value).startswith(refusal("bump", pressing, pressing + 100.0 * 0.001))
        assert str(added.value).endswith("move it out of bump, then upload again")
        controller.set_wall("end-stop", 1800.0, 12.0)  # the wall it presses, stiffened: its operator's own change
        controller.run(1)
        moved_away = compile_scene([Wall("end-stop", x + 0.001, -1, 1800.0, 12.0)])  # 1 mm ahead of the handle
        controller.upload_scene(moved_away)
        controller.run(1)
        assert controller.applied_scenes == 2 and controller.scene.by_name()["end-stop"].position == x + 0.001
    (refused,) = [e for e in controller.events.events if e.kind == "refused"]
    assert refused.message.startswith("upload refused: the handle would be inside bump at once")


def test_haptic_bus_upload_of_a_wall_s_k_from_0_onto_the_handle_is_one_line_exit_1(
        capsys: pytest.CaptureFixture[str]) -> None:
    profile = load_profile("cia402-handle")
    channel = f"step-{uuid.uuid4().hex[:10]}"
    args = ["upload", "--interface", "virtual", "--channel", channel, "--node-id", "42", "--object", "0"]
    with simulated_canopen(profile, operator=ConstantPush(PUSH), channel=channel, interface="virtual") as (_, drive):
        controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit,
                                    origin=encoder_origin(drive))
        controller.run(SETTLE)  # 2 mm into the end-stop
        with ControllerNode(controller, 42).attached(drive.link.network):
            drive.link.read_by_notifier()  # between runs canopen's notifier reads the drive's bus
            off = main([*args, "--stiffness", "0", "--damping", "10"])  # the spring off: the hand sinks in
            controller.run(100)
            x = controller.handle_position()
            drive.link.read_by_notifier()
            capsys.readouterr()
            on = main([*args, "--stiffness", "1500", "--damping", "10"])  # back on, the handle deep inside
            err = capsys.readouterr().err
            controller.run(1)
    assert off == 0 and on == 1
    # the client's one line (the run's own log line, WARNING node 42: commit refused, is in this process too)
    (line,) = [line for line in err.splitlines() if line.startswith("haptic-bus upload:")]
    assert "Traceback" not in err
    assert line.startswith("haptic-bus upload: refused: " + refusal("end-stop", 0.0, 1500.0 * (x - END_STOP)))
    assert f"{0.5 * 1500.0 * (x - END_STOP) ** 2 * 1e3:.3g} mJ in the new walls' springs" in line
    assert line.endswith("move it out of end-stop, then upload again")
    assert controller.scene.by_name()["end-stop"].stiffness == 0.0  # the running wall kept


def test_three_axes_refuse_a_plane_moved_onto_the_handle_and_take_the_one_it_presses_stiffer() -> None:
    gantry = load_profile("gantry-3d")
    normal = (1.0, 1.0, 0.0)
    slab = Plane("slab", (0.002, 0.002, 0.0), normal, 1500.0, 5.0)  # the handle starts 2.83 mm inside
    shelf = Plane("shelf", (0.0, 0.0, 0.001), (0.0, 0.0, 1.0), 800.0, 5.0)  # 1 mm above it: inside at once
    profile = dataclasses.replace(gantry, space=(slab,), operator_model={"model": "none"})
    gate, first = profile.gate(), profile.compiled_scene()
    onto, stiffer = compile_space_scene([slab, shelf]), first.with_walls({"slab": (2000.0, 5.0)})
    for scene in (onto, stiffer):  # judged before the drives run: the uploads below hit the verdict cache
        gate.judge(scene)
    seen: dict[str, object] = {}

    def upload(running: WallController) -> None:
        if running.cycles == 2:
            seen["x"] = running.handle_position()
            with pytest.raises(Refusal) as refused:
                running.upload_scene(onto)
            seen["refused"] = str(refused.value)
            running.upload_scene(stiffer)

    with simulated_axes(profile) as (_, axes):
        controller = WallController(axes, gate, first, names=[a.name for a in profile.axes],
                                    force_limit=[a.force_limit for a in profile.axes], origin=encoder_origins(axes))
        axes.enable()
        assert controller.run(4, on_cycle=upload).exit_reason == "completed"
    x = seen["x"]
    depth = float(sum((0.002 - c) * n for c, n in zip(x, normal)) / math.sqrt(2.0))  # into the slab, m
    assert 0.0027 < depth < 0.0029  # 4 mm / sqrt 2, the slab pushing it out slowly
    rise = 800.0 * (0.001 - x[2])  # N: the shelf's push along z, orthogonal to the slab's
    assert str(seen["refused"]).startswith(refusal("shelf", 1500.0 * depth, math.hypot(1500.0 * depth, rise)))
    assert controller.scene.by_name()["slab"].stiffness == 2000.0 and controller.applied_scenes == 1
