"""haptic-bus bench's usage error is one line on stderr, exit 2, as every other command's: an unknown
option printed the bench's three-line usage first."""

from __future__ import annotations

import subprocess
import sys

from haptic_bus.app.arguments import EXIT_INVALID


def test_an_unknown_bench_option_is_one_line_naming_the_command() -> None:
    done = subprocess.run([sys.executable, "-m", "haptic_bus.bench", "--bogus"], capture_output=True, text=True,
                          timeout=60, check=False)
    assert done.returncode == EXIT_INVALID
    assert done.stdout == ""
    assert done.stderr.splitlines() == ["haptic-bus bench: error: unrecognized arguments: --bogus"]
