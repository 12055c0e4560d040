"""``profiles new`` without ``--force`` never replaces a file, even one another command made after its
check that the file did not exist (two ``profiles new`` at once: 2 of 8 started together used to exit 0,
each having written the same file, the later replacing the earlier); it creates the file exclusively
(O_EXCL) and, finding it there, says so as its check does: one line, exit 2 (break16)."""

from __future__ import annotations

import pathlib

import pytest

import haptic_bus.app.profile_template as profile_template
from haptic_bus.app.cli import main

OTHERS = "# written by another command meanwhile\n"


def test_a_file_made_between_the_check_and_the_write_is_kept(
        tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "new.toml"
    template = profile_template.template

    def another_command_meanwhile(*args: object, **kwargs: object) -> str:
        out.write_text(OTHERS)  # after profiles new's check, before its write
        return template(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(profile_template, "template", another_command_meanwhile)
    assert main(["profiles", "new", "new", "--out", str(out)]) == 2
    stdout, err = capsys.readouterr()
    assert stdout == "" and out.read_text() == OTHERS
    assert err == (f"haptic-bus profiles new: error: --out = '{out}' is invalid; allowed: a file that does not "
                   "exist yet (--force overwrites it)\n")
    assert main(["profiles", "new", "new", "--out", str(out), "--force"]) == 0  # --force replaces it, as it says
    assert out.read_text().startswith("# Profile new, written by `haptic-bus profiles new new`")
