"""The pytest plugin (:mod:`haptic_bus.testing`) in this tree: its fixtures, as a user's test uses them.

A teardown check runs in a pytest of its own (a subprocess with ``-p haptic_bus.testing``, as
where the package is importable but not installed); the other tests use the fixtures directly
(this suite loads the plugin in pyproject.toml's ``addopts``).  The README's example runs once,
from a fresh installation, entry point and all: ``tests/test_plugin_fresh_venv.py``.
"""

from __future__ import annotations

import math
import os
import pathlib
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from drives.bus_config import resolve_bus_config
from haptic_bus.errors import ParameterError
from haptic_bus.testing.buses import vcan0_exists
from tests.plugin_readme import REPO

INNER_PYTEST_WAIT = 900.0  # s of wall clock: a pytest of its own and a controller run (with the README's example, which
# ran here too then, 26 s idle and about 163 s beside four CPU-bound processes at a load average of 11)

# Left running on purpose by the first test; the second finds them stopped by the fixtures' teardown.
TEARDOWN_CHECK = '''
import json
import pathlib

LEFT = {}


def test_leaves_a_drive_in_another_process_and_a_run_going(haptic_sim, haptic_controller):
    drive = haptic_sim("cia402-handle", interface="udp_multicast")
    run = haptic_controller("cia402-handle", drive, duration=600.0)  # 10 minutes of virtual time
    run.wait_cycling()
    assert run.running
    LEFT.update(drive=drive, run=run)
    pathlib.Path("sim.pid").write_text(str(drive.process.process.pid))


def test_the_teardown_stopped_the_run_then_the_drive(recorded_run):
    run, drive = LEFT["run"], LEFT["drive"]
    assert not run.running and run.result.exit_reason == "stopped"
    assert drive.process.process.returncode == 0  # SIGTERM, a clean exit
    recorded = recorded_run(run.folder)
    assert recorded.exit_reason == "stopped"
    assert recorded.record["time_s"].size == recorded.summary["cycles"] > 0
'''


@pytest.mark.slow
def test_the_teardown_passes_in_a_pytest_of_its_own(tmp_path: pathlib.Path) -> None:
    (tmp_path / "test_teardown.py").write_text(TEARDOWN_CHECK)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
    done = subprocess.run([sys.executable, "-m", "pytest", "-p", "haptic_bus.testing", "-p", "no:cacheprovider", "-q",
                           "test_teardown.py"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=INNER_PYTEST_WAIT)
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
    assert "2 passed" in done.stdout, done.stdout[-2000:]
    pid = int((tmp_path / "sim.pid").read_text())
    with pytest.raises(ProcessLookupError):  # stopped and reaped, not left behind as an orphan
        os.kill(pid, 0)


def _free_motion_velocity(push: float, coulomb: float, mass: float, friction: float, t: float) -> float:
    """Velocity (m/s) at ``t`` s of a handle (kg, N s/m) pushed from rest with ``push`` N against ``coulomb`` N."""
    return (push - coulomb) / friction * -math.expm1(-friction * t / mass)


def test_a_drive_in_another_process_runs_its_hidden_truth_not_the_profile(haptic_sim, haptic_controller) -> None:
    """The controller believes cia402-handle (b 20 N s/m, no Coulomb friction); the hardware has
    b = 30 N s/m and 0.15 N of Coulomb friction.  Free motion under a 0.6 N push shows the truth:
    at 0.12 s, 3.6 time constants in, the handle moves at 97 % of (0.6 - 0.15)/30 = 15 mm/s.  The
    drive's clock runs a few periods ahead of the record's (the enable walk's SYNC exchanges
    advance the plant, the hand already pushing): each ms moves that velocity by 0.08 %, so 2 %
    covers 24 ms (measured: +0.5 %).  The belief would say 27 mm/s."""
    push, coulomb, mass, friction, at = 0.6, 0.15, 1.0, 30.0, 0.12
    drive = haptic_sim("cia402-handle", interface="udp_multicast", friction=friction, coulomb_friction=coulomb,
                       operator={"model": "constant", "level": push})
    assert drive.process is not None and drive.sim is None
    assert resolve_bus_config(**drive.bus)["hop_limit"] == 0  # the frames stay on this machine
    run = haptic_controller("cia402-handle", drive, duration=0.3).wait()
    assert run.exit_reason == "completed", run.error
    assert run.record["energy_j"].min() >= 0.0
    k = int(np.argmin(np.abs(run.record["time_s"] - at)))
    assert run.record["time_s"][k] == pytest.approx(at, abs=1e-9)
    assert run.record["position_m"][k] < 0.003  # still in free motion: the wall is 3 mm ahead
    measured = run.record["velocity_m_per_s"][k]
    assert measured == pytest.approx(_free_motion_velocity(push, coulomb, mass, friction, at), rel=0.02)
    believed = _free_motion_velocity(push, 0.0, mass, 20.0, at)
    assert measured < 0.6 * believed


def test_an_in_process_drive_is_built_from_the_truth_file(haptic_sim) -> None:
    drive = haptic_sim("seed-ideal", interface="lockstep", mass=0.8, velocity_noise=3.0, noise_seed=7, timing="cia402")
    assert drive.process is None and drive.sim is not None and drive.truth is not None
    parameters = drive.sim.drive.parameters
    assert (parameters.mass, parameters.friction, parameters.velocity_noise, parameters.noise_seed) == (0.8, 0.1, 3.0, 7)
    assert drive.sim.drive.handle.operator.level == 1.0  # seed-ideal's own operator: a 1 N step
    assert drive.truth.name.startswith("seed-ideal-truth-") and "mass = 0.8" in drive.truth.read_text()


@pytest.mark.parametrize("call, message", [
    (dict(profile="cia402-handle", mass=-1.0), "device.mass = -1.0 is invalid; allowed: "),
    (dict(profile="cia402-handle", mas=1.0), "simulated drive: truth mas = 1.0 is invalid; allowed: keys of a "
                                             "profile's [device] table: mass, friction, "),
    (dict(profile="cia402-handle", operator={"model": "constant", "level": "x"}), "operator_model.level = 'x' is invalid"),
    (dict(profile="cia402-handle", interface="can0"), "simulated drive: interface = 'can0' is invalid; allowed: "
                                                      "virtual, lockstep, udp_multicast, socketcan"),
    (dict(mass=1.0), "simulated drive: profile is missing; allowed: a shipped profile name or a TOML path"),
], ids=["out-of-range", "unknown-key", "bad-operator", "bad-interface", "truth-without-profile"])
def test_a_bad_truth_is_one_line_naming_the_field(haptic_sim, call: dict, message: str) -> None:
    kwargs = dict(call)
    profile = kwargs.pop("profile", None)
    with pytest.raises(ParameterError) as refused:
        haptic_sim(profile, interface=kwargs.pop("interface", "udp_multicast"), **kwargs)
    assert message in str(refused.value) and "\n" not in str(refused.value)


def test_socketcan_runs_on_vcan0_or_skips_saying_why(haptic_sim) -> None:
    if vcan0_exists():
        drive = haptic_sim(interface="socketcan")
        assert drive.process is not None and drive.bus["channel"] == "vcan0"
        return
    with pytest.raises(pytest.skip.Exception, match=r"SocketCAN vcan0 does not exist on this kernel \(create it with: "):
        haptic_sim(interface="socketcan")


def test_the_plugin_loads_only_the_standard_library_and_pytest() -> None:
    code = textwrap.dedent("""
        import sys
        before = set(sys.modules)
        import haptic_bus.testing
        heavy = sorted(m for m in ("numpy", "can", "canopen", "pymodbus", "scipy", "matplotlib", "sim_drive", "drives")
                       if m in sys.modules and m not in before)
        print(heavy)
    """)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


def test_the_plugin_knows_the_in_process_buses_the_runtime_knows() -> None:
    """The plugin spells :data:`drives.bus_config.IN_PROCESS_INTERFACES` itself (it loads no project
    package): a run there writes from a thread (haptic_bus.app.run_writer), a drive there is in the test's process."""
    from drives.bus_config import IN_PROCESS_INTERFACES
    from haptic_bus.testing.buses import IN_PROCESS

    assert IN_PROCESS == IN_PROCESS_INTERFACES


def test_wall_pacing_runs_against_a_drive_in_a_process_of_its_own(haptic_sim, haptic_controller) -> None:
    """The route the plugin's docs give for ``pacing="wall"`` (a drive in the test's process is refused at
    pre-flight: it shares the GIL): ``haptic_sim(interface="udp_multicast")``.  The run is wall-paced (its
    pre-flight in run.json) and completes its cycles, unless this shared machine cannot hold the period
    then, which pre-flight names (as test_modbus_axes' wall-paced run allows)."""
    drive = haptic_sim("cia402-handle", interface="udp_multicast")
    run = haptic_controller("cia402-handle", drive, duration=0.5, pacing="wall").wait(timeout=120)
    assert "preflight" in run.document, sorted(run.document)
    if run.exit_reason == "refused":
        assert run.error is not None and "this machine holds T >=" in run.error, run.error
    else:
        assert run.exit_reason == "completed", run.error
        assert run.summary["cycles"] == round(0.5 / 1e-3)  # cia402-handle's T = 1 ms, 0.5 s of wall clock


def test_a_modbus_drive_with_its_hidden_truth_settles_at_f_over_k(haptic_sim, haptic_controller) -> None:
    """The plugin's example over Modbus TCP on loopback: the same fixtures, ``interface="modbus"``."""
    drive = haptic_sim("cia402-handle", interface="modbus", unit_id=3, mass=1.4, friction=24.0,
                       operator={"model": "constant", "level": 3.0})
    assert drive.run_kwargs() == {"unit_id": 3} and drive.run_args() == ["--modbus", drive.bus, "--unit-id", "3"]
    run = haptic_controller("cia402-handle", drive, duration=1.0).wait()
    assert run.exit_reason == "completed" and run.document["link"]["unit_id"] == 3
    assert run.record["energy_j"].min() >= 0.0
    depth = run.record["position_m"][-100:].mean() - 0.003  # the wall's surface is 3 mm ahead
    assert depth == pytest.approx(3.0 / 1500.0, rel=1e-3)  # F / K, whatever the mass and friction


@pytest.mark.parametrize(("interface", "servers"), [("lockstep", 1), ("modbus", 1), ("modbus", 3)])
def test_a_multi_axis_profile_runs_through_the_same_fixtures(haptic_sim, haptic_controller, interface: str,
                                                             servers: int) -> None:
    """gantry-3d's three simulated axes: on the lock-step CAN bus (node ids 5, 6, 7 from the
    profile), or over Modbus as units 1, 2, 3 of one server or of a server each; the controller
    seen cycling, then stopped; each axis' record read back."""
    drive = haptic_sim("gantry-3d", interface=interface, servers=servers)
    if interface == "modbus":
        assert drive.run_kwargs() == {"unit_ids": [1, 2, 3]} and len(set(drive.urls)) == servers
    else:
        assert drive.run_kwargs() == {} and drive.node_ids == (5, 6, 7)
    run = haptic_controller("gantry-3d", drive, duration=600.0)  # 10 minutes of virtual time: stopped before
    run.wait_cycling()
    recorded = run.stop()
    assert recorded.exit_reason == "stopped" and sorted(recorded.records) == ["x", "y", "z"]
    cycles = recorded.summary["cycles"]
    assert cycles > 0 and [recorded.records[axis]["time_s"].size for axis in "xyz"] == [cycles] * 3
    assert recorded.summary["least_energy"] >= 0.0


@pytest.mark.parametrize("call, message", [
    (dict(mass=2.0), "simulated drive: truth = ['mass'] is invalid; allowed: none for a multi-axis profile"),
    (dict(node_id=0), "simulated drive: node_id = 0 is invalid; allowed: none for a multi-axis profile (its [[axes]]"),
    (dict(unit_id=2, interface="modbus"), "simulated drive: unit_id = 2 is invalid; allowed: none for a multi-axis"),
    (dict(servers=0, interface="modbus"), "simulated drive: servers = 0 is invalid; allowed: 1, or one Modbus server "
                                          "per axis (3) with interface='modbus'"),
    (dict(servers=3), "simulated drive: servers = 3 is invalid"),  # servers are Modbus's
], ids=["truth", "node-id", "unit-id", "no-server", "servers-on-can"])
def test_a_multi_axis_profile_refuses_what_it_states_itself(haptic_sim, call: dict, message: str) -> None:
    """What the profile states (each axis' ids, truth and hand) is not given again: one line naming the
    argument (a node_id was ignored, and servers=0 was called '--modbus = 0'), before any bus is opened."""
    with pytest.raises(ParameterError) as refused:
        haptic_sim("gantry-3d", **call)
    assert message in str(refused.value) and "\n" not in str(refused.value)
