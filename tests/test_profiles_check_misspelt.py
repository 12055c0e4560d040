"""``haptic-bus profiles check`` names a misspelt required key as ``profiles show`` and ``run`` do,
not as the value "still missing" that the user did write under another name (breaker11b)."""

from __future__ import annotations

import pathlib
import re

import pytest

from haptic_bus.app.cli import main
from haptic_bus.profile.files import resolve_profile


def _edited(tmp_path: pathlib.Path, pattern: str, replacement: str) -> pathlib.Path:
    """The shipped cia402-handle with one line of it changed, as a file of its own."""
    text = resolve_profile("cia402-handle").read_text(encoding="utf-8")
    edited, count = re.subn(pattern, replacement, text, count=1, flags=re.MULTILINE)
    assert count == 1
    path = tmp_path / "edited.toml"
    path.write_text(edited, encoding="utf-8")
    return path


@pytest.mark.parametrize(("pattern", "replacement", "named"), [
    (r"^mass = ", "masss = ", "device.masss = 1.0 is invalid; allowed: no such key; did you mean mass?"),
    (r"^force_limit = ", "forcelimit = ", "limits.forcelimit = 30.0 is invalid; allowed: no such key; did you mean force_limit?"),
])
def test_check_names_the_misspelling(tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str],
                                     pattern: str, replacement: str, named: str) -> None:
    path = _edited(tmp_path, pattern, replacement)
    for command in ("check", "show"):  # the same line from both
        assert main(["profiles", command, str(path)]) == 2
        lines = capsys.readouterr().err.splitlines()
        assert len(lines) == 1
        assert lines[0].startswith(f"haptic-bus profiles {command}: error: profile {path}: {named} (")


def test_check_still_lists_a_key_left_out(tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _edited(tmp_path, r"^mass = .*\n", "")  # no key like it left: what profiles new asks for
    assert main(["profiles", "check", str(path)]) == 2
    assert capsys.readouterr().err == f"haptic-bus profiles check: error: {path}: still missing device.mass\n"
