"""``haptic-bus profiles new NAME [--from-drive ...]``: the commented profile it writes (the drive's
statement, first guesses, every other value asked with the loader's range), what ``profiles check``
then says is missing, that reading the drive writes nothing to it, and the refusals (one line, exit 2)."""

from __future__ import annotations

import math
import os
import stat
import time
import tomllib
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import can
import pytest
import tomlkit

from haptic_bus.app.cli import main
from haptic_bus.app.profile_template import ASKS, missing
from haptic_bus.app.profiles import read_profile
from sim_drive.canopen.slave import CanopenSimDrive
from sim_drive.modbus.server import ModbusSimServer
from sim_drive.parameters import DeviceParameters

NODE = 5
TRUTH = DeviceParameters()  # the simulated drive's default scaling: every factor stated by its standard objects
FILLED = {  # a value for every ask, as a user would give it
    "device.mass": 0.4, "device.friction": 2.0, "device.velocity": "point", "device.velocity_per_count": 1e-6,
    "device.position_per_count": 1e-7, "device.rated_torque": 0.2, "device.force_per_torque": 50.0,
    "device.max_torque_permille": 3000, "limits.force_limit": 5.0,
}
WALL = {"kind": "wall", "name": "end-stop", "position": 0.003, "normal": -1, "stiffness": 200.0, "damping": 1.5}


def fill(path: Path, values: dict[str, Any], wall: bool = True) -> None:
    """Give ``values`` (dotted keys) and a wall, keeping the file's comments (tomlkit)."""
    document = tomlkit.parse(path.read_text())
    for key, value in values.items():
        table, name = key.split(".")
        document[table][name] = value  # type: ignore[index]
    if wall:
        document["scene"]["objects"] = tomlkit.aot()  # type: ignore[index]
        document["scene"]["objects"].append(tomlkit.item(WALL))  # type: ignore[index]
    path.write_text(tomlkit.dumps(document))


def one_line(err: str) -> str:
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err


@pytest.fixture
def standard_drive() -> Iterator[tuple[list[str], can.BusABC]]:
    """The simulated drive with standard objects only, node 5 on a fresh virtual bus; yields the bus
    options of the command line and a second bus handle that hears every frame."""
    channel = f"profiles-new-{uuid.uuid4().hex[:10]}"
    sim = CanopenSimDrive({"interface": "virtual", "channel": channel}, NODE, od="standard").start()
    try:
        with can.Bus(interface="virtual", channel=channel) as sniffer:
            yield ["--interface", "virtual", "--channel", channel], sniffer
    finally:
        sim.stop()


def frames(bus: can.BusABC) -> list[can.Message]:
    heard = []
    while (message := bus.recv(0.05)) is not None:
        heard.append(message)
    return heard


def test_without_a_drive_every_value_is_asked_and_check_lists_them_all(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "new.toml"
    assert main(["profiles", "new", "axis-1", "--out", str(out)]) == 0
    text = out.read_text()
    assert [ask.key for ask in missing(tomllib.loads(text))] == [ask.key for ask in ASKS]
    for ask in ASKS[:-1]:  # each a commented line naming its unit and range
        assert f"# {ask.name} = ?" in text and ask.allowed.split(";")[0] in text, ask.key
    capsys.readouterr()
    assert main(["profiles", "check", str(out)]) == 2
    captured = capsys.readouterr()
    assert one_line(captured.err) == (f"haptic-bus profiles check: error: {out}: still missing "
                                      + ", ".join(ask.key for ask in ASKS) + "\n")
    assert captured.out.startswith(f"profile {out}: {len(ASKS)} values still missing:")
    assert "device.mass                  kg, a finite real in [1e-09, 1e+09]" in captured.out


def test_the_asks_are_exactly_what_the_loader_needs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "new.toml"
    assert main(["profiles", "new", "axis-1", "--out", str(out)]) == 0
    fill(out, FILLED)
    profile = read_profile(out)  # every ask given: the profile loads as written (defaults included)
    assert (profile.device.mass, profile.loop.period, profile.loop.timing, profile.loop.delay) == (0.4, 0.001, "cia402", 1)
    assert missing(tomllib.loads(out.read_text())) == []
    assert main(["profiles", "check", str(out)]) == 0 and "profile verdict: passive" in capsys.readouterr().out
    for key in FILLED:  # any one of them left out: check names exactly that one
        partial = tmp_path / f"without-{key}.toml"
        assert main(["profiles", "new", "axis-1", "--out", str(partial)]) == 0
        fill(partial, {k: v for k, v in FILLED.items() if k != key})
        assert [ask.key for ask in missing(tomllib.loads(partial.read_text()))] == [key]
        capsys.readouterr()
        assert main(["profiles", "check", str(partial)]) == 2
        assert one_line(capsys.readouterr().err).endswith(f"still missing {key}\n")


def test_from_a_canopen_drive_its_statement_and_no_write(
        standard_drive: tuple[list[str], can.BusABC], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bus, sniffer = standard_drive
    frames(sniffer)  # the boot-up
    out = tmp_path / "axis.toml"
    assert main(["profiles", "new", "axis", "--from-drive", *bus, "--node-id", str(NODE), "--out", str(out),
                 "--mass", "0.5", "--friction", "1", "--velocity", "average", "--force-limit", "5"]) == 0
    heard = frames(sniffer)
    said = capsys.readouterr().out
    assert said.startswith(f"wrote {out}: from the drive rated_torque, max_torque_permille, position_per_count, "
                           "force_per_torque, velocity_per_count; still to give: scene.objects")
    requests = [m for m in heard if m.arbitration_id == 0x600 + NODE]
    assert requests and all(m.data[0] == 0x40 for m in requests)  # SDO upload requests only: nothing written
    assert {m.arbitration_id for m in heard} <= {0x600 + NODE, 0x580 + NODE, 0x700 + NODE}  # no NMT, no SYNC, no PDO
    document = tomllib.loads(out.read_text())
    device = document["device"]
    assert (device["rated_torque"], device["max_torque_permille"]) == (TRUTH.rated_torque, TRUTH.max_torque_permille)
    assert (device["velocity_per_count"], device["position_per_count"]) == (TRUTH.velocity_per_count,
                                                                            TRUTH.position_per_count)
    assert math.isclose(device["force_per_torque"], TRUTH.force_per_torque, rel_tol=1e-12)  # through the feed constant
    assert (device["mass"], device["friction"], device["velocity"], document["limits"]["force_limit"]) == (
        0.5, 1.0, "average", 5.0)
    text = out.read_text()
    assert "# N m: stated by the drive, 0x6076 (200 mN m)" in text and "stated by the drive, 0x6072" in text
    assert "at most 30 N, what 0x6072 allows" in text
    assert [ask.key for ask in missing(document)] == ["scene.objects"]


def test_a_drive_whose_objects_state_no_length_gets_those_values_asked(tmp_path: Path) -> None:
    """A position_per_count that is no power of ten: the simulated drive's 0x60A8 says increments,
    so no object states a length (the note says so) and the template asks for the three factors."""
    channel = f"profiles-new-{uuid.uuid4().hex[:10]}"
    parameters = DeviceParameters(position_per_count=1.1984224905356573e-07, velocity_per_count=1.1984224905356573e-07)
    sim = CanopenSimDrive({"interface": "virtual", "channel": channel}, NODE, od="standard", parameters=parameters).start()
    try:
        out = tmp_path / "axis.toml"
        assert main(["profiles", "new", "axis", "--from-drive", "--interface", "virtual", "--channel", channel,
                     "--node-id", str(NODE), "--out", str(out)]) == 0
    finally:
        sim.stop()
    text = out.read_text()
    assert "# note: position_per_count, force_per_torque: the drive has 0x60A8 = " in text
    lacking = [ask.key for ask in missing(tomllib.loads(text))]
    assert {"device.position_per_count", "device.force_per_torque"} <= set(lacking)
    assert "device.rated_torque" not in lacking and "# force_limit = ?" in text


def test_from_a_modbus_drive(tmp_path: Path) -> None:
    out = tmp_path / "axis.toml"
    with ModbusSimServer(port=0) as server:  # the simulator's defaults, as haptic-bus sim --modbus serves them
        assert main(["profiles", "new", "axis", "--from-drive", "--modbus", server.url, "--out", str(out)]) == 0
    device = tomllib.loads(out.read_text())["device"]
    assert {key: device[key] for key in ("rated_torque", "max_torque_permille", "velocity_per_count",
                                         "position_per_count", "force_per_torque")} == {
        "rated_torque": TRUTH.rated_torque, "max_torque_permille": TRUTH.max_torque_permille,
        "velocity_per_count": TRUTH.velocity_per_count, "position_per_count": TRUTH.position_per_count,
        "force_per_torque": TRUTH.force_per_torque}
    assert "stated by the drive, register 0x" in out.read_text()


def test_a_silent_node_is_one_line_and_exit_1(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "axis.toml"
    started = time.monotonic()
    assert main(["profiles", "new", "axis", "--from-drive", "--interface", "virtual", "--channel",
                 f"empty-{uuid.uuid4().hex[:10]}", "--node-id", "9", "--timeout", "0.2", "--out", str(out)]) == 1
    assert time.monotonic() - started < 10.0  # one unanswered read, bounded by the timeout (a hang would run far past)
    assert one_line(capsys.readouterr().err) == ("haptic-bus profiles new: drive error: node 9: no answer from node 9 within "
                                                 "0.2 s (haptic-bus scan lists the nodes on the bus)\n")
    assert not out.exists()


@pytest.mark.parametrize("argv, message", [
    (["my handle"], "NAME = 'my handle' is invalid"),
    (["axis", "--node-id", "5"], "--node-id = 5 is invalid"),
    (["axis", "--from-drive"], "--from-drive = 'without a drive' is invalid; allowed: --node-id N (and the bus) or --modbus"),
    (["axis", "--from-drive", "--modbus", "tcp://127.0.0.1:1", "--node-id", "5"], "--node-id = 5 is invalid"),
    (["axis", "--mass", "-1"], "--mass = -1 is invalid"),
    (["axis", "--velocity", "fast"], "velocity = 'fast' is invalid"),
    (["axis", "--force-limit", "0"], "--force-limit = 0 is invalid"),
])
def test_bad_input_is_one_line_and_exit_2(argv: list[str], message: str, tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "axis.toml"
    assert main(["profiles", "new", *argv, "--out", str(out)]) == 2
    assert message in one_line(capsys.readouterr().err)
    assert not out.exists()


def test_an_existing_file_is_kept_without_force(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "axis.toml"
    out.write_text("kept\n")
    assert main(["profiles", "new", "axis", "--out", str(out)]) == 2
    assert one_line(capsys.readouterr().err) == (f"haptic-bus profiles new: error: --out = '{out}' is invalid; "
                                                 "allowed: a file that does not exist yet (--force overwrites it)\n")
    assert out.read_text() == "kept\n"
    assert main(["profiles", "new", "axis", "--out", str(out), "--force"]) == 0
    assert out.read_text().startswith("# Profile axis, written by `haptic-bus profiles new axis` on ")


def test_an_empty_out_is_refused_not_read_as_the_default(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """``--out ""`` (a script's unset variable) wrote NAME.toml here, as if no --out were given; ``run --out ""``
    is refused, and so is this now."""
    monkeypatch.chdir(tmp_path)
    assert main(["profiles", "new", "axis", "--out", ""]) == 2
    assert one_line(capsys.readouterr().err) == ("haptic-bus profiles new: error: --out = '' is invalid; allowed: a file's "
                                                 "path (empty: none given)\n")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("force", [[], ["--force"]])
def test_no_file_but_a_regular_one_is_replaced(force: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A pipe (as a device: ``--out /dev/null --force`` run as root renamed a regular file over the device) is
    refused, with or without --force, and stays what it was."""
    out = tmp_path / "pipe"
    os.mkfifo(out)
    assert main(["profiles", "new", "axis", "--out", str(out), *force]) == 2
    assert one_line(capsys.readouterr().err) == (
        f"haptic-bus profiles new: error: --out = '{out}' is invalid; allowed: a regular file or none (not a device, "
        "a pipe or a socket)\n")
    assert stat.S_ISFIFO(out.stat().st_mode)


@pytest.mark.parametrize("where", ["inside a file", "a folder", "a missing folder"])
def test_an_unwritable_target_is_one_line_and_exit_2(where: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    afile = tmp_path / "afile"
    afile.write_text("kept\n")
    out = {"inside a file": afile / "axis.toml", "a folder": tmp_path, "a missing folder": tmp_path / "no" / "axis.toml"}[where]
    assert main(["profiles", "new", "axis", "--out", str(out)]) == 2
    assert one_line(capsys.readouterr().err) == (f"haptic-bus profiles new: error: --out = '{out}' is invalid; "
                                                 "allowed: a file in an existing folder this user can write\n")
    assert afile.read_text() == "kept\n"
