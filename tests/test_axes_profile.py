"""Multi-axis profiles (issue 22): ``[[axes]]`` parsed and validated with one-line errors, the bus
load checked and the coupled gate judged on load; one loader for both kinds (issue 26)."""

from __future__ import annotations

import pathlib

import pytest

from haptic_bus.analysis.loop import WallLoop
from haptic_bus.app.profiles import AxesProfile, Profile, load_profile, one_axis_only, read_profile
from haptic_bus.errors import ParameterError, Refusal

AXIS = """
[[axes]]
name = "{name}"
node_id = {node}
timing = "cia402"
force_limit = 30.0
[axes.device]
mass = {mass}
friction = {friction}
friction_source = "drive-side damping plus the guide"
velocity_per_count = 1.1984224905356573e-07
position_per_count = 1.1984224905356573e-07
rated_torque = 0.32
force_per_torque = 50.0
max_torque_permille = 2000
velocity = "average"
"""
HEAD = """
[profile]
name = "gantry-test"
operator = "test"
task = "a box, a ball and a floor on three axes"
description = "three Cartesian axes on one CANopen bus"

[loop]
period = 0.001

[bus]
bitrate = {bitrate}

[gate]
safety_margin = 0.5
bandwidth = "warn"
"""
SPACE = """
[space]
[[space.objects]]
kind = "plane"
name = "floor"
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
stiffness = 1000.0
damping = 5.0

[[space.objects]]
kind = "box"
name = "block"
center = [0.02, 0.0, 0.01]
half = [0.01, 0.01, 0.01]
stiffness = {box_k}
damping = 10.0

[[space.objects]]
kind = "sphere"
name = "ball"
center = [-0.02, 0.0, 0.01]
radius = 0.01
stiffness = 1200.0
damping = 8.0
"""
DEVICES = (("x", 5, 2.0, 30.0), ("y", 6, 1.0, 20.0), ("z", 7, 0.5, 10.0))


def gantry(tmp_path: pathlib.Path, *, bitrate: int = 1_000_000, box_k: float = 1500.0, extra: str = "",
           axes: str | None = None) -> pathlib.Path:
    """A three-axis profile file (edited by the arguments)."""
    text = HEAD.format(bitrate=bitrate) + (axes if axes is not None else "".join(
        AXIS.format(name=n, node=i, mass=m, friction=b) for n, i, m, b in DEVICES)) + SPACE.format(box_k=box_k) + extra
    path = tmp_path / "gantry.toml"
    path.write_text(text)
    return path


def test_a_gantry_profile_loads_judged_by_the_coupled_gate(tmp_path: pathlib.Path) -> None:
    profile = load_profile(gantry(tmp_path))
    assert isinstance(profile, AxesProfile)
    assert [a.name for a in profile.axes] == ["x", "y", "z"] and [a.node_id for a in profile.axes] == [5, 6, 7]
    assert profile.axis_loops()[2] == WallLoop(0.5, 10.0, 1e-3, 0.0, 0.0, 1, "average")
    assert profile.kinematics().size == 3
    load = profile.bus_load()
    assert load is not None and load.bits == 685 and load.load == pytest.approx(0.685)
    decision = profile.judge()
    assert decision.accepted and decision.worst_margin is not None and decision.worst_margin >= 0.5
    assert read_profile(profile.path or "") == profile  # the same file read, not judged: the same profile


def test_one_loader_reads_either_kind_and_one_axis_commands_refuse_axes(tmp_path: pathlib.Path) -> None:
    one, three = load_profile("cia402-handle"), load_profile(gantry(tmp_path))
    assert isinstance(one, Profile) and isinstance(read_profile("cia402-handle"), Profile)
    assert isinstance(three, AxesProfile) and len(three.axes) == 3
    assert one_axis_only(one, "validate") is one
    with pytest.raises(ParameterError) as refused:
        one_axis_only(three, "validate")
    assert str(refused.value) == (f"profile = '{three.path}' is invalid; allowed: a one-axis profile, without "
                                  "[[axes]] (validate works on one axis; this one has 3 axes)")


def test_the_bus_load_is_refused_with_the_load_and_the_smallest_period(tmp_path: pathlib.Path) -> None:
    with pytest.raises(ParameterError) as refused:  # a profile that cannot run: read refuses it, before any gate
        read_profile(gantry(tmp_path, bitrate=125_000))
    message = str(refused.value)
    assert "\n" not in message and "loop.period = 0.001" in message
    assert "bus load 548.0 % of 125 kbit/s" in message and "T >= 7.829 ms" in message


def test_a_wall_the_coupled_gate_refuses_is_named(tmp_path: pathlib.Path) -> None:
    with pytest.raises(Refusal, match=r"gantry.toml: passivity gate refused the scene: block \(K = 40000"):
        load_profile(gantry(tmp_path, box_k=40_000.0))


def test_a_wall_the_coupled_gate_refuses_loads_beyond_the_gate_under_the_bound_layer(tmp_path: pathlib.Path) -> None:
    """The one rule of both kinds: ``[passivity] beyond_gate`` (bound layer only) loads a scene its gate refuses."""
    bound = '\n[passivity]\nlayer = "bound"\nbeyond_gate = true\n'
    profile = load_profile(gantry(tmp_path, box_k=40_000.0, extra=bound))
    assert isinstance(profile, AxesProfile) and profile.passivity.beyond_gate
    assert not profile.judge().accepted


def _one_axis(**changes: object) -> str:
    text = AXIS.format(name="x", node=5, mass=1.0, friction=20.0)
    for key, value in changes.items():
        if value is None:
            text = "\n".join(line for line in text.splitlines() if not line.startswith(f"{key} ="))
        elif f"\n{key} =" in text:
            text = "\n".join(f"{key} = {value}" if line.startswith(f"{key} =") else line for line in text.splitlines())
        else:
            text = text.replace("timing =", f"{key} = {value}\ntiming =")
    return text


@pytest.mark.parametrize(("axes", "field", "allowed"), [
    (_one_axis(node_id=None), "axes[0].node_id", "exactly one of node_id"),
    (_one_axis(unit_id=3), "axes[0].node_id", "exactly one of node_id"),
    (_one_axis(node_id=200), "axes[0].node_id", "CANopen node ids 1..127"),
    (_one_axis(mapping='"full"'), "axes[0].mapping", "'minimal' or 'with-position'"),
    (_one_axis(force_limit=40.0), "axes[0].force_limit", "(0, 32] N"),
    (_one_axis(mass=-1.0), "axes[0].device.mass", "kg"),
    (_one_axis(speed=3), "axes[0].speed", "no such key"),
    (_one_axis(force_limit=None, force_limt=30.0), "axes[0].force_limt", "no such key; did you mean force_limit?"),
    (_one_axis() + _one_axis().replace('"x"', '"y"'), "axes[1].node_id",
     "a node_id no other entry uses (axes[0].node_id has it)"),
    (_one_axis(node_id=None, unit_id=2) + _one_axis(node_id=None, unit_id=2).replace('"x"', '"y"'), "axes[1].unit_id",
     "a unit_id no other entry uses (axes[0].unit_id has it)"),
    (_one_axis() + _one_axis(node_id=6), "axes[1].name", "a name no other entry uses (axes[0].name has it)"),
    (_one_axis() + _one_axis(node_id=None, unit_id=2).replace('"x"', '"y"'), "axes", "one kind of bus"),
    ("", "axes", "1 to 6 tables"),
])
def test_axes_errors_name_the_field_and_the_allowed_range(tmp_path: pathlib.Path, axes: str, field: str,
                                                          allowed: str) -> None:
    path = gantry(tmp_path, axes=axes)
    if not axes:  # an empty array of axes, at the top level where the file's kind is read
        path.write_text("axes = []\n" + path.read_text())
    with pytest.raises(ParameterError) as error:
        read_profile(path)
    assert error.value.name == field and allowed in error.value.allowed
    assert "\n" not in str(error.value)


@pytest.mark.parametrize("axes", [_one_axis(node_id=None), _one_axis(unit_id=3), _one_axis(node_id=200),
                                  _one_axis(node_id=None, nod_id=5), _one_axis(node_id=None, unit_id=0)],
                         ids=["neither", "both", "node-id-200", "misspelt", "unit-id-0"])
def test_the_simulated_drive_reads_an_axis_link_as_the_controller_does(tmp_path: pathlib.Path, axes: str) -> None:
    """One reader of node_id/unit_id (haptic_bus.profile.link): the simulated drive refuses in the controller's words
    (it let both or neither pass, leaving the check to the controller)."""
    from sim_drive.profile import read_simulated_device

    path = gantry(tmp_path, axes=axes)
    with pytest.raises(ParameterError) as controller:
        read_profile(path)
    with pytest.raises(ParameterError) as sim:
        read_simulated_device(path)
    assert str(sim.value) == str(controller.value) and controller.value.name.startswith("axes[0].")


@pytest.mark.parametrize(("old", "new", "field", "allowed"), [
    ("radius = 0.01", "radius = -0.01", "space.objects[2].radius", "(0, 1e+06] m"),
    ("center = [-0.02, 0.0, 0.01]", "center = [-0.02, 0.0]", "space.objects[2].center", "an array of 3 numbers"),
    ('kind = "sphere"', 'kind = "cone"', "space.objects[2].kind", "'plane' or 'box' or 'sphere'"),
    ("normal = [0.0, 0.0, 1.0]", "normal = [0.0, 0.0, 0.0]", "space.objects[0].normal", "a nonzero vector"),
    ('name = "ball"', 'name = "block"', "space.objects[2].name", "a name no other entry uses"),
])
def test_space_errors_name_the_field_and_the_allowed_range(tmp_path: pathlib.Path, old: str, new: str, field: str,
                                                           allowed: str) -> None:
    path = gantry(tmp_path)
    path.write_text(path.read_text().replace(old, new))
    with pytest.raises(ParameterError) as error:
        read_profile(path)
    assert isinstance(error.value, ParameterError)
    assert error.value.name == field and allowed in error.value.allowed


@pytest.mark.parametrize("argv", [
    ["identify", "--profile", "gantry-3d", "--node-id", "5", "--interface", "virtual", "--channel", "one-axis-only"],
    ["validate", "gantry-3d", "--node-id", "5", "--interface", "virtual", "--channel", "one-axis-only"],
    ["report", "gantry-3d", "--out", "{out}"],
])
def test_the_commands_that_measure_one_drive_refuse_axes_in_one_line(argv: list[str], tmp_path: pathlib.Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    from haptic_bus.app.cli import main

    assert main([arg.format(out=tmp_path / "report") for arg in argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"haptic-bus {argv[0]}: error: profile = ")
    assert err.endswith(f"allowed: a one-axis profile, without [[axes]] ({argv[0]} works on one axis; this one has "
                        "3 axes)\n")
    assert not (tmp_path / "report").exists()  # refused before anything is written
