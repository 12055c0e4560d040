"""A profile nested hundreds deep (``b = [[[[...]]]]``, inline tables, a dotted table header of 2000
keys) is one line naming the nesting, exit 2, from every reader of a profile (``profiles check``,
``run``, ``sim``, ``hb.load_profile``): tomllib parses recursively, and such a file used to end
``profiles check`` in a RecursionError's traceback, exit 1 (break16)."""

from __future__ import annotations

import json
import pathlib

import pytest

from haptic_bus.app.cli import main
from haptic_bus.errors import ParameterError
from haptic_bus.profile.files import resolve_profile
from haptic_bus.profile.reader import MAX_NESTING, read_document

HANDLE = resolve_profile("cia402-handle").read_text()

DEEP = {  # each a shipped profile plus one deep value, of each shape the parser recurses on
    "array": HANDLE.replace("level = 3.0", "level = " + "[" * 500 + "]" * 500),
    "inline-table": HANDLE + "\nx = " + "{a=" * 2000 + "1" + "}" * 2000 + "\n",
    "dotted-header": HANDLE + "\n[" + ".".join(["a"] * 2000) + "]\n",
    "just-too-deep": HANDLE + "\nx = " + "[" * MAX_NESTING + "1" + "]" * MAX_NESTING + "\n",
}


@pytest.mark.parametrize("shape", sorted(DEEP))
def test_a_deeply_nested_profile_is_one_line_exit_2(shape: str, tmp_path: pathlib.Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / f"{shape}.toml"
    path.write_text(DEEP[shape])
    with pytest.raises(ParameterError) as raised:
        read_document(path)
    assert raised.value.name == "(nesting)"
    for argv in (["profiles", "check", str(path)], ["profiles", "show", str(path)],
                 ["run", str(path), "--interface", "virtual", "--channel", "break16-nesting", "--node-id", "3"]):
        assert main(argv) == 2, argv
        out, err = capsys.readouterr()
        assert out == "" and "Traceback" not in err and err.count("\n") == 1, (out, err)
        assert f"profile {path}: (nesting) = " in err and f"nested at most {MAX_NESTING} deep" in err, err


def test_the_deepest_nesting_a_profile_uses_is_within_the_limit(tmp_path: pathlib.Path) -> None:
    """The limit refuses nothing a profile means: gantry-3d's ``space.operator.toward`` (points in an array
    in a table in a table) and a value nested exactly MAX_NESTING deep, counting its tables, load."""
    read_document(resolve_profile("gantry-3d"))
    path = tmp_path / "limit.toml"
    path.write_text("x = " + "[" * (MAX_NESTING - 1) + "1" + "]" * (MAX_NESTING - 1) + "\n")
    assert read_document(path)["x"] == json.loads("[" * (MAX_NESTING - 1) + "1" + "]" * (MAX_NESTING - 1))
