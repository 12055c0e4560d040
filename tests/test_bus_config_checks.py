"""The values python-can would take without a word are checked where the bus configuration is made,
one line each, exit 2 before any bus is opened:

- udp_multicast's hop_limit: a text or a value that does not fit the IP header's one byte (it was
  python-can's struct.error traceback, exit 1, from ``--bus-option hop_limit=abc``);
- the bitrate: a positive whole number of bit/s, from ``--bitrate``, ``--bus-option`` or python-can's
  configuration (``haptic-bus run --bitrate -5`` was accepted);
- udp_multicast's group and port: ``haptic-bus run --interface udp_multicast`` without ``--channel`` ended in
  python-can's ``inet_pton`` TypeError traceback, and ``--bus-option port=99999`` was a drive error, exit 1
  (found by hand, break14b);
- no bus at all (no --interface, nothing in python-can's environment or config file): every command that
  opens a bus said it as a drive error, exit 1 (``haptic-bus status``, break round 16); it is invalid input.
"""

from __future__ import annotations

import pathlib

import pytest

from drives.bus_config import LOCAL_HOP_LIMIT, resolve_bus_config
from drives.errors import ParameterError
from haptic_bus.app.cli import main

GROUP = {"interface": "udp_multicast", "channel": "239.74.163.2", "port": 43113}


def test_no_hop_limit_stays_on_this_host() -> None:
    assert resolve_bus_config(**GROUP)["hop_limit"] == LOCAL_HOP_LIMIT


def test_a_hop_limit_the_user_names_is_kept() -> None:
    assert resolve_bus_config(**GROUP, hop_limit=1)["hop_limit"] == 1


@pytest.mark.parametrize("hops", ["abc", -1, 256, 1.5, True])
def test_a_hop_limit_that_is_no_byte_is_refused_in_one_line(hops: object) -> None:
    with pytest.raises(ParameterError) as refused:
        resolve_bus_config(**GROUP, hop_limit=hops)
    assert "hop_limit" in str(refused.value) and "0..255" in str(refused.value)
    assert "\n" not in str(refused.value)


@pytest.mark.parametrize("rate", [-5, 0, 1.5, "fast", True])
def test_a_bitrate_that_is_no_positive_whole_number_is_refused_in_one_line(rate: object) -> None:
    with pytest.raises(ParameterError) as refused:
        resolve_bus_config(interface="virtual", channel="checks", bitrate=rate)  # type: ignore[arg-type]
    assert str(refused.value).startswith("bus virtual:checks: bitrate = ")
    assert "a positive whole number of bit/s" in str(refused.value) and "\n" not in str(refused.value)


def test_a_bitrate_the_user_names_is_kept() -> None:
    assert resolve_bus_config(interface="virtual", channel="checks", bitrate=500_000)["bitrate"] == 500_000


def test_run_refuses_a_negative_bitrate_with_exit_2_before_its_bus(tmp_path: pathlib.Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    code = main(["run", "cia402-handle", "--interface", "virtual", "--channel", "checks", "--node-id", "5",
                 "--bitrate", "-5", "--duration", "0.1", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "bitrate = -5 is invalid" in err, err
    assert not out.exists()  # refused before its folder, too


@pytest.mark.parametrize(("option", "value", "allowed"), [
    ("channel", None, "a multicast group address"), ("channel", "", "a multicast group address"),
    ("port", 99999, "1..65535"), ("port", 0, "1..65535"), ("port", "abc", "1..65535"), ("port", True, "1..65535")])
def test_a_udp_multicast_group_or_port_that_cannot_be_is_refused_in_one_line(option: str, value: object,
                                                                               allowed: str) -> None:
    with pytest.raises(ParameterError) as refused:
        resolve_bus_config(**{**GROUP, option: value})
    said = f"{option} is missing" if value is None else f"{option} = "
    assert said in str(refused.value) and allowed in str(refused.value) and "\n" not in str(refused.value)


def test_run_without_a_group_is_exit_2_in_one_line_before_its_bus(tmp_path: pathlib.Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    code = main(["run", "cia402-handle", "--interface", "udp_multicast", "--node-id", "5", "--duration", "0.1",
                 "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "channel is missing; allowed: a multicast group address" in err, err
    assert not out.exists()


NO_BUS_COMMANDS = [
    ["status", "--node-id", "5"], ["scan"], ["sdo", "read", "0x1000", "--node-id", "5"], ["fault-reset", "--node-id", "5"],
    ["run", "cia402-handle", "--node-id", "5", "--duration", "0.1"], ["validate", "cia402-handle", "--node-id", "5"],
    ["upload", "--node-id", "5", "--object", "1", "--stiffness", "1", "--damping", "1"],
    ["identify", "--profile", "cia402-handle", "--node-id", "5"],
]


@pytest.mark.parametrize("command", NO_BUS_COMMANDS, ids=[c[0] for c in NO_BUS_COMMANDS])
def test_no_bus_configured_is_exit_2_in_one_line_naming_what_is_missing(
        command: list[str], tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    for name in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr("can.rc", {})
    monkeypatch.setattr("can.util.CONFIG_FILES", [])
    monkeypatch.chdir(tmp_path)  # a run folder would appear here
    code = main(command)
    err = capsys.readouterr().err
    assert code == 2 and err == (f"haptic-bus {command[0]}: error: bus: interface is missing; allowed: --interface NAME "
                                 "and --channel CHANNEL (e.g. socketcan can0), CAN_INTERFACE and CAN_CHANNEL, a [default] "
                                 "section in python-can's config file ~/.canrc, or --modbus URL\n"), err
    assert list(tmp_path.iterdir()) == []
