"""``haptic-bus profiles`` without its subcommand names the subcommands, not a parser's internal
name (breaker13: "the following arguments are required: profiles_command")."""

from __future__ import annotations

import pytest

from haptic_bus.app.cli import main


def test_profiles_alone_names_its_subcommands(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["profiles", "--x"]) == 2
    err = capsys.readouterr().err
    assert err == "haptic-bus profiles: error: a command is missing; allowed: one of list, show, check, new\n"
