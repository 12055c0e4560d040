"""The two-mass device on the command line, in profiles and in the gate (issue 27, item 4).

``haptic-bus check --transmission STIFFNESS:DAMPING:MOTOR_MASS`` and a profile's
``[device.transmission]``: the verdict names the two-mass model; invalid values exit 2 with one
line naming the range.  The numbers: the cia402-handle's wall (K 1500 N/m, B 10 N s/m, D = 1,
average) on its 1 kg handle with a 20 000 N/m, 2 N s/m belt and a 0.3 kg motor (46.85 Hz) passes
with margin +22.03 N s/m at Nyquist (the rigid handle: +11.09 N s/m); passive K at this B up to
6 954 N/m, where the rigid handle passes up to 16 911 N/m.
"""

from __future__ import annotations

import json
import pathlib

import pytest

from haptic_bus.analysis.transmission import Transmission
from haptic_bus.app.cli import main
from haptic_bus.app.profiles import read_profile
from haptic_bus.errors import ParameterError

PROFILES = pathlib.Path(__file__).resolve().parents[1] / "profiles"
HANDLE = ["check", "--mass", "1", "--friction", "20", "--period", "0.001", "--delay", "1", "--velocity", "average"]


def test_check_judges_the_two_mass_device_and_says_so(capsys) -> None:
    status = main([*HANDLE, "--stiffness", "1500", "--damping", "10", "--transmission", "20000:2:0.3"])
    out = capsys.readouterr().out
    assert status == 0
    assert "model: two-mass" in out and "verdict: passive  (exact, two-mass" in out
    assert "free resonance 46.85 Hz" in out and "margin +22.0275 N s/m" in out
    assert "rigid criterion on the handle alone (m = 1 kg, no transmission): passive, margin +11.0944" in out


def test_check_json_and_a_wall_the_belt_makes_active(capsys) -> None:
    """K = 8000 N/m passes on the rigid handle (up to 16 911 at B = 10) but not behind the belt (up to 6 954)."""
    status = main([*HANDLE, "--stiffness", "8000", "--damping", "10", "--transmission", "20000:2:0.3", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert status == 1
    assert report["model"].startswith("two-mass") and report["criterion"].startswith("exact, two-mass")
    assert report["max_stiffness"] == pytest.approx(6953.74, rel=1e-5)
    assert report["rigid"]["handle_alone"]["passive"] is True
    assert report["transmission"] == pytest.approx({"stiffness": 20000.0, "damping": 2.0, "motor_mass": 0.3,
                                                    "resonance_hz": 46.85}, rel=1e-3)


INVALID = [("0:2:0.3", "transmission stiffness = 0.0 is invalid; allowed: a finite real in (0, 1e+12] N/m"),
           ("2e4:2", "STIFFNESS:DAMPING:MOTOR_MASS (N/m, N s/m, kg)"),
           ("2e4:2:-1", "transmission motor_mass = -1.0 is invalid; allowed: a finite real in [1e-09, 1e+09] kg")]


@pytest.mark.parametrize(("value", "named"), INVALID)
def test_check_refuses_an_invalid_transmission_in_one_line(capsys, value: str, named: str) -> None:
    status = main([*HANDLE, "--stiffness", "1500", "--damping", "10", "--transmission", value])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1 and named in err


def test_check_refuses_a_transmission_with_a_position_resolution_in_one_line(capsys) -> None:
    """The quantisation condition is derived for a rigid handle: asked together, exit 2 before judging."""
    status = main([*HANDLE, "--stiffness", "1500", "--damping", "10", "--transmission", "2e4:2:0.3",
                   "--position-resolution", "1e-6"])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and "--position-resolution" in err and "rigid handle" in err


def _belt_profile(tmp_path: pathlib.Path, table: str) -> pathlib.Path:
    text = (PROFILES / "cia402-handle.toml").read_text()
    marker = "\n[loop]"
    path = tmp_path / "belt.toml"
    path.write_text(text.replace(marker, f"\n[device.transmission]\n{table}\n{marker}", 1))
    return path


def test_a_profile_with_a_transmission_is_gated_as_a_two_mass_device(tmp_path: pathlib.Path) -> None:
    profile = read_profile(_belt_profile(tmp_path, "stiffness = 20000.0\ndamping = 2.0\nmotor_mass = 0.3"))
    assert profile.device.transmission == Transmission(20000.0, 2.0, 0.3)
    decision = profile.gate().judge(profile.compiled_scene())
    [wall] = decision.walls
    assert decision.accepted and wall.verdict.criterion.startswith("exact, two-mass")
    assert wall.verdict.margin == pytest.approx(22.0275, abs=1e-3)
    assert "transmission stiffness 20000 N/m" in profile.device_loop().describe()
    ramp = profile.gate().proves_ramp(profile.compiled_scene())  # sampled on a two-mass device
    assert ramp.proven and ramp.walls[0][1].intervals == ((0.0, 1.0),)


def test_a_misspelt_transmission_key_is_refused(tmp_path: pathlib.Path) -> None:
    with pytest.raises(ParameterError) as caught:
        read_profile(_belt_profile(tmp_path, "stifness = 20000.0\ndamping = 2.0\nmotor_mass = 0.3"))
    assert caught.value.name.endswith("device.transmission.stifness")


def test_a_lightly_damped_belt_in_band_makes_the_gate_refuse_the_shipped_wall(tmp_path: pathlib.Path, capsys) -> None:
    """1e5 N/m, 6.9 N s/m (zeta 0.05) and 50 g at the motor: 231 Hz, in band; the cia402-handle's wall, passive
    on the rigid handle, is unstable here, and the refusal names the two-mass criterion and its passive K
    (none: at B = 10 N s/m even K = 0, the damper alone at the motor, is active behind this belt)."""
    path = _belt_profile(tmp_path, "stiffness = 100000.0\ndamping = 6.9\nmotor_mass = 0.05")
    profile = read_profile(path)
    decision = profile.gate().judge(profile.compiled_scene())
    assert not decision.accepted and decision.walls[0].verdict.outcome == "unstable"
    assert "transmission stiffness 100000 N/m" in decision.reasons[0]
    assert decision.reasons[0].endswith("two-mass criterion; passive K at this B from 0: none")  # B = 10 alone is active
    assert main(["profiles", "check", str(path), "--json"]) == 1
    [wall] = json.loads(capsys.readouterr().out)["walls"]
    assert wall["report"]["model"].startswith("two-mass") and wall["report"]["rigid"]["handle_alone"]["passive"]
