"""haptic-bus bench's usage error is one line on stderr, exit 2, as every other command's: an unknown
option printed the bench's three-line usage first."""

from __future__ import annotations

import pytest

from haptic_bus.app.arguments import EXIT_INVALID
from haptic_bus.bench import main


def test_an_unknown_bench_option_is_one_line_naming_the_command(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--bogus"]) == EXIT_INVALID
    out, err = capsys.readouterr()
    assert out == "" and err.splitlines() == ["haptic-bus bench: error: unrecognized arguments: --bogus"]
