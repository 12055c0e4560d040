"""``haptic-bus run AXES --modbus A --modbus A --modbus B`` (a server named twice, no --unit-ids) is refused
naming --modbus, the flag given twice; the line named ``--unit-ids = [1, 1, 1]``, a flag the user never
typed (break16).  With unit ids that keep the places apart the same URL twice stays allowed."""

from __future__ import annotations

import pathlib

import pytest

from drives.modbus.in_process import tcp_url
from drives.modbus.link import ModbusAddress
from haptic_bus.app.cli import main
from haptic_bus.app.profiles import read_profile
from haptic_bus.app.run_links import modbus_units
from haptic_bus.errors import ParameterError
from haptic_bus.profile.files import resolve_profile

A, B = "tcp://127.0.0.1:44169", "tcp://127.0.0.1:44168"


def test_a_server_named_twice_without_unit_ids_names_the_url() -> None:
    gantry = read_profile(resolve_profile("gantry-3d"))
    with pytest.raises(ParameterError) as raised:
        modbus_units(gantry, [A, A, B], None)
    assert raised.value.name == "bus" and raised.value.value == A  # the URL given twice, not the list (break18b)
    assert raised.value.allowed == ("one for every axis, or a different one per axis (3 axes; 3 given, this one twice): "
                                    "several axes on one server: one URL with the unit ids")
    with pytest.raises(ParameterError) as given:  # unit ids given, two at one place: the unit ids are named
        modbus_units(gantry, [A, A, B], [1, 1, 2])
    assert given.value.name == "unit_ids" and given.value.allowed.endswith(f"none twice at one URL (unit 1 is given twice "
                                                                           f"at {A})")
    assert modbus_units(gantry, [A, A, B], [1, 2, 1]) == [1, 2, 1]  # two units on A, one on B
    assert modbus_units(gantry, [A, B, "tcp://127.0.0.1:44167"], None) == [1, 1, 1]


@pytest.mark.parametrize(("urls", "shown"), [([A, A], f"'{A}' is invalid; allowed: one for a one-axis profile (given twice"),
                                             ([A, B], f"'{B}' is invalid; allowed: one for a one-axis profile (2 given, "
                                                      "this one last")])
def test_a_one_axis_run_given_modbus_twice_names_a_url_as_typed(
        urls: list[str], shown: str, tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``run cia402-handle --modbus A --modbus A``: one line naming the URL, not the list (break18b)."""
    code = main(["run", "cia402-handle", *(word for url in urls for word in ("--modbus", url)), "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and err.startswith(f"haptic-bus run: error: --modbus = {shown}"), err
    assert not (tmp_path / "r").exists()


def test_an_ipv6_address_is_written_in_brackets(capsys: pytest.CaptureFixture[str]) -> None:
    """An IPv6 Modbus address shows as it is typed, ``tcp://[::1]:PORT``: it showed as ``tcp://::1:PORT``,
    which names no port (break round 16).  Nothing listens on the port: the one line is the drive error."""
    assert ModbusAddress.from_url("tcp://[::1]:5020").url == "tcp://[::1]:5020"
    assert ModbusAddress.from_url("tcp://127.0.0.1:5020").url == "tcp://127.0.0.1:5020"
    assert tcp_url("fe80::1%eth0", 502) == "tcp://[fe80::1%eth0]:502" and tcp_url("drive.local", 502) == "tcp://drive.local:502"
    code = main(["status", "--modbus", "tcp://[::1]:15179"])
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1 and err.startswith("haptic-bus status: drive error: Modbus unit 1 at "
                                                                 "tcp://[::1]:15179: "), err


@pytest.mark.parametrize("timeout", [0, -0.1, float("inf"), float("nan"), True, "0.1"])
def test_an_answer_timeout_that_is_no_finite_real_above_zero_is_refused(timeout: object) -> None:
    with pytest.raises(ParameterError) as refused:
        ModbusAddress.from_url(A, timeout=timeout)  # type: ignore[arg-type]
    assert str(refused.value) == f"Modbus drive: timeout = {timeout!r} is invalid; allowed: a finite real > 0 s"
