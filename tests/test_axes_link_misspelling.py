"""An ``[[axes]]`` entry whose ``node_id`` or ``unit_id`` is misspelt is refused naming the
misspelling ("did you mean"), as a misspelt required key is, not as a missing link."""

from __future__ import annotations

import pathlib

import pytest

import profiles
from haptic_bus.app.profiles import read_profile
from haptic_bus.errors import ParameterError

GANTRY = pathlib.Path(profiles.__file__).parent / "gantry-3d.toml"


@pytest.mark.parametrize(("written", "meant"), [("nod_id", "node_id"), ("unit_idd", "unit_id")])
def test_a_misspelt_link_of_an_axis_is_named(tmp_path: pathlib.Path, written: str, meant: str) -> None:
    text = GANTRY.read_text()
    assert text.count("\nnode_id = 6\n") == 1  # axis y's link, axes[1]
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("\nnode_id = 6\n", f"\n{written} = 6\n"))
    with pytest.raises(ParameterError) as caught:
        read_profile(bad)
    assert str(caught.value).startswith(f"profile {bad}: axes[1].{written} = 6 is invalid; allowed: no such key; "
                                        f"did you mean {meant}? ")


def test_an_axis_without_a_link_is_told_to_give_one(tmp_path: pathlib.Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(GANTRY.read_text().replace("\nnode_id = 6\n", "\n"))
    with pytest.raises(ParameterError, match=r"axes\[1\]\.node_id is missing; allowed: exactly one of "
                                             r"node_id \(CANopen node ids 1\.\.127\) and unit_id \(Modbus unit ids 1\.\.247\)$"):
        read_profile(bad)
