"""The README a newcomer reads in five minutes: at most 200 lines, the two fresh-machine commands as
CI runs them, one line for each command ``haptic-bus --help`` lists, and every ``haptic-bus`` command
line of the README and the manual one the command's own parser takes (its options spelled as they are).

The README's Python example is the package docstring's (``tests/test_public_api.py`` runs that), its
plugin example runs in ``tests/test_plugin.py`` and ``tests/test_plugin_fresh_venv.py``, the manual's
examples in ``tests/test_manual_examples.py`` and ``tests/test_commissioning_walkthrough.py``.
"""

from __future__ import annotations

import argparse
import pathlib
import re

import pytest

from haptic_bus.app.cli import build_parser
from tests.doc_blocks import PAGES, README, REPO, code_blocks, command_lines

FRESH_MACHINE = ["pip install -e . && haptic-bus demo", "pip install -e '.[test]' && python -m pytest -q -n 4"]


def test_the_readme_is_at_most_200_lines() -> None:
    assert len(README.read_text().splitlines()) <= 200


def test_the_fresh_machine_commands_come_first_and_ci_runs_the_test_command_verbatim() -> None:
    assert code_blocks(README, "bash")[:2] == [command + "\n" for command in FRESH_MACHINE]
    assert FRESH_MACHINE[1] in (REPO / ".ci" / "run").read_text().splitlines()


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def test_the_readme_has_one_line_for_each_command() -> None:
    listed = re.findall(r"^- `haptic-bus ([a-z-]+)`: ", README.read_text(), re.M)
    assert sorted(listed) == sorted(_subcommands(build_parser()))
    assert len(listed) == len(set(listed))


def _parser_for(command: list[str]) -> tuple[argparse.ArgumentParser, list[str]]:
    """The parser that reads ``haptic-bus COMMAND...`` (sim and bench parse their own) and its arguments."""
    if command[:1] == ["sim"]:
        from sim_drive.cli import build_parser as sim_parser

        return sim_parser(), command[1:]
    if command[:1] == ["bench"]:
        from haptic_bus.bench import build_parser as bench_parser

        return bench_parser(), command[1:]
    return build_parser(), command


SHOWN = [(path, command) for path in [README, *PAGES] for command in command_lines(path)]


def test_the_pages_show_commands() -> None:
    assert len(SHOWN) >= 30  # 32 today: the README's 4, the walk-through's 7, the operations' 11, ...
    assert {path.name for path, _ in SHOWN} >= {"README.md", "commissioning.md", "operations.md", "axes.md", "profiles.md"}


@pytest.mark.parametrize(("path", "command"), SHOWN, ids=[f"{p.name}:{' '.join(c)[:60]}" for p, c in SHOWN])
def test_every_command_shown_parses(path: pathlib.Path, command: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    parser, args = _parser_for(command)
    try:
        parser.parse_args(args)
    except SystemExit as done:
        asked = {"--help", "-h", "--version", "--eds-path"} & set(args)
        assert done.code == 0 and asked, f"{path.name}: haptic-bus {' '.join(command)}: {capsys.readouterr().err}"
