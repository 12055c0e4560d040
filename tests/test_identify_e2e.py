"""``haptic-bus identify`` over a real bus: the CANopen master against the simulated drive, whose
truth (another profile) the controller does not know.

In one process in virtual time: on python-can's virtual bus (the command line's refusal) and on the
lock-step bus (the run; the data that cannot support the estimate; the command line against a drive
built from a hidden profile file: the estimate, the profile it writes); and in
two processes on udp_multicast, Ctrl-C of ``haptic-bus identify`` against the drive ``haptic-bus sim
--profile HIDDEN`` builds.  The tolerances are those of ``tests/test_identify_fit.py`` (the issue's
bounds and 4 standard errors of the fit).
"""

from __future__ import annotations

import json
import signal
import subprocess
import time
import tomllib
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from drives.cia402 import State
from haptic_bus.app.cli import main
from haptic_bus.app.identify_cli import format_identification
from haptic_bus.app.identify_run import IdentifyOptions, identify_canopen
from haptic_bus.app.profiles import load_profile, read_profile
from haptic_bus.errors import Refusal
from sim_drive.canopen.slave import CanopenSimDrive
from sim_drive.operator import HandModel, NoOperator, OperatorModel
from sim_drive.parameters import DeviceParameters
from sim_drive.profile import read_simulated_device
from tests.cli_process import cli_process, reaped
from tests.guess_profile import guess_profile
from tests.run_rig import run_cli, simulated_drive

NODE = 5
SIGMAS = 4.0
START_WAIT = 30.0  # s: a process imports numpy/scipy/canopen before it answers
RUN_WAIT = 120.0  # s: the longest an interrupted identify process is waited for (it disables the drive first)
HIDDEN = dict(mass=0.37, friction=2.9, coulomb_friction=0.2, velocity_noise=1000.0, noise_seed=21)
EXCITATION = 2.0  # s over the bus (was 10 s, then 5 s): measured (seed 21) at 5, 2 and 1 s: m within +0.03 %, -0.04 %
# and -0.004 %, b within -0.22 %, -0.17 % and +0.30 % (the 3 % and 5 % asserted are 66 and 13 standard errors at 1 s),
# m, b and Fc all within 1.42, 0.95 and 0.81 standard errors at 5, 2, 1 s (4 asserted), D = 1 and "average" found; 2 s keeps
# twice the samples of the least the command accepts (1 s) for a loaded machine's stale cycles, which the fit leaves
# out: 1.6 s of CPU where 5 s took 2.0 s; the fit's statistics at the command's default 20 s are
# tests/test_identify_fit.py's

def controller_profile(folder: Path, force_limit: float = 5.0) -> Path:
    """The controller's profile in ``folder``: what it believes, not the drive's truth."""
    return guess_profile(folder / "controller.toml", comment="What the controller believes: not the drive's truth.",
                         name="identify-test", task="measure the handle before trusting the gate",
                         description="a 0.5 kg guess with a datasheet b; the drive is said to report v(kT)",
                         mass=0.5, friction=1.0, velocity="point", rated_torque=0.2, period=0.001,
                         force_limit=force_limit)


@contextmanager
def hidden_drive(timing: str, operator: OperatorModel | None = None, interface: str = "virtual",
                 **truth: object) -> Iterator[tuple[CanopenSimDrive, str]]:
    """The simulated drive with the hidden truth on a fresh channel of ``interface`` (python-can's
    ``virtual`` or the in-process ``lockstep`` bus), node NODE."""
    channel = f"identify-{uuid.uuid4().hex[:12]}"
    parameters = DeviceParameters(**(HIDDEN | truth))  # type: ignore[arg-type]
    sim = CanopenSimDrive({"interface": interface, "channel": channel}, NODE, timing=timing, parameters=parameters,
                          operator=operator).start()
    try:
        yield sim, channel
    finally:
        sim.stop()


def within(estimate: dict, truth: float) -> bool:
    """The truth lies within SIGMAS standard errors of a JSON estimate."""
    return abs(estimate["value"] - truth) <= SIGMAS * estimate["stderr"]


def test_identify_over_the_lock_step_bus_in_virtual_time(tmp_path: Path) -> None:
    """The hidden drive reports the encoder difference (average) where the controller says point:
    m, b, Fc and the delay found, the model contradicted, the drive disabled at the end.  On the
    lock-step bus: the same cycles as python-can's virtual bus, without its thread per node (identify
    on that bus, the threaded delivery's own case: ``tests/test_axes_sim.py``)."""
    profile = read_profile(controller_profile(tmp_path))
    with hidden_drive("cia402", interface="lockstep", velocity="average") as (sim, channel):
        outcome = identify_canopen(profile, {"interface": "lockstep", "channel": channel}, NODE,
                                   IdentifyOptions(duration=EXCITATION, pacing="virtual"))
        state = sim.drive.state
    found = outcome.identification
    assert outcome.exit_reason == "completed" and outcome.exit_status == 0, outcome.error
    assert found is not None and found.fit is not None and found.velocity is not None
    fit = found.fit
    assert abs(fit.mass.value / 0.37 - 1) < 0.03 and abs(fit.mass.value - 0.37) <= SIGMAS * fit.mass.stderr
    assert abs(fit.friction.value / 2.9 - 1) < 0.05 and abs(fit.friction.value - 2.9) <= SIGMAS * fit.friction.stderr
    assert abs(fit.coulomb.value - 0.2) <= SIGMAS * fit.coulomb.stderr
    assert fit.whole_delay == 1
    assert found.velocity.best == "average" and found.velocity.matches_declared is False
    assert found.record.excitation_seconds == pytest.approx(EXCITATION)
    assert state is State.SWITCH_ON_DISABLED
    report = format_identification(found, "identify-test")
    for row in ("mass m", "viscous friction b", "Coulomb friction Fc", "loop delay D", "whole samples: 1",
                "velocity (0x606C): matches average", "declared point: CONTRADICTED", "verdict: supported"):
        assert row in report


def test_a_blocked_handle_is_refused_and_the_drive_left_disabled(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A stiff stop at the start: exit 1, the reason on stderr, no excitation, nothing written."""
    written = tmp_path / "written.toml"
    with hidden_drive("cia402", operator=HandModel(1e5, 50.0)) as (sim, channel):
        code = main(["identify", "--profile", str(controller_profile(tmp_path)), "--interface", "virtual", "--channel",
                     channel, "--node-id", str(NODE), "--virtual-time", "--write-profile", str(written)])
        state = sim.drive.state
    captured = capsys.readouterr()
    assert code == 1
    assert "refused: the handle is not free to move towards +x" in captured.err
    assert "REFUSED" in captured.out and not written.exists()
    assert state is State.SWITCH_ON_DISABLED


def test_data_that_cannot_support_the_estimate_exit_1_and_write_nothing(tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """A 0.3 N force limit against 0.2 N of Coulomb friction: the handle is free, but it sticks.

    On the lock-step bus (the same cycles as python-can's virtual bus, 1.0 s of CPU where that bus
    took 2.8 s), with 1 s of excitation, the least the command accepts: the probe (5.9 s of the
    handle's time at this force limit) is the same whatever the duration, and the findings asserted
    are the same at 1 s as at 5 s (measured: sticking and noise, both "cannot support"; 4.9 s of
    CPU at 5 s on the virtual bus, 1.0 s now)."""
    written = tmp_path / "written.toml"
    with hidden_drive("cia402", interface="lockstep") as (_, channel):
        code = main(["identify", "--profile", str(controller_profile(tmp_path, force_limit=0.3)), "--interface", "lockstep",
                     "--channel", channel, "--node-id", str(NODE), "--virtual-time", "--duration", "1", "--json",
                     "--write-profile", str(written)])
    document = json.loads(capsys.readouterr().out)
    assert code == 1 and not written.exists()
    assert document["identification"]["supported"] is False
    assert any(f["topic"] == "sticking" and f["severity"] == "cannot support" for f in document["identification"]["findings"])


@pytest.mark.parametrize("arguments", [
    [],  # no --node-id, no --modbus
    ["--node-id", "5", "--unit-id", "2"],
    ["--node-id", "5", "--modbus", "tcp://127.0.0.1:1502"],
    ["--node-id", "5", "--controller-node-id", "5"],
    ["--node-id", "5", "--travel", "1e-6"],  # the probe needs 20 increments of 0.1 um: more than half of it
    ["--node-id", "5", "--duration", "0.5"],
    ["--node-id", "5", "--write-profile", "/nonexistent-folder/x.toml"],
    ["--node-id", "5", "--write-profile", "{profile}"],
    ["--node-id", "5", "--write-profile", "{existing}"],  # an identified profile is kept: --force replaces it
])
def test_invalid_input_is_refused_before_the_bus_is_touched(arguments: list[str], tmp_path: Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """Exit 2 with one line on stderr; the interface does not exist, so touching the bus would be exit 1."""
    profile = controller_profile(tmp_path)
    existing = tmp_path / "identified.toml"
    existing.write_text("# an earlier identify's\n")
    arguments = [a.replace("{profile}", str(profile)).replace("{existing}", str(existing)) for a in arguments]
    try:
        code: object = main(["identify", "--profile", str(profile), "--interface", "no-such-interface", *arguments])
    except SystemExit as usage:  # argparse's own refusals end the parse
        code = usage.code
    err = capsys.readouterr().err
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "haptic-bus identify" in err
    assert existing.read_text() == "# an earlier identify's\n"  # untouched


@pytest.mark.parametrize(("command", "flag"), [(["identify", "--node-id", "5"], "--write-profile"),
                                              (["profiles", "new", "x"], "--out")], ids=["identify", "profiles-new"])
def test_a_file_to_write_is_refused_in_the_same_words_by_both_commands(command: list[str], flag: str, tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """``identify --write-profile`` said "--force replaces it" and "an existing, writable folder" where
    ``profiles new --out`` said "--force overwrites it" and "an existing folder this user can write" for the
    same check (break18): one check now (``haptic_bus.validation.new_file``), one wording."""
    existing, absent = tmp_path / "identified.toml", tmp_path / "no-folder" / "x.toml"
    existing.write_text("# an earlier identify's\n")
    identify = command[0] == "identify"  # its bus a name python-can lacks: a bus touched would be exit 1
    rest = ["--profile", str(controller_profile(tmp_path)), "--interface", "no-such-interface"] if identify else []
    for target, allowed in ((existing, "a file that does not exist yet (--force overwrites it)"),
                            (absent, "a file in an existing folder this user can write")):
        code = main([*command, *rest, flag, str(target)])
        said = f"haptic-bus {' '.join(command[:2] if command[0] == 'profiles' else command[:1])}: error: {flag} = " \
               f"'{target}' is invalid; allowed: {allowed}\n"
        assert (code, capsys.readouterr().err) == (2, said)
    assert existing.read_text() == "# an earlier identify's\n"


# --------------------------------------------------------------------------- a hidden profile; Ctrl-C of two processes

def _hidden_profile(folder: Path) -> Path:
    """The simulated drive's truth, which the controller is never given."""
    path = folder / "hidden.toml"
    path.write_text("""\
[device]
mass = 0.37
friction = 2.9
coulomb_friction = 0.2
velocity_noise = 1000
noise_seed = 22
velocity = "point"
velocity_per_count = 1e-6
position_per_count = 1e-7

[loop]
period = 0.001
timing = "cia402"
""")
    return path


def _identify_process(multicast: tuple[str, int], *arguments: str) -> subprocess.Popen[str]:
    group, port = multicast
    return cli_process("identify", "--interface", "udp_multicast", "--channel", group, "--bus-option", f"port={port}",
                       "--node-id", str(NODE), "--virtual-time", *arguments)


def test_identify_against_a_drive_with_a_hidden_profile_writes_the_profile(tmp_path: Path,
                                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """The command line against the simulated drive built from a profile file (as ``haptic-bus sim
    --profile HIDDEN`` builds it), in this process on the lock-step bus."""
    written = tmp_path / "identified.toml"
    with simulated_drive("canopen", _hidden_profile(tmp_path)) as drive:
        # 5 s: b's standard error ~0.2 %, far inside the 5 % bound
        result = run_cli(capsys, "identify", *drive.args, "--virtual-time", "--profile", str(controller_profile(tmp_path)),
                         "--duration", "5", "--json", "--write-profile", str(written))
    assert result.code == 0, result.err
    document = json.loads(result.out)
    fit = document["identification"]["fit"]
    assert abs(fit["mass"]["value"] / 0.37 - 1) < 0.03 and within(fit["mass"], 0.37)
    assert abs(fit["friction"]["value"] / 2.9 - 1) < 0.05 and within(fit["friction"], 2.9)
    assert within(fit["coulomb_friction"], 0.2) and fit["delay"]["whole"] == 1
    assert document["identification"]["run"]["excitation_s"] == pytest.approx(5.0)
    assert document["identification"]["velocity"]["best"] == "point"
    assert document["wrote"] == str(written)
    profile = load_profile(written)  # the loader accepts it: [device] and [loop] agree with [identification]
    identified = tomllib.loads(written.read_text())["identification"]
    assert profile.device.mass == pytest.approx(fit["mass"]["value"], rel=1e-5)
    assert profile.device.friction <= identified["friction"] - 3 * identified["friction_stderr"] < 2.9
    assert profile.loop.delay >= identified["delay"] + 3 * identified["delay_stderr"] >= 1.0
    assert str(profile.device.velocity) == identified["velocity"] == "point"
    assert "coulomb_friction" not in tomllib.loads(written.read_text())["device"]  # the truth stays the drive's
    assert "# What the controller believes" in written.read_text()  # the user's comments are kept
    assert drive.states[-2:] == [State.OPERATION_ENABLED, State.SWITCH_ON_DISABLED]  # disabled at the end, not faulted


def test_a_written_profile_whose_walls_the_measured_device_refuses_is_said_so(tmp_path: Path,
                                                                              capsys: pytest.CaptureFixture[str]) -> None:
    """stiff-wall's drive with half a sample of delay hidden: identify measures it and writes the profile
    (exit 0: the data support the estimate), whose hard stop the gate then refuses at the measured
    delay; one line on stderr says so, naming the wall, before the operator runs it."""
    written = tmp_path / "identified.toml"
    with simulated_drive("canopen", "stiff-wall") as drive:
        drive.drive.set_operator(NoOperator())  # identify needs the handle free
        drive.drive.reconfigure(extra_delay=0.5)
        result = run_cli(capsys, "identify", *drive.args, "--virtual-time", "--profile", "stiff-wall", "--duration", "5",
                         "--write-profile", str(written))
    assert result.code == 0 and f"wrote {written}" in result.out, result.err
    (line,) = result.err.splitlines()
    assert line.startswith(f"haptic-bus identify: {written} holds what was measured, and the gate refuses its walls")
    with pytest.raises(Refusal):
        load_profile(written)


@pytest.mark.slow  # SIGINT to a real command process is the point
def test_ctrl_c_disables_the_drive_and_exits_130(multicast: tuple[str, int], tmp_path: Path) -> None:
    """``haptic-bus identify`` a process of its own on udp_multicast, Ctrl-C'd in its probe or excitation;
    the drive (as ``haptic-bus sim --profile HIDDEN`` builds it) in this process on the same bus: the
    process that matters is the Ctrl-C'd one, a second interpreter for the drive would only import
    numpy, scipy and canopen again (0.7 s of CPU)."""
    group, port = multicast
    truth, operator = read_simulated_device(_hidden_profile(tmp_path)).one_axis()
    sim = CanopenSimDrive({"interface": "udp_multicast", "channel": group, "port": port}, NODE, timing=truth.timing,
                          parameters=truth.parameters, operator=operator, hand_needs_power=True)
    states: list[State] = []
    sim.drive.state_listeners.append(lambda old, new, number: states.append(new))
    sim.start()
    try:
        with reaped(_identify_process(multicast, "--profile", str(controller_profile(tmp_path)), "--duration", "600")) as run:
            deadline = time.monotonic() + START_WAIT
            while State.OPERATION_ENABLED not in states and run.poll() is None and time.monotonic() < deadline:
                time.sleep(0.02)
            assert State.OPERATION_ENABLED in states, run.communicate(timeout=RUN_WAIT)[1] if run.poll() is not None else states
            time.sleep(0.5)  # well into the probe or the excitation
            run.send_signal(signal.SIGINT)
            _, err = run.communicate(timeout=RUN_WAIT)
    finally:
        sim.stop()
    assert run.returncode == 130, err
    assert "interrupted" in err
    assert states[-2:] == [State.OPERATION_ENABLED, State.SWITCH_ON_DISABLED], states  # disabled by the master, not faulted
