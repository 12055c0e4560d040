"""A profile's ``[safety]`` table tunes the safety chain (issue 10): every key reaches the
settings the masters write, an unknown key or a value out of range is a ParameterError naming it."""

from __future__ import annotations

import pytest

from drives.safety import SafetySettings
from haptic_bus.app.profiles import load_profile, resolve_profile
from haptic_bus.errors import ParameterError


def _profile_with(tmp_path, table: str):
    path = tmp_path / "tuned.toml"
    path.write_text(resolve_profile("cia402-handle").read_text() + "\n[safety]\n" + table)
    return load_profile(path)


def test_no_safety_table_gives_the_defaults() -> None:
    assert load_profile("cia402-handle").safety == SafetySettings()


def test_every_safety_key_reaches_the_settings(tmp_path) -> None:
    safety = _profile_with(tmp_path, 'heartbeat_ms = 10\nconsumer_ms = 35\nrpdo_deadline_periods = 5\n'
                                     'abort_option = "quick-stop"\nstrict = true\nmodbus_watchdog_ms = 80\n').safety
    assert safety == SafetySettings(heartbeat_ms=10, consumer_ms=35, rpdo_deadline_periods=5, abort_option=3,
                                    strict=True, modbus_watchdog_ms=80)
    assert safety.rpdo_deadline_ms(0.001) == 5


@pytest.mark.parametrize(("table", "key"), [
    ("consumer_ms = 20\n", "consumer_ms"),  # not longer than the 20 ms heartbeat
    ("heartbeat_ms = 0\n", "heartbeat_ms"),
    ('abort_option = "explode"\n', "abort_option"),
    ("rpdo_deadline_periods = -1\n", "rpdo_deadline_periods"),
    ("modbus_watchdog_ms = 70000\n", "modbus_watchdog_ms"),
    ("heartbeat = 20\n", "heartbeat"),  # a misspelt key is not silently ignored
])
def test_a_bad_safety_value_names_its_key(tmp_path, table: str, key: str) -> None:
    with pytest.raises(ParameterError, match=key):
        _profile_with(tmp_path, table)
