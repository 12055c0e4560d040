"""A unit id no Modbus unit answers for names the option that gave it: ``--unit-id`` for a one-axis
run, ``--unit-ids`` (or the profile's ``[[axes]] unit_id``) for several axes.  A one-axis run was told
to check ``--unit-ids``, an option its command line refuses (exit 2)."""

from __future__ import annotations

import pathlib

import pytest

import haptic_bus as hb
from haptic_bus.app.profiles import load_profile

CASES = [  # profile, the run's unit id keywords, the unit nobody answers for, the hint's end
    ("cia402-handle", {"unit_id": 3}, 3, "check the unit id (--unit-id)"),
    ("gantry-3d", {"unit_ids": [1, 2, 4]}, 4, "check the unit ids (--unit-ids, or the profile's [[axes]] unit_id)"),
]


@pytest.mark.parametrize(("name", "units", "missing", "hint"), CASES, ids=[case[0] for case in CASES])
def test_a_unit_nobody_answers_for_names_the_option_that_gave_it(haptic_sim, tmp_path: pathlib.Path, name: str,
                                                                  units: dict[str, object], missing: int,
                                                                  hint: str) -> None:
    drive = haptic_sim(name, interface="modbus")
    options = hb.RunOptions(0.01, pacing="virtual", out_dir=tmp_path / "run", live=False, plots=False)
    result = hb.run(load_profile(name), drive.bus, options, **units)
    assert result.exit_reason == "drive error"
    assert result.summary is None  # refused at connect: never cycled, nothing enabled
    assert result.error is not None
    assert f"no unit {missing} answers at {drive.bus}" in result.error
    assert result.error.endswith(hint)
