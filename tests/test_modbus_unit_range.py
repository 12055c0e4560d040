"""hb.run and ModbusDrive take the Modbus unit ids the command line takes (1..247), refused before
anything is touched: unit 0 is broadcast, which no unit answers (breaker6: hb.run took unit_id=0,
opened a run folder and asked unit 0 for its identity)."""

from __future__ import annotations

import pathlib

import pytest

import haptic_bus as hb
from drives.modbus.drive import ModbusDrive
from drives.modbus.register_map import UNIT_ID_RANGE

# nothing listens here: a check that came after the connect would fail on the connect instead
URL = "tcp://127.0.0.1:1"


@pytest.mark.parametrize("unit_id", [0, 248, True])
def test_one_axis_run_refuses_a_unit_id_no_unit_answers(tmp_path: pathlib.Path, unit_id: int) -> None:
    out = tmp_path / "run"
    with pytest.raises(hb.ParameterError) as raised:
        hb.run(hb.load_profile("cia402-handle"), URL, hb.RunOptions(duration=0.1, pacing="virtual", out_dir=out),
               unit_id=unit_id)
    assert str(raised.value).startswith(f"run: unit_id = {unit_id!r} is invalid; allowed: Modbus unit ids 1..247")
    assert not out.exists()  # no run folder: nothing touched


def test_several_axes_run_refuses_unit_ids_no_unit_answers(tmp_path: pathlib.Path) -> None:
    out = tmp_path / "run"
    with pytest.raises(hb.ParameterError) as raised:
        hb.run(hb.load_profile("gantry-3d"), URL, hb.RunOptions(duration=0.1, pacing="virtual", out_dir=out),
               unit_ids=[0, 1, 2])
    assert "unit_ids = [0, 1, 2] is invalid" in str(raised.value)
    assert not out.exists()


@pytest.mark.parametrize("unit_id", [UNIT_ID_RANGE[0] - 1, UNIT_ID_RANGE[1] + 1])
def test_modbus_drive_takes_the_units_that_answer(unit_id: int) -> None:
    with pytest.raises(hb.ParameterError, match=r"unit_id = .* allowed: Modbus unit ids 1\.\.247"):
        ModbusDrive.from_url(URL, unit_id=unit_id)
    assert ModbusDrive.from_url(URL, unit_id=UNIT_ID_RANGE[1]).unit_id == 247  # built, not connected


def test_unit_ids_given_as_a_string_are_refused_as_such(tmp_path: pathlib.Path) -> None:
    """``unit_ids="123"`` read as three ids '1', '2', '3' said "1..247" of strings; it is refused as what it is."""
    options = hb.RunOptions(0.01, pacing="virtual", out_dir=tmp_path / "run", live=False)
    with pytest.raises(hb.ParameterError, match=r"^run: unit_ids = '123' is invalid; allowed: Modbus unit ids 1\.\.247, a "
                                                r"list of them, one per axis$"):
        hb.run(hb.load_profile("gantry-3d"), "tcp://127.0.0.1:1", options, unit_ids="123")  # type: ignore[arg-type]
    assert not (tmp_path / "run").exists()
