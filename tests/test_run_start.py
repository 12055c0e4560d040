"""Issue 11, safe start: ``haptic-bus run`` reads the handle's position before it enables the
drive, and a start inside an object is refused or ramped in (every scaled wall proven passive).

The real command line runs in this process against the simulated drive on a real link: a
CANopen slave on python-can's ``virtual`` bus, or a Modbus TCP server on 127.0.0.1.  The
simulated handle starts at x = 0; the profile's end-stop is moved to x = -5 mm (solid for
x > -5 mm), so the run starts 5 mm inside it: at rest the wall would push with
K d = 1500 N/m * 5 mm = 7.5 N.
"""

from __future__ import annotations

import dataclasses
import math
import pathlib

import numpy as np
import pytest

from haptic_bus.app.profiles import StartPolicy, load_profile
from haptic_bus.app.runner import RunOptions, run_canopen
from haptic_bus.control.record import COLUMNS
from haptic_bus.control.scene import Wall
from haptic_bus.errors import ParameterError
from tests.run_rig import (
    CliResult,
    DriveUnderTest,
    events_of,
    profile_variant,
    read_record,
    read_run,
    run_cli,
    simulated_drive,
)

K, B, DEPTH = 1500.0, 10.0, 0.005  # cia402-handle's end-stop (N/m, N s/m) and how deep the run starts in it (m)
SURFACE = -DEPTH  # m
PERIOD = 1e-3  # s
RAMP_TIME = 0.2  # s: 200 cycles
REFUSAL = ("handle is 5.0 mm inside end-stop (at rest it would feel 7.5 N); "
           "move it out or use --start-in-contact ramp")


def inside(folder: pathlib.Path, start: str = "") -> pathlib.Path:
    """cia402-handle with its end-stop 5 mm behind the handle's start, plus a ``[start]`` table."""
    return profile_variant(folder, "cia402-handle", "inside", {"position = 0.003 ": f"position = {SURFACE!r} "}, start)


def run_inside(folder: pathlib.Path, capsys: pytest.CaptureFixture[str], transport: str, start: str,
               *options: str) -> tuple[CliResult, DriveUnderTest, pathlib.Path]:
    """``haptic-bus run OPTIONS`` in virtual time of :func:`inside` (with ``start``) against the
    simulated drive on ``transport``: what the command did, the drive, the run's folder."""
    profile = inside(folder, start)
    out = folder / "run"
    with simulated_drive(transport, profile) as drive:
        result = run_cli(capsys, "run", str(profile), *drive.args, *options, "--virtual-time", "--no-plots", "--out",
                         str(out))
    return result, drive, out


@pytest.mark.parametrize("transport, start, option", [
    ("canopen", "", []),  # the default policy
    ("modbus", '[start]\nin_contact = "ramp"\n', ["--start-in-contact", "refuse"]),  # the option wins over the profile
])
def test_a_start_inside_an_object_is_refused_and_the_drive_never_enabled(
        transport: str, start: str, option: list[str], tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    result, drive, out = run_inside(tmp_path, capsys, transport, start, *option, "--duration", "1")
    assert result.code == 1, result.err
    assert result.err_lines == [f"haptic-bus run: refused: {REFUSAL}"]
    assert not drive.was_enabled and drive.drive.state.value == "SWITCH ON DISABLED", drive.states
    assert drive.drive.sync_count <= 1 and drive.drive.target_torque == 0  # no cycle ran (Modbus counts its SYNC 0)
    document = read_run(out)  # the folder was made before the bus was touched, and keeps why the run ended
    assert document["exit_reason"] == "refused" and document["error"] == REFUSAL
    assert "summary" not in document and not (out / "record.csv").exists()  # nothing cycled
    logged = [str(out / "bus.asc")] if transport == "canopen" else []  # the bus log: commissioning's frames
    assert "ended: refused; wrote " + ", ".join([*logged, str(out / "run.json")]) in result.out


@pytest.mark.parametrize("transport, start, option", [
    ("canopen", f"[start]\nramp_time = {RAMP_TIME}\n", ["--start-in-contact", "ramp"]),  # the option
    ("modbus", f'[start]\nin_contact = "ramp"\nramp_time = {RAMP_TIME}\n', []),  # the profile
])
def test_the_start_ramp_scales_the_scene_from_0_to_1_and_is_no_observer_alarm(
        transport: str, start: str, option: list[str], tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    result, drive, out = run_inside(tmp_path, capsys, transport, start, *option, "--duration", "0.5", "-q")
    assert result.code == 0, result.err
    assert drive.was_enabled and drive.states[-1].value != "FAULT"
    header, record = read_record(out)
    assert tuple(header) == COLUMNS and record["time_s"].size == 500
    # scale: (k + 1)/N for the first N = ramp_time/T cycles, then 1.  Exact: the record is written
    # with repr, and the controller computes the same quotient.
    n = round(RAMP_TIME / PERIOD)
    expected = np.minimum(1.0, (np.arange(500) + 1.0) / n)
    np.testing.assert_array_equal(record["scale"], expected)
    assert record["scale"][n - 2] < 1.0 == record["scale"][n - 1]
    # force = scale * the full scene's K (x - surface) + B v, inside the wall (the handle never
    # leaves it here).  1e-9 N: the two evaluations differ by the rounding of ~10 N terms
    # (1e-15 N); a torque count at the drive is 16 mN.
    x, v = record["position_m"], record["velocity_m_per_s"]
    assert np.all(x > SURFACE)
    full = K * (x - SURFACE) + B * v
    np.testing.assert_allclose(record["force_n"], record["scale"] * full, rtol=0, atol=1e-9)
    assert abs(record["force_n"][0]) < 7.5 / n * 1.1  # the first cycle pushes 1/N of the 7.5 N, no step
    # the observer starts from the energy the wall holds at the start, K d^2 / 2 = 18.75 mJ
    energy = record["energy_j"]
    assert energy[0] == pytest.approx(0.5 * K * DEPTH**2, rel=1e-12)
    document = read_run(out)
    assert events_of(document, "alarm") == [] and document["summary"]["observer_active_cycles"] == 0
    assert document["start"] == {"position_m": 0.0, "ramp_time_s": RAMP_TIME}
    limit = document["settings"]["supervisor"]["observer_limit"]
    # ... and had it started from zero, this start would have been an alarm: the wall gave back more than 1 mJ
    assert float(energy.min()) - energy[0] < -limit


def test_without_a_passivity_layer_the_start_ramp_is_refused_and_the_drive_never_enabled(
        tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    # each scaled wall is proven passive, but a scale rising under the handle is a time-varying wall:
    # the layer's energy bound holds it, or the observer's stop; with neither it could give energy
    start = (f'[start]\nin_contact = "ramp"\nramp_time = {RAMP_TIME}\n\n[passivity]\nlayer = "off"\n\n'
             '[supervisor]\non_observer = "warn"\n')
    result, drive, out = run_inside(tmp_path, capsys, "canopen", start, "--duration", "0.5")
    assert result.code == 1, result.err
    assert result.err_lines == [
        "haptic-bus run: refused: handle is 5.0 mm inside end-stop (at rest it would feel 7.5 N); and the start ramp "
        'is refused with [passivity] layer = "off" and [supervisor] on_observer = "warn": a wall whose force rises '
        "under the handle is time-varying, which the gate's verdict on each scaled wall does not cover; the passivity "
        "layer, or the observer stopping the run, bounds the energy it can give"]
    assert not drive.was_enabled and drive.drive.target_torque == 0
    assert read_run(out)["exit_reason"] == "refused"


ACTIVE_WALL = Wall("end-stop", SURFACE, -1, 40_000.0, B)  # largest passive K at B = 10 is 16 911 N/m here


@pytest.mark.parametrize("surface, policy, reason", [
    (SURFACE, "ramp", "handle is 5.0 mm inside end-stop (at rest it would feel 200 N); and the start ramp is refused: "
                      "end-stop scaled by s is passive only for s in [0, 0."),  # in contact: the ramp's proof fails first
    (0.003, "refuse", "passivity gate refused the change: end-stop (K = 40000 N/m, B = 10 N s/m) is unstable with "),
], ids=["in-contact-ramp", "no-contact"])
def test_the_api_never_enables_the_drive_for_a_scene_the_gate_has_not_proven(
        surface: float, policy: str, reason: str, tmp_path: pathlib.Path) -> None:
    """A Profile object changed in code (dataclasses.replace) skips the loader's gate: the run
    itself proves the start ramp, and admits the scene, before it enables the drive."""
    path = inside(tmp_path)
    profile = dataclasses.replace(load_profile(path), scene=(dataclasses.replace(ACTIVE_WALL, position=surface),),
                                  start=StartPolicy(policy, RAMP_TIME))
    options = RunOptions(duration=0.5, pacing="virtual", out_dir=tmp_path / "run", live=False)
    with simulated_drive("canopen", path) as drive:
        result = run_canopen(profile, drive.bus, 5, options)
    assert not drive.was_enabled, drive.states
    assert result.exit_reason == "refused" and result.error is not None and result.error.startswith(reason), result.error
    document = read_run(tmp_path / "run")
    assert document["exit_reason"] == "refused" and document["error"] == result.error


def test_a_ramp_time_outside_its_range_is_refused_at_load(tmp_path: pathlib.Path) -> None:
    for bad in ("0.0", "-1.0", "nan", "inf"):
        with pytest.raises(ParameterError, match=r"start\.ramp_time"):
            load_profile(inside(tmp_path, f'[start]\nin_contact = "ramp"\nramp_time = {bad}\n'))
    assert math.isclose(load_profile(inside(tmp_path, "[start]\nramp_time = 2.5\n")).start.ramp_time, 2.5)


def test_a_handle_moved_into_a_wall_during_pre_flight_is_refused_before_enabling(
        tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Real time: the start is judged (outside, at 0 m) before pre-flight; a hand then moves the
    unpowered handle 7 mm into the end-stop (surface at 3 mm) during pre-flight's cycles.  The start
    is judged again right before enabling: refused, nothing enabled."""
    import threading
    import time

    # the profile's push waits for the torque: only the mover moves the handle
    with simulated_drive("canopen", "cia402-handle", hand_needs_power=True) as drive:

        def move_during_preflight() -> None:
            deadline = time.monotonic() + 30.0
            while drive.drive.sync_count < 100 and time.monotonic() < deadline:
                time.sleep(0.001)
            drive.drive.handle.position = 0.010

        mover = threading.Thread(target=move_during_preflight, daemon=True)
        mover.start()
        result = run_cli(capsys, "run", "cia402-handle", *drive.args, "--duration", "1", "-q", "--no-plots",
                         "--out", str(tmp_path / "run"))
        mover.join(35.0)
    if "this machine holds T >=" in result.err or "watchdog" in result.err:
        pytest.skip(f"this machine cannot hold the loop now, and the run said so at pre-flight: {result.err.strip()}")
    assert result.code == 1, result.err
    assert result.err_lines == ["haptic-bus run: refused: handle is 7.0 mm inside end-stop (at rest it would feel "
                                "10.5 N): it moved there during pre-flight, after the start was judged outside every "
                                "object; move it out or use --start-in-contact ramp"]
    assert not drive.was_enabled
