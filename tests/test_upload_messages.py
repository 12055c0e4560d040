"""``haptic-bus upload``'s messages and exit statuses, against a real controller node and a real simulated
drive on one python-can virtual bus (one process): an object the scene lacks (2, before any write, never
the last commit's verdict), the drive's node id instead of the controller's (1, one clear line), no
controller at all (1, "no controller answered on node N within T s"), an accepted and a refused upload."""

from __future__ import annotations

import dataclasses
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from haptic_bus.app.cli import main
from haptic_bus.app.profiles import load_profile
from haptic_bus.app.rig import simulated_canopen
from haptic_bus.control.controller import WallController
from haptic_bus.control.joints import encoder_origin
from haptic_bus.control.scene import Wall
from haptic_bus.node.controller_node import ControllerNode

DRIVE, CONTROLLER = 5, 42


@contextmanager
def controller_and_drive() -> Iterator[tuple[list[str], WallController]]:
    """The seed profile's wall served by controller node 42, the simulated drive as node 5, on one
    virtual bus; yields the ``upload`` arguments that select the bus, and the controller."""
    profile = dataclasses.replace(load_profile("seed-ideal"), scene=(Wall("wall", 0.0, -1, 200.0, 100.0),))
    channel = f"upload-{uuid.uuid4().hex[:10]}"
    with simulated_canopen(profile, node_id=DRIVE, channel=channel, interface="virtual") as (_, drive):
        controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit,
                                    origin=encoder_origin(drive))
        with ControllerNode(controller, CONTROLLER).attached(drive.link.network):
            drive.link.read_by_notifier()  # canopen's notifier reads the drive's bus between runs
            yield ["upload", "--interface", "virtual", "--channel", channel], controller


def one_line(err: str) -> str:
    """The upload's one line (the controller node, in this process too, logs its own refusals)."""
    node_log = "WARNING haptic_bus.node.controller_node:"
    err = "".join(line for line in err.splitlines(keepends=True) if not line.startswith(node_log))
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err


def test_an_object_the_scene_lacks_is_named_with_what_it_has_not_the_last_verdict(
        capsys: pytest.CaptureFixture[str]) -> None:
    with controller_and_drive() as (bus, controller):
        upload = [*bus, "--node-id", str(CONTROLLER)]
        assert main([*upload, "--object", "0", "--stiffness", "5e6", "--damping", "1"]) == 1  # a verdict at 0x2002
        refused = one_line(capsys.readouterr().err)
        assert refused.startswith("haptic-bus upload: refused: passivity gate refused")
        assert main([*upload, "--object", "7", "--stiffness", "250", "--damping", "120"]) == 2
        err = one_line(capsys.readouterr().err)
        assert err == ("haptic-bus upload: error: --object = 7 is invalid; allowed: an object of the running "
                       f"scene, 0..0 (controller node {CONTROLLER} has 1 object: 0 'wall')\n")
        assert "passivity" not in err
        controller.run(2)
        assert controller.scene.by_name()["wall"].stiffness == 200.0  # nothing was written
        controller.axes.drives[0].link.read_by_notifier()  # the run read the bus itself: canopen's notifier again
        assert main([*upload, "--object", "0", "--stiffness", "250", "--damping", "120"]) == 0
        assert capsys.readouterr().out.startswith("accepted")


def test_the_drives_node_id_says_it_answered_as_a_drive(capsys: pytest.CaptureFixture[str]) -> None:
    with controller_and_drive() as (bus, _):
        assert main([*bus, "--node-id", str(DRIVE), "--object", "0", "--stiffness", "250", "--damping", "120"]) == 1
        err = one_line(capsys.readouterr().err)
    assert err == (f"haptic-bus upload: node {DRIVE} answered as a drive, not a haptic-bus controller "
                   "(0x1000 = 0x00020192: CiA-402 servo drive)\n")


def test_no_controller_on_the_node_says_so_within_the_timeout(capsys: pytest.CaptureFixture[str]) -> None:
    with controller_and_drive() as (bus, _):
        started = time.monotonic()
        assert main([*bus, "--node-id", "99", "--timeout", "0.2", "--object", "0", "--stiffness", "1", "--damping", "1"]) == 1
        elapsed = time.monotonic() - started
        err = one_line(capsys.readouterr().err)
    assert err == ("haptic-bus upload: no controller answered on node 99 within 0.2 s (is haptic-bus run going on this "
                   "bus with --controller-node-id 99?; python-can's virtual bus reaches this process alone: a run in "
                   "another process is never on it)\n")
    assert elapsed < 10.0  # one unanswered read and the bus's open and close; a hang would run far past it


@pytest.mark.parametrize("argv, message", [
    (["--object", "256"], "object = 256 is invalid"),
    (["--stiffness", "nan"], "stiffness = nan is invalid"),
    (["--damping", "-1"], "damping = -1.0 is invalid"),
    (["--bus-option", "port=1", "--bus-kwargs", "port=2"], "one value per key"),
])
def test_invalid_input_is_exit_2_before_the_bus(argv: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    base = {"--object": "0", "--stiffness": "1", "--damping": "1"}
    for flag, value in zip(argv[::2], argv[1::2], strict=True):
        base[flag] = value
    args = ["upload", "--interface", "no-such-interface", "--node-id", "3", *(x for kv in base.items() for x in kv)]
    assert main(args) == 2  # the interface is never opened: an unknown one would be exit 1
    assert message in one_line(capsys.readouterr().err)
