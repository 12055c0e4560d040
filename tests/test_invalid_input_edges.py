"""Invalid input a new user meets at the edges (a ~/.canrc python-can cannot read, id ranges too large to
list, malformed IPv6 Modbus URLs, None for the API's arguments, an interface's own arguments left out):
each one line and exit 2 (ParameterError), no traceback (found by a user-level break round, break17b)."""

from __future__ import annotations

import pathlib

import pytest

from drives.bus_config import resolve_bus_config
from drives.errors import ParameterError


@pytest.fixture
def no_can_env(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        monkeypatch.delenv(name, raising=False)


@pytest.mark.parametrize("text, said", [
    (b"[default\ninterface = virtual\n", "no section headers"),          # configparser's traceback, exit 1
    (b"[default]\ninterface = virtual\ninterface = x\n", "already exists"),
    (b"\xff\xfe[default]\n", "utf-8"),                                    # a DriveError, exit 1
])
def test_unreadable_canrc_is_invalid_input(tmp_path, no_can_env, text: bytes, said: str) -> None:
    rc = tmp_path / "canrc"
    rc.write_bytes(text)
    with pytest.raises(ParameterError) as caught:
        resolve_bus_config(config_file=str(rc))
    assert caught.value.name == "python-can's config file"
    assert said in caught.value.allowed
    assert "\n" not in str(caught.value)


def test_canrc_unknown_interface_is_invalid_input(tmp_path, no_can_env) -> None:
    rc = tmp_path / "canrc"
    rc.write_text("[default]\ninterface = nonesuch\nchannel = x\n")
    with pytest.raises(ParameterError) as caught:  # was DriveError 'invalid CAN bus configuration', exit 1
        resolve_bus_config(config_file=str(rc))
    assert caught.value.name == "interface" and caught.value.value == "nonesuch"
    assert "udp_multicast" in caught.value.allowed


@pytest.mark.parametrize("text", ["1-100000000", "1-0x7fffffffffff", "0-5", "5-1000000000000"])
def test_huge_id_range_is_refused_before_it_is_listed(text: str) -> None:
    from haptic_bus.validation import ids_in_order

    with pytest.raises(ParameterError) as caught:  # was range(1, 10**8) listed first: MemoryError, exit 1
        ids_in_order("unit ids", text, "Modbus unit ids", 1, 247)
    assert caught.value.value == text
    assert ids_in_order("unit ids", "0x5-0x7,1", "Modbus unit ids", 1, 247) == [5, 6, 7, 1]


@pytest.mark.parametrize("url", ["tcp://[::1:15191", "tcp://::1]:15191", "tcp://[]:15191", "tcp://[::zz]:15191",
                                 "tcp://[127.0.0.1]:15191"])
def test_malformed_ipv6_modbus_url_is_invalid_input(url: str) -> None:
    from drives.modbus.link import ModbusAddress
    from sim_drive.modbus.server import parse_modbus_url

    for read in (ModbusAddress.from_url, parse_modbus_url):  # was urllib's ValueError traceback, exit 1
        with pytest.raises(ParameterError) as caught:
            read(url)
        assert caught.value.value == url and "tcp://[::1]:PORT" in caught.value.allowed
    assert ModbusAddress.from_url("tcp://[::1]:15191").host == "::1"
    assert parse_modbus_url("tcp://[::1]:15191") == ("::1", 15191)


def test_load_profile_of_nothing_names_no_none() -> None:
    import haptic_bus as hb

    with pytest.raises(hb.ParameterError) as caught:  # was 'profile None: profile is missing; ...'
        hb.load_profile(None)  # type: ignore[arg-type]
    assert str(caught.value).startswith("profile is missing; allowed: ") and "None" not in str(caught.value)
    with pytest.raises(hb.ParameterError) as caught:  # was 'profile : profile = '' is invalid; ...'
        hb.load_profile("")
    assert str(caught.value).startswith("profile = '' is invalid; allowed: ") and "stiff-wall" in str(caught.value)


def test_run_modbus_without_url_names_the_url() -> None:
    import haptic_bus as hb

    profile = hb.load_profile("stiff-wall")
    with pytest.raises(hb.ParameterError) as caught:  # was 'run: unit_id = 1 is invalid; ... a CANopen drive is node_id'
        hb.run_modbus(profile, None, 1, hb.RunOptions(duration=0.1))  # type: ignore[arg-type]
    assert caught.value.name == "url" and caught.value.value is None
    assert str(caught.value).startswith("run_modbus: url is missing; allowed: a Modbus URL")


def test_run_modbus_without_unit_id_names_it_missing(tmp_path: pathlib.Path) -> None:
    """``hb.run_modbus(profile, url, None, options)`` ran against unit 1 (run()'s default); its unit id is
    required: refused as missing, before any folder or bus."""
    import haptic_bus as hb

    profile = hb.load_profile("stiff-wall")
    with pytest.raises(hb.ParameterError) as caught:
        hb.run_modbus(profile, "tcp://127.0.0.1:47104", None, hb.RunOptions(duration=0.1, out_dir=tmp_path / "r"))  # type: ignore[arg-type]
    assert caught.value.name == "unit_id" and caught.value.value is None
    assert str(caught.value) == "run_modbus: unit_id is missing; allowed: Modbus unit ids 1..247"
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("interface, missing", [("serial", "channel"), ("slcan", "channel"),
                                                ("socketcand", "channel, host, port")])
def test_an_interface_without_its_required_arguments_is_invalid_input(no_can_env, interface: str, missing: str) -> None:
    from drives.bus_config import open_bus

    with pytest.raises(ParameterError) as caught:  # was python-can's TypeError traceback ('missing 1 required
        open_bus(interface=interface, config_file="/nonexistent/canrc")  # positional argument: 'channel'), exit 1
    assert caught.value.name == "channel" and caught.value.value is None
    assert caught.value.context == f"bus {interface}:?"  # no '{interface}:None'
    assert f"the {interface} bus' {missing} (--channel" in caught.value.allowed
