"""One profile format, read once: the controller's view and the simulated drive's view of the same file.

``haptic_bus.profile`` reads ``[device]``, ``[loop]``, ``[operator_model]`` and ``[identification]``
for both; these tests hold the two views to the same numbers and the same one-line errors.
"""

from __future__ import annotations

import pathlib
import tomllib
from collections.abc import Callable

import pytest

from haptic_bus.app.cli import main as haptic_bus_main
from haptic_bus.app.profiles import read_profile, resolve_profile, shipped_profiles
from haptic_bus.errors import ParameterError
from haptic_bus.profile.identification import IdentifiedDevice, read_identification
from sim_drive.cli import main as sim_main
from sim_drive.parameters import DeviceParameters, Timing
from sim_drive.profile import read_simulated_device


@pytest.mark.parametrize("name", sorted(shipped_profiles()))
def test_both_views_of_every_shipped_profile_agree(name: str) -> None:
    believed = read_profile(name)
    truth, _ = read_simulated_device(name).one_axis()
    assert truth.parameters == DeviceParameters(**believed.sim_device_parameters())  # type: ignore[arg-type]
    assert truth.timing is Timing(believed.loop.timing)


def _variant(tmp_path: pathlib.Path, old: str, new: str, name: str = "cia402-handle", count: int = 1) -> pathlib.Path:
    """The shipped profile ``name`` with ``old`` replaced by ``new`` (``count`` times, -1: everywhere)."""
    text = resolve_profile(name).read_text()
    assert old in text
    path = tmp_path / "variant.toml"
    path.write_text(text.replace(old, new, count))
    return path


def _same_line(path: pathlib.Path, readers: tuple[Callable[[pathlib.Path], object], ...], field: str) -> str:
    """The one line every reader refuses ``path`` with (ParameterError on ``field``), asserted the same."""
    lines = []
    for read in readers:
        with pytest.raises(ParameterError) as caught:
            read(path)
        assert caught.value.name == field
        lines.append(str(caught.value))
    assert lines[0] == lines[-1] and "\n" not in lines[0]
    return lines[0]


@pytest.mark.parametrize(("old", "new", "field", "allowed"), [
    ("mass = 1.0", "mass = nan", "device.mass", "a finite real in [1e-09, 1e+09] kg"),
    ("mass = 1.0", "mass = -1.0", "device.mass", "a finite real in [1e-09, 1e+09] kg"),
    ("mass = 1.0", 'mass = "1.0"', "device.mass", "a finite real in [1e-09, 1e+09] kg"),
    ("max_torque_permille = 2000", "max_torque_permille = 2000.0", "device.max_torque_permille", "an integer in [1, 32767]"),
    ("[loop]", "[loop]\nperod = 0.001", "loop.perod", "no such key; keys of [loop]"),
    ("[device]", "[devcie]\n[device]", "devcie", "no such key; keys of [top level]"),
    ("stiffness = 1500.0", "stiffness = nan", "scene.objects[0].stiffness", "a finite real in [0"),
    ("force_limit = 30.0", "force_limit = -5", "limits.force_limit", "a finite real in (0, 1e+06] N"),
    ("force_limit = 30.0", "force_limit = 1000.0", "limits.force_limit", "the force 0x6072 allows"),
    ('kind = "wall"', 'kind = "wal"', "scene.objects[0].kind", "'wall' or 'slot' or 'detent'"),
])
def test_both_views_refuse_a_bad_value_with_the_same_line(tmp_path: pathlib.Path, old: str, new: str, field: str,
                                                           allowed: str) -> None:
    path = _variant(tmp_path, old, new)
    line = _same_line(path, (read_profile, read_simulated_device), field)
    assert allowed in line.split("allowed: ", 1)[1]
    assert line.startswith(f"profile {path}: {field} = ")


def test_the_command_lines_say_it_in_one_line_and_exit_2(tmp_path: pathlib.Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    path = _variant(tmp_path, "friction = 20.0", "friction = inf")
    assert haptic_bus_main(["profiles", "check", str(path)]) == 2
    controller = capsys.readouterr().err.strip()
    assert sim_main(["--interface", "virtual", "--channel", "views", "--node-id", "3", "--profile", str(path)]) == 2
    simulator = capsys.readouterr().err.strip()
    for err in (controller, simulator):
        assert err.count("\n") == 0 and "Traceback" not in err
        assert f"profile {path}: device.friction = inf is invalid; allowed: a finite real in [0" in err


def test_a_file_that_is_not_utf8_is_one_line_and_exit_2_everywhere(tmp_path: pathlib.Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "binary.toml"
    path.write_bytes(b"\xff\xfe garbage")
    commands = [(haptic_bus_main, ["profiles", "check", str(path)]),
                (haptic_bus_main, ["run", str(path), "--interface", "virtual", "--channel", "utf8", "--node-id", "5",
                                   "--virtual-time", "--out", str(tmp_path / "run")]),
                (sim_main, ["--interface", "virtual", "--channel", "utf8", "--node-id", "3", "--profile", str(path)])]
    for command, args in commands:
        assert command(args) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "Traceback" not in err
        assert err.endswith(f"profile {path}: (encoding) = 'byte 0xFF at 0' is invalid; allowed: UTF-8 text (TOML 1.0)")
    assert not (tmp_path / "run").exists()


def test_the_simulator_fills_what_a_profile_leaves_out_and_takes_an_identified_delay(tmp_path: pathlib.Path) -> None:
    bare = tmp_path / "bare.toml"
    bare.write_text('[device]\nmass = 0.8\n')
    (drive,) = read_simulated_device(bare).axes  # a one-axis profile is one axis; silent on timing: cia402
    assert drive.parameters == DeviceParameters(mass=0.8) and drive.timing is Timing.CIA402
    # identify --write-profile writes the largest credible delay: above cia402's own sample, still a cia402 drive
    path = _variant(tmp_path, 'timing = "cia402"', 'timing = "cia402"\ndelay = 1.3')
    assert read_profile(path).loop.delay == 1.3 and read_simulated_device(path).axes[0].timing is Timing.CIA402


def test_the_simulator_refuses_a_multi_axis_profile_for_one_node() -> None:
    with pytest.raises(ParameterError) as caught:
        read_simulated_device("gantry-3d").one_axis()
    assert caught.value.name == "axes" and "--node-ids" in caught.value.allowed


def test_identification_is_written_and_read_as_one_table(tmp_path: pathlib.Path) -> None:
    measured = IdentifiedDevice("2026-12-02T05:00:00Z", 1.02, 0.01, 20.5, 0.2, 0.3, 0.05, 1.1, 0.05,
                                read_profile("cia402-handle").device.velocity, 30.0, 2e-6)
    table = measured.as_table()
    assert table["velocity"] == "average" and next(iter(table)) == "date"
    text = "".join(f"{key} = {value!r}\n".replace("'", '"') for key, value in table.items())
    assert read_identification(tmp_path / "p.toml", tomllib.loads(text)) == measured
    assert measured.lowest_credible_friction == pytest.approx(19.9) and measured.largest_credible_delay == pytest.approx(1.25)


def test_both_views_of_a_multi_axis_profile_refuse_a_bad_axis_with_the_same_line(tmp_path: pathlib.Path) -> None:
    from haptic_bus.app.profiles import read_profile
    path = _variant(tmp_path, "\nmass = 0.5\n", "\nmass = -0.5\n", "gantry-3d")
    assert "[1e-09, 1e+09] kg" in _same_line(path, (read_profile, read_simulated_device), "axes[2].device.mass")
    truth = read_simulated_device("gantry-3d")
    believed = read_profile("gantry-3d")
    assert [(a.name, a.node_id, a.parameters.mass, a.parameters.friction) for a in truth.axes] == [
        (a.name, a.node_id, a.device.mass, a.device.friction) for a in believed.axes]


def test_a_misspelt_table_is_named_first_by_both_views_and_every_command(tmp_path: pathlib.Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    path = _variant(tmp_path, "[loop]", "[loopp]")
    line = _same_line(path, (read_profile, read_simulated_device), "loopp")
    assert "no such key; keys of [top level]: device, gate, identification, limits, loop," in line
    commands = [(haptic_bus_main, ["profiles", "check", str(path)]),
                (haptic_bus_main, ["profiles", "show", str(path)]),
                (haptic_bus_main, ["run", str(path), "--interface", "virtual", "--channel", "loopp", "--node-id", "5",
                                   "--virtual-time", "--out", str(tmp_path / "run")]),
                (sim_main, ["--interface", "virtual", "--channel", "loopp", "--node-id", "3", "--profile", str(path)])]
    for command, args in commands:
        assert command(args) == 2
        out = capsys.readouterr()
        assert out.err.count("\n") == 1 and out.err.strip().endswith(line) and "still missing" not in out.out
    assert not (tmp_path / "run").exists()


def test_profiles_check_and_show_judge_a_multi_axis_profile_by_the_coupled_gate(
        tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    import json

    from haptic_bus.app.profiles import load_profile

    profile = load_profile("gantry-3d")
    decision = profile.gate().judge(profile.compiled_scene())
    assert haptic_bus_main(["profiles", "show", "gantry-3d", "--json"]) == 0  # the shape of a one-axis show
    report = json.loads(capsys.readouterr().out)
    assert report["gate_decision"]["accepted"] and [a["name"] for a in report["axes"]] == ["x", "y", "z"]
    assert report["gate_decision"]["worst_margin"] == pytest.approx(decision.worst_margin, rel=1e-12)
    assert report["gate_decision"]["worst_margin"] == pytest.approx(4.28, abs=0.005)  # the profile's own comment
    assert [o["name"] for o in report["space"]["objects"]] == ["ball", "block", "slope"]
    assert haptic_bus_main(["profiles", "check", "gantry-3d", "--json"]) == 0  # the shape of a one-axis check
    checked = json.loads(capsys.readouterr().out)
    assert checked["profile"] == "gantry-3d" and checked["passive"] is True and checked["gate"]["accepted"] is True
    assert checked["gate"]["worst_margin"] == report["gate_decision"]["worst_margin"]
    assert checked["gate"]["safety_margin"] == 2.0 and checked["walls"] == report["gate_decision"]["walls"]
    assert haptic_bus_main(["profiles", "check", "cia402-handle", "--json"]) == 0
    assert set(json.loads(capsys.readouterr().out)) == set(checked)  # one shape, either kind
    assert haptic_bus_main(["profiles", "show", "gantry-3d"]) == 0
    shown = capsys.readouterr().out
    assert "z (node 7): m=0.5 kg b=10 N s/m" in shown and "sphere ball: center=(0, -0.03, 0), radius=0.01" in shown
    assert "coupled gate: accepts" in shown and "ball: margin +4.277 N s/m" in shown
    # a wall the coupled gate refuses: check says so, show still shows it; both exit 1, as for one axis
    stiff = _variant(tmp_path, "stiffness = 1500", "stiffness = 200000", "gantry-3d", -1)
    assert haptic_bus_main(["profiles", "check", str(stiff)]) == 1
    assert "coupled gate: REFUSES" in capsys.readouterr().out
    assert haptic_bus_main(["profiles", "show", str(stiff)]) == 1
    shown = capsys.readouterr()
    assert "refused:" in shown.out and shown.err.count("\n") == 1 and "passivity gate refused the scene" in shown.err
    # an invalid value: one line, exit 2, from both commands
    bad = _variant(tmp_path, "\nmass = 0.5\n", "\nmass = nan\n", "gantry-3d")
    for command in ("check", "show"):
        assert haptic_bus_main(["profiles", command, str(bad)]) == 2
        out = capsys.readouterr()
        assert out.out == "" and out.err.count("\n") == 1 and "axes[2].device.mass = nan is invalid" in out.err


def test_the_simulator_refuses_a_bad_scene_before_serving(tmp_path: pathlib.Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    path = _variant(tmp_path, "stiffness = 1500.0", "stiffness = nan")
    assert sim_main(["--interface", "virtual", "--channel", "scene", "--node-id", "3", "--profile", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.endswith(f"profile {path}: scene.objects[0].stiffness = nan is invalid; "
                                                 "allowed: a finite real in [0, 1e+15] N/m")
