"""Operator parameter profiles: shipped files load and pass the gate, bad files are named precisely."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import pathlib

import pytest

from haptic_bus.analysis.check import check_loop
from haptic_bus.analysis.loop import BANDWIDTH_ALPHA, WallLoop
from haptic_bus.analysis.resolution import Quantisation
from haptic_bus.app.profiles import (
    DEFAULT_PROFILE,
    Profile,
    default_profile,
    load_profile,
    profile_to_dict,
    read_profile,
    shipped_profiles,
)
from haptic_bus.app.profiles_cli import add_profiles_parser, cmd_check, cmd_list, cmd_show
from haptic_bus.control.scene import Detent, Slot, Wall
from haptic_bus.errors import ParameterError, Refusal

SHIPPED = shipped_profiles()

# A small valid profile; tests break it one field at a time.
BASE = """\
[profile]
name = "t"
operator = "tester"
task = "test"
description = "a test profile"

[device]
mass = 1.0
friction = 20.0
friction_source = "test bench"
velocity_per_count = 1e-6
position_per_count = 1e-7
rated_torque = 0.2
force_per_torque = 50.0
max_torque_permille = 1000
velocity = "average"

[loop]
period = 0.001
timing = "cia402"

[limits]
force_limit = 10.0

[gate]
safety_margin = 0.0
bandwidth = "warn"

[[scene.objects]]
kind = "wall"
name = "a"
position = 0.0
normal = -1
stiffness = 1000.0
damping = 8.0

[[scene.objects]]
kind = "detent"
name = "b"
center = 0.01
reach = 0.002
stiffness = 100.0
damping = 1.0

[[scene.objects]]
kind = "slot"
name = "c"
low = -0.05
high = 0.05
stiffness = 500.0
damping = 4.0

[operator_model]
model = "constant"
level = 2.0
"""


def write(tmp_path: pathlib.Path, text: str, name: str = "p.toml") -> pathlib.Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_base_profile_loads(tmp_path):
    profile = load_profile(write(tmp_path, BASE))
    assert isinstance(profile, Profile)
    assert [type(o) for o in profile.scene] == [Wall, Detent, Slot]
    assert profile.loop.delay == 1 and profile.device.max_force == pytest.approx(10.0)
    assert profile.scaling().max_force == pytest.approx(10.0)
    assert profile.device_loop().delay == 1
    assert dict(profile.operator_model) == {"model": "constant", "level": 2.0}


# ---------------------------------------------------------------- shipped profiles

def test_shipped_set_and_default():
    assert {"seed-ideal", "cia402-handle", "stiff-wall", "multi-object"} <= set(SHIPPED)
    assert DEFAULT_PROFILE == "cia402-handle" and DEFAULT_PROFILE in SHIPPED
    assert default_profile().name == DEFAULT_PROFILE


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_profile_loads_and_gate_agrees_with_check(name):
    """The gate's verdict on every summed contact wall is what ``haptic-bus check`` says."""
    profile = load_profile(name)
    assert profile.name == name and profile.path == SHIPPED[name]
    assert 0 < profile.force_limit <= profile.device.max_force * (1 + 1e-12)
    decision = profile.gate().judge(profile.compiled_scene())
    assert decision.accepted and decision.walls
    d, loop = profile.device, profile.loop
    for wall in decision.walls:
        report = check_loop(WallLoop(d.mass, d.friction, loop.period, wall.K, wall.B, loop.delay, d.velocity))
        assert report.passive is True
        assert report.passive == wall.verdict.passive
        assert report.margin == wall.verdict.margin  # the same criterion, the same number
        assert wall.verdict.margin >= profile.gate_policy.safety_margin
        if profile.gate_policy.bandwidth == "warn" and report.bandwidth_rule_holds is False:
            assert any(f"K = {wall.K:g} N/m" in w for w in decision.warnings)


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_profile_builds_the_simulated_drive(name):
    """operator_model and sim_device_parameters() are what sim_drive takes."""
    from sim_drive.operator import OPERATOR_NAMES, operator_from_table
    from sim_drive.parameters import DeviceParameters

    profile = load_profile(name)
    model = operator_from_table(profile.operator_model, base=profile.path.parent)
    assert type(model) is OPERATOR_NAMES[profile.operator_model["model"]]
    params = DeviceParameters(**profile.sim_device_parameters())
    assert params.scaling == profile.scaling()


def test_seed_ideal_numbers():
    profile = load_profile("seed-ideal")
    assert (profile.device.mass, profile.device.friction, profile.loop.period) == (0.5, 0.1, 1e-3)
    assert profile.loop.timing == "ideal" and profile.loop.delay == 0
    assert [(o.stiffness, o.damping) for o in profile.scene] == [(200.0, 100.0)]
    (wall,) = profile.gate().judge(profile.compiled_scene()).walls
    # At theta = pi the seed's margin is b minus a term of order (B + KT/2) tanh(c/2) ~ 1e-4
    assert wall.verdict.margin == pytest.approx(0.0998, abs=1e-4)


def test_seed_profile_with_cia402_timing_is_refused(tmp_path):
    text = SHIPPED["seed-ideal"].read_text().replace('timing = "ideal"', 'timing = "cia402"')
    path = write(tmp_path, text, "seed-cia402.toml")
    with pytest.raises(Refusal) as caught:
        load_profile(path)
    assert str(caught.value).startswith(f"profile {path}: passivity gate refused the scene: ")
    assert str(path) in str(caught.value)
    (wall,) = caught.value.decision.walls
    assert wall.verdict.margin == pytest.approx(-84.09, abs=0.01)  # haptic-bus check --delay 1
    assert wall.verdict.critical_theta == pytest.approx(1.97, abs=0.01)
    assert read_profile(path).loop.delay == 1  # valid, just not passive


def test_default_profile_is_a_realistic_cia402_handle():
    profile = load_profile(DEFAULT_PROFILE)
    assert profile.loop.timing == "cia402" and profile.loop.period == 1e-3
    assert 0.2 <= profile.device.mass <= 2.0
    assert profile.device.friction_source.strip()
    decision = profile.gate().judge(profile.compiled_scene())
    assert not decision.warnings and profile.gate_policy.bandwidth == "strict"
    for wall in decision.walls:
        loop = WallLoop(profile.device.mass, profile.device.friction, 1e-3, wall.K, wall.B, 1)
        assert loop.alpha > BANDWIDTH_ALPHA
        assert wall.K <= 0.5 * check_loop(loop).max_stiffness  # well inside the region
        assert wall.B <= 0.5 * check_loop(loop).max_damping
    push = profile.operator_model
    assert push["model"] == "constant" and 0 < push["level"] < 10
    (wall,) = profile.scene
    assert wall.normal == -1 and 0.001 <= wall.position <= 0.01  # a few mm ahead of x = 0


def test_multi_object_has_overlaps():
    profile = load_profile("multi-object")
    kinds = {type(o) for o in profile.scene}
    assert kinds == {Wall, Slot, Detent}
    contacts = profile.compiled_scene().contacts()
    assert any(len(names) > 1 for names in contacts.values())  # summed objects are judged


# ---------------------------------------------------------------- malformed profiles

def broken(tmp_path, old: str, new: str) -> ParameterError:
    assert old in BASE
    path = write(tmp_path, BASE.replace(old, new, 1))
    with pytest.raises(ParameterError) as caught:
        load_profile(path)
    error = caught.value
    assert error.context == f"profile {path}" and str(path) in str(error)
    assert error.name in str(error) and error.allowed in str(error)
    return error


def test_missing_field(tmp_path):
    error = broken(tmp_path, "mass = 1.0\n", "")
    assert error.name == "device.mass" and error.value is None and "is missing" in str(error) and "kg" in error.allowed


def test_wrong_type(tmp_path):
    error = broken(tmp_path, "mass = 1.0", 'mass = "1.0"')
    assert error.name == "device.mass" and error.value == "1.0" and "finite real" in error.allowed


def test_nan(tmp_path):
    error = broken(tmp_path, "friction = 20.0", "friction = nan")
    assert error.name == "device.friction" and math.isnan(error.value)
    assert "N s/m" in error.allowed and "nan" in str(error)


def test_negative_mass(tmp_path):
    error = broken(tmp_path, "mass = 1.0", "mass = -0.5")
    assert (error.name, error.value) == ("device.mass", -0.5)
    assert "[1e-09, 1e+09] kg" in error.allowed


def test_negative_stiffness_names_the_object(tmp_path):
    error = broken(tmp_path, "stiffness = 500.0", "stiffness = -500.0")
    assert (error.name, error.value) == ("scene.objects[2].stiffness", -500.0)
    assert "N/m" in error.allowed


def test_unknown_object_kind(tmp_path):
    error = broken(tmp_path, 'kind = "detent"', 'kind = "cylinder"')
    assert (error.name, error.value) == ("scene.objects[1].kind", "cylinder")
    assert all(k in error.allowed for k in ("wall", "slot", "detent"))


def test_unknown_key_is_a_typo(tmp_path):
    error = broken(tmp_path, "damping = 8.0", "damping = 8.0\ndampng = 9.0")
    assert (error.name, error.value) == ("scene.objects[0].dampng", 9.0)
    assert "no such key" in error.allowed and "damping" in error.allowed


def test_a_misspelt_required_key_is_named_not_reported_missing(tmp_path):
    error = broken(tmp_path, "mass = 1.0", "mas = 1.0")
    assert (error.name, error.value) == ("device.mas", 1.0)
    assert error.allowed.startswith("no such key; did you mean mass? (mass is required: ") and "kg" in error.allowed


def test_unknown_table(tmp_path):
    error = broken(tmp_path, "[limits]", "[limit]\nx = 1\n\n[limits]")
    assert error.name == "limit"


def test_duplicate_object_names(tmp_path):
    error = broken(tmp_path, 'name = "c"', 'name = "a"')
    assert (error.name, error.value) == ("scene.objects[2].name", "a")
    assert "(scene.objects[0].name has it)" in error.allowed


def test_force_limit_above_0x6072(tmp_path):
    error = broken(tmp_path, "force_limit = 10.0", "force_limit = 10.5")
    assert (error.name, error.value) == ("limits.force_limit", 10.5)
    assert "(0, 10] N" in error.allowed and "0x6072" in error.allowed


def test_bad_timing_and_permille_type(tmp_path):
    assert broken(tmp_path, 'timing = "cia402"', 'timing = "ethercat"').name == "loop.timing"
    assert broken(tmp_path, "max_torque_permille = 1000", "max_torque_permille = 1000.0").name == \
        "device.max_torque_permille"


def test_bad_operator_model(tmp_path):
    error = broken(tmp_path, "level = 2.0", "levle = 2.0")
    assert error.name == "operator_model.levle" and "did you mean level? (level is required" in error.allowed
    error = broken(tmp_path, 'model = "constant"', 'model = "jitter"')
    assert error.name == "operator_model.model" and "'hand'" in error.allowed


def test_csv_operator_resolves_beside_the_profile(tmp_path):
    from sim_drive.operator import RecordedForce, operator_from_table

    (tmp_path / "push.csv").write_text("time,force\n0,0\n0.1,2\n")
    text = BASE.replace('model = "constant"\nlevel = 2.0', 'model = "csv"\npath = "push.csv"')
    profile = load_profile(write(tmp_path, text))
    assert profile.operator_model["model"] == "recorded"
    model = operator_from_table(profile.operator_model)
    assert isinstance(model, RecordedForce) and model.force(0.2, 0.0, 0.0) == 2.0
    missing = BASE.replace('model = "constant"\nlevel = 2.0', 'model = "csv"\npath = "gone.csv"')
    with pytest.raises(ParameterError) as caught:
        load_profile(write(tmp_path, missing, "q.toml"))
    assert caught.value.name == "operator_model.path"


def test_toml_syntax_and_unknown_name(tmp_path):
    with pytest.raises(ParameterError) as caught:
        load_profile(write(tmp_path, BASE + "\n[device\n"))
    assert caught.value.name == "(TOML syntax)"
    with pytest.raises(ParameterError) as caught:
        load_profile("no-such-profile")
    assert "cia402-handle" in caught.value.allowed


# ---------------------------------------------------------------- CLI functions

def ns(**kw) -> argparse.Namespace:
    return argparse.Namespace(**{"json": False, "profile": DEFAULT_PROFILE} | kw)


def test_cli_list(capsys):
    assert cmd_list(ns(json=True)) == 0
    rows = json.loads(capsys.readouterr().out)
    assert {r["name"] for r in rows} == set(SHIPPED) | {"gantry-3d"} and all(r["status"] == "ok" for r in rows)
    (gantry,) = [r for r in rows if r["name"] == "gantry-3d"]  # the multi-axis kind listed beside the one-axis
    assert gantry["axes"] == ["x", "y", "z"] and gantry["objects"] == 3 and gantry["worst_margin"] > 0


def test_cli_show(capsys):
    assert cmd_show(ns(profile="multi-object", json=True)) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["profile"]["name"] == "multi-object" and shown["gate_decision"]["accepted"]
    assert cmd_show(ns()) == 0 and "cia402-handle" in capsys.readouterr().out


def test_cli_check_matches_check_report(capsys):
    assert cmd_check(ns(profile="stiff-wall", json=True)) == 0
    out = json.loads(capsys.readouterr().out)
    (wall,) = out["walls"]
    expected = check_loop(WallLoop(1.0, 20.0, 1e-3, 16500.0, 7.0, 1, "average")).to_dict()
    assert wall["report"]["passive"] is expected["passive"] is True
    assert wall["report"]["margin"] == expected["margin"]
    assert cmd_check(ns(profile="seed-ideal")) == 0
    text = capsys.readouterr().out
    assert "verdict: passive" in text and "delay=0" in text


def test_cli_exit_codes(tmp_path, capsys):
    refused = write(tmp_path, SHIPPED["seed-ideal"].read_text().replace('"ideal"', '"cia402"'), "s.toml")
    assert cmd_check(ns(profile=str(refused))) == 1
    assert "verdict: NOT passive" in capsys.readouterr().out
    assert cmd_show(ns(profile=str(refused))) == 1  # shown all the same, the refusal one line on stderr
    shown = capsys.readouterr()
    assert "gate: REFUSES" in shown.out and shown.err.count("\n") == 1 and "margin -84.09" in shown.err
    beyond = write(tmp_path, (tmp_path / "s.toml").read_text().replace('layer = "off"', 'layer = "bound"\nbeyond_gate = true'),
                   "beyond.toml")
    assert cmd_show(ns(profile=str(beyond))) == 0  # it loads, and runs, beyond the gate: the view says so
    shown = capsys.readouterr()
    assert "gate: REFUSES (the profile runs beyond it under the bound layer" in shown.out and shown.err == ""
    invalid = write(tmp_path, BASE.replace("mass = 1.0", "mass = -1.0"), "bad.toml")
    for command in (cmd_show, cmd_check):
        assert command(ns(profile=str(invalid))) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "device.mass" in err and str(invalid) in err


def test_add_profiles_parser():
    parser = argparse.ArgumentParser()
    add_profiles_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["profiles", "check", "stiff-wall", "--json"])
    assert args.handler is cmd_check and args.profile == "stiff-wall" and args.json
    args = parser.parse_args(["profiles", "show"])
    assert args.handler is cmd_show and args.profile == DEFAULT_PROFILE
    assert parser.parse_args(["profiles", "list"]).handler is cmd_list


# --------------------------------------------------------------------------- the measured loop

IDENTIFIED = """
[identification]
date = "2026-11-30T22:50:00Z"
mass = 1.0
mass_stderr = 0.01
friction = 21.0
friction_stderr = 0.2
coulomb_friction = 0.3
coulomb_friction_stderr = 0.01
delay = 1.0
delay_stderr = 0.0
velocity = "average"
excitation_s = 20.0
residual_rms = 1e-7
"""


def test_the_velocity_model_is_required_and_named_with_its_choices(tmp_path):
    error = broken(tmp_path, 'velocity = "average"\n', "")
    assert error.name == "device.velocity" and "'average'" in error.allowed and "encoder difference" in error.allowed
    error = broken(tmp_path, 'velocity = "average"\n', 'velocity = "tacho"\n')
    assert error.name == "device.velocity" and "lowpass:SECONDS" in error.allowed
    error = broken(tmp_path, 'velocity = "average"\n', 'velocity = "window:0.002"\n')  # longer than T = 1 ms
    assert error.name == "device.velocity" and "(0, T]" in error.allowed


def test_the_profile_velocity_model_reaches_the_gate_and_the_simulated_drive(tmp_path):
    profile = load_profile(write(tmp_path, BASE.replace('velocity = "average"', 'velocity = "lowpass:0.0005"')))
    assert str(profile.device_loop().wall(0.0, 0.0).velocity) == "lowpass:0.0005"
    assert str(profile.sim_device_parameters()["velocity"]) == "lowpass:0.0005"


@pytest.mark.parametrize("timing, given, expected", [
    ("ideal", None, 0), ("cia402", None, 1), ("cia402", "1.25", 1.25), ("ideal", "0.3", 0.3), ("reception", "0.3", 0.3),
])
def test_the_loop_delay_is_real_and_defaults_to_the_timing(tmp_path, timing, given, expected):
    text = BASE.replace('timing = "cia402"', f'timing = "{timing}"' + ("" if given is None else f"\ndelay = {given}"))
    profile = read_profile(write(tmp_path, text))
    assert profile.loop.delay == expected and profile.device_loop().delay == expected
    if timing == "reception":
        assert profile.sim_device_parameters()["reception_delay"] == expected


def test_a_delay_below_the_timing_or_missing_for_reception_is_refused(tmp_path):
    error = broken(tmp_path, 'timing = "cia402"', 'timing = "cia402"\ndelay = 0.5')
    assert error.name == "loop.delay" and "[1, 1000]" in error.allowed and "cia402" in error.allowed
    error = broken(tmp_path, 'timing = "cia402"', 'timing = "reception"')
    assert error.name == "loop.delay" and error.value is None and "loop.delay is missing; allowed: " in str(error)
    error = broken(tmp_path, 'timing = "cia402"', 'timing = "ideal"\ndelay = nan')
    assert error.name == "loop.delay"


def test_the_hidden_truth_keys_go_to_the_simulated_drive_only(tmp_path):
    text = BASE.replace('velocity = "average"\n', 'velocity = "average"\ncoulomb_friction = 0.2\n'
                        'velocity_noise = 1000.0\nnoise_seed = 7\n')
    profile = load_profile(write(tmp_path, text))
    parameters = profile.sim_device_parameters()
    assert (parameters["coulomb_friction"], parameters["velocity_noise"], parameters["noise_seed"]) == (0.2, 1000.0, 7)
    # the noise never reaches the gate; the Coulomb friction does, with the encoder's resolution
    assert profile.device_loop() == dataclasses.replace(load_profile(write(tmp_path, BASE)).device_loop(),
                                                        quantisation=Quantisation(1e-7, 0.2, 1e-6))
    assert broken(tmp_path, 'velocity = "average"\n', 'velocity = "average"\nnoise_seed = -1\n').name == "device.noise_seed"


def test_a_stated_coulomb_friction_below_the_quantisation_condition_is_refused_by_the_gate(tmp_path, capsys):
    """The stiffest contact is wall a + slot c: K = 1500 N/m, B = 12 N s/m; with Delta = 1e-7 m and
    average velocity it needs f_c >= K Delta/2 + B Delta/T = 7.5e-5 + 1.2e-3 = 1.275e-3 N."""
    text = BASE.replace('velocity = "average"\n', 'velocity = "average"\ncoulomb_friction = 0.001\n')
    with pytest.raises(Refusal) as caught:
        load_profile(write(tmp_path, text))
    assert "quantisation" in str(caught.value) and "= 0.001275 N" in str(caught.value)
    enough = load_profile(write(tmp_path, text.replace("coulomb_friction = 0.001", "coulomb_friction = 0.0013")))
    decision = enough.gate().judge(enough.compiled_scene())
    assert decision.accepted and decision.wall_dicts()[0]["quantisation"]["holds"] is True
    assert load_profile(write(tmp_path, BASE)).device_loop().quantisation is None  # not stated: not judged
    assert cmd_check(ns(profile=str(write(tmp_path, text)))) == 1  # profiles check says why, wall by wall
    out = capsys.readouterr().out
    assert "verdict: NOT passive (the quantisation condition fails)" in out and "leak 2.75e-11 J per crossing" in out


def test_a_profile_as_pessimistic_as_its_identification_loads(tmp_path):
    text = BASE.replace("friction = 20.0", "friction = 20.4") + IDENTIFIED  # 21.0 - 3 * 0.2 = 20.4
    profile = load_profile(write(tmp_path, text))
    assert profile.identification is not None and profile.identification.lowest_credible_friction == pytest.approx(20.4)
    assert profile_to_dict(profile)["identification"]["velocity"] == "average"


@pytest.mark.parametrize("old, new, field, needle", [
    ('velocity = "average"\n', 'velocity = "point"\n', "device.velocity", "average"),
    ("friction = 20.0", "friction = 20.5", "device.friction", "at most 20.4"),
    ('timing = "cia402"', 'timing = "ideal"', "loop.delay", "at least 1"),
    ('velocity = "average"\n', 'velocity = "average"\ncoulomb_friction = 0.28\n', "device.coulomb_friction",
     "at most 0.27"),  # 0.3 - 3 * 0.01
])
def test_a_profile_more_optimistic_than_its_identification_is_refused(tmp_path, old, new, field, needle):
    path = write(tmp_path, BASE.replace(old, new, 1) + IDENTIFIED)
    with pytest.raises(ParameterError) as caught:
        load_profile(path)
    assert caught.value.name == field and needle in caught.value.allowed and "2026-11-30" in caught.value.allowed
