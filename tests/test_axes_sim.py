"""The simulated multi-axis device (issue 22): one CANopen slave per axis on one bus, each its own
exact plant with its hidden truth; ``scan`` finds all of them, ``identify --node-id N`` measures one
axis while the others stay disabled; ``haptic-bus sim --node-ids`` refuses what it cannot serve.

Why the other axes stay disabled (not enabled at zero torque) while one is identified: identify
is a one-drive master that knows nothing of the others, and on a Cartesian device the axes are
independent plants (``J = I``, a diagonal mass), so an axis neither moves nor loads the measured
one whether it is disabled or enabled at zero torque -- the same zero force -- while enabling it
would hand its safety chain (RPDO deadline, heartbeat) to a master that does not serve it.  The
SYNCs of the measured axis reach every node (they share the bus), so their plants keep time.
"""

from __future__ import annotations

import json
import math
import pathlib
import uuid

import pytest

from drives.cia402 import State
from haptic_bus.app.cli import main
from haptic_bus.app.identify_run import IdentifyOptions, identify_canopen
from haptic_bus.app.profiles import load_profile, read_profile
from haptic_bus.app.rig import simulated_axes_device
from sim_drive.cli import main as sim_main
from tests.guess_profile import guess_profile
from tests.run_rig import wait_until

SIGMAS = 4.0


def test_scan_finds_every_axis_and_identify_measures_one_while_the_others_stay(
        tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    gantry = load_profile("gantry-3d")
    channel = f"axes-sim-{uuid.uuid4().hex[:10]}"
    quiet = gantry.__class__(**{**gantry.__dict__, "operator_model": {"model": "none"}})  # nobody touches the handle
    sim = simulated_axes_device(quiet, {"interface": "virtual", "channel": channel}).start()
    try:
        code = main(["scan", "--interface", "virtual", "--channel", channel, "--node-ids", "1-10", "--json"])
        found = json.loads(capsys.readouterr().out)
        assert code == 0
        assert [row["node_id"] for row in found] == [5, 6, 7]
        assert all(row["cia402"] and row["cst_supported"] for row in found), found
        # the y axis of gantry-3d as a one-axis profile: what identify needs of it (scaling, period, force limit);
        # the guesses 0.8 kg and 15 N s/m (the truth is 1 kg and 20 N s/m)
        profile_path = guess_profile(tmp_path / "gantry-y.toml", comment="The y axis of gantry-3d as a one-axis profile.",
                                     name="gantry-y", task="identify one axis of the gantry",
                                     description="the y axis of gantry-3d, node 6", mass=0.8, friction=15.0,
                                     velocity="average", rated_torque=0.1, period=0.002, force_limit=10.0)
        outcome = identify_canopen(read_profile(profile_path), {"interface": "virtual", "channel": channel}, 6,
                                   IdentifyOptions(duration=6.0, pacing="virtual"))
        # python-can's virtual bus hands each node its frames in that node's own thread: the last SYNC may
        # still be on its way to one of them when identify returns
        wait_until(lambda: len({node.drive.sync_count for node in sim.nodes}) == 1)
        states = [node.drive.state for node in sim.nodes]
        positions = [node.drive.handle.position for node in sim.nodes]
        syncs = [node.drive.sync_count for node in sim.nodes]
        energy = [node.drive.wall_energy for node in sim.nodes]
    finally:
        sim.stop()
    assert outcome.exit_reason == "completed" and outcome.exit_status == 0, outcome.error
    fit = outcome.identification.fit  # type: ignore[union-attr]
    assert fit is not None
    assert abs(fit.mass.value / 1.0 - 1) < 0.03 and abs(fit.mass.value - 1.0) <= SIGMAS * fit.mass.stderr
    assert abs(fit.friction.value / 20.0 - 1) < 0.03 and abs(fit.friction.value - 20.0) <= SIGMAS * fit.friction.stderr
    assert fit.whole_delay == 1
    assert states == [State.SWITCH_ON_DISABLED] * 3  # identify left node 6 disabled; 5 and 7 were never enabled
    assert positions[0] == 0.0 and positions[2] == 0.0 and positions[1] != 0.0  # only y moved
    assert energy[0] == 0.0 and energy[2] == 0.0 and energy[1] != 0.0  # only node 6's motor worked
    assert syncs[0] == syncs[1] == syncs[2] > 6.0 / 0.002  # every plant heard every SYNC


@pytest.mark.parametrize(("args", "expected"), [
    (["--node-ids", "5,6,9", "--profile", "gantry-3d"], "node ids of the profile's [[axes]]: [5, 6, 7]"),
    (["--node-ids", "5,5"], "distinct CANopen node ids 1..127"),
    (["--node-ids", "5,6", "--node-id", "5"], "without --node-id and --eds"),
])
def test_the_multi_axis_simulator_refuses_what_it_cannot_serve(
        capsys: pytest.CaptureFixture[str], args: list[str], expected: str) -> None:
    code = sim_main(["--interface", "virtual", "--channel", f"never-{uuid.uuid4().hex[:8]}", *args])
    err = capsys.readouterr().err
    assert code == 2 and expected in err and err.count("\n") == 1


def test_the_hand_in_space_pushes_every_axis_towards_its_point() -> None:
    """Each axis takes its component of one push, computed once per period from every axis' position."""
    from sim_drive.space_operator import SpacePush

    hand = SpacePush([[3.0, 4.0, 0.0]], force=5.0)
    assert hand.vector(0.0, [0.0, 0.0, 0.0]) == [3.0, 4.0, 0.0]
    assert hand.vector(0.0, [3.0, 4.0, 0.0]) == [0.0, 0.0, 0.0]  # at the point: no direction, no force
    two = SpacePush([[1.0, 0.0], [0.0, 2.0]], force=2.0, dwell=1.5)
    assert two.target(1.49) == (1.0, 0.0) and two.target(1.5) == (0.0, 2.0) and two.target(99.0) == (0.0, 2.0)
    assert math.isclose(sum(c * c for c in two.vector(2.0, [0.0, 0.0])), 4.0)
