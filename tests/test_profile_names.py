"""A profile named on the command line or to ``hb.load_profile``: a shipped name, a path, or
neither, and for neither one ParameterError (exit 2 on the command line), whatever the string."""

from __future__ import annotations

import pathlib

import pytest

import haptic_bus as hb
from haptic_bus.app.cli import main

NAME_MAX = 255
"""Linux's longest file name, bytes: a longer name is ENAMETOOLONG, not "no such file"."""


@pytest.mark.parametrize("length", [NAME_MAX - len(".toml") + 2, NAME_MAX + 45])
def test_a_name_too_long_for_a_file_is_refused_in_one_line(length: int, capsys: pytest.CaptureFixture[str]) -> None:
    # NAME_MAX - 3 characters: a name the working folder may hold, but not with ".toml" after it in the
    # profiles folder; NAME_MAX + 45: too long anywhere
    name = "a" * length
    with pytest.raises(hb.ParameterError) as caught:
        hb.load_profile(name)
    assert caught.value.allowed.startswith("an existing TOML file or a shipped profile name: cia402-handle,")
    assert main(["profiles", "show", name]) == 2
    err = capsys.readouterr().err
    assert err.startswith("haptic-bus profiles show: error: profile ") and err.count("\n") == 1


def test_a_shipped_name_beside_a_file_of_that_name_in_the_working_folder(tmp_path: pathlib.Path,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    from haptic_bus.profile.files import resolve_profile

    shipped = resolve_profile("cia402-handle")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "cia402-handle.toml").write_text("not a profile")
    assert resolve_profile("cia402-handle") == shipped  # the name is the shipped one's
    assert resolve_profile("cia402-handle.toml") == pathlib.Path("cia402-handle.toml")  # the path is the file's
    (tmp_path / "gantry-3d").symlink_to(shipped)  # a file named exactly as given wins, as a path
    assert resolve_profile("gantry-3d") == pathlib.Path("gantry-3d")
    with pytest.raises(hb.ParameterError):
        resolve_profile(pathlib.Path("seed-ideal"))  # a Path is a path, never a name
