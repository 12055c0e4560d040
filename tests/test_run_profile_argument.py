"""``hb.run`` given a profile's name or path instead of the profile: one ParameterError that says what
it takes, before any bus or file is touched (it used to ask a one-axis run's node_id even of
"gantry-3d", whose node ids come from its [[axes]])."""

from __future__ import annotations

import pathlib

import pytest

import haptic_bus as hb


@pytest.mark.parametrize("given", ["gantry-3d", pathlib.Path("profiles/cia402-handle.toml")])
def test_a_profile_name_or_path_is_refused_naming_the_loader(tmp_path: pathlib.Path, given: object) -> None:
    out = tmp_path / "run"
    with pytest.raises(hb.ParameterError) as caught:
        hb.run(given, {"interface": "virtual", "channel": "unused"}, hb.RunOptions(1.0, out_dir=out))  # type: ignore[arg-type]
    assert str(caught.value) == (f"run: profile = {given!r} is invalid; allowed: a Profile or an AxesProfile, as "
                                 "hb.load_profile(name_or_path) returns it")
    assert not out.exists()
