"""``haptic-bus run AXES --modbus A --modbus A --modbus B`` (a server named twice, no --unit-ids) is refused
naming --modbus, the flag given twice; the line named ``--unit-ids = [1, 1, 1]``, a flag the user never
typed (break16).  With unit ids that keep the places apart the same URL twice stays allowed."""

from __future__ import annotations

import pytest

from haptic_bus.app.profiles import read_profile
from haptic_bus.app.run_links import modbus_units
from haptic_bus.errors import ParameterError
from haptic_bus.profile.files import resolve_profile

A, B = "tcp://127.0.0.1:44169", "tcp://127.0.0.1:44168"


def test_a_server_named_twice_without_unit_ids_names_the_urls() -> None:
    gantry = read_profile(resolve_profile("gantry-3d"))
    with pytest.raises(ParameterError) as raised:
        modbus_units(gantry, [A, A, B], None)
    assert raised.value.name == "bus" and raised.value.value == [A, A, B]
    assert raised.value.allowed.startswith("one Modbus URL for every axis, or a different one per axis (3): a server "
                                           "named twice")
    with pytest.raises(ParameterError) as given:  # unit ids given, two at one place: the unit ids are named
        modbus_units(gantry, [A, A, B], [1, 1, 2])
    assert given.value.name == "unit_ids"
    assert modbus_units(gantry, [A, A, B], [1, 2, 1]) == [1, 2, 1]  # two units on A, one on B
    assert modbus_units(gantry, [A, B, "tcp://127.0.0.1:44167"], None) == [1, 1, 1]
