"""The console blocks of the manual's pages as a user types them: each ``$ `` command with the output the
page shows for it, and one bash that runs them in turn (not a test module).

The bash runs this tree's ``haptic_bus`` (``PYTHONPATH``) and this interpreter's ``haptic-bus``
(``PATH``), its stderr merged into stdout, in a session of its own that :meth:`Shell.close` ends.
"""

from __future__ import annotations

import os
import pathlib
import re
import select
import signal
import subprocess
import sys
import time
from dataclasses import dataclass

REPO = pathlib.Path(__file__).resolve().parents[1]


def user_env() -> dict[str, str]:
    """This environment, with this tree's ``haptic_bus`` and this interpreter's ``haptic-bus`` first."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    env["PATH"] = os.pathsep.join([str(pathlib.Path(sys.executable).parent), env.get("PATH", "")])
    return env


@dataclass(frozen=True)
class Command:
    """One command of a console block as typed (continuation lines and a here-document included) and
    the output the page shows for it."""

    text: str
    shown: str


def console_commands(page: str) -> list[Command]:
    """Every ``$ `` command of the page's ``console`` blocks, in order."""
    commands: list[Command] = []
    for block in re.findall(r"```console\n(.*?)```", page, re.S):
        lines = block.splitlines()
        i = 0
        while i < len(lines):
            if not lines[i].startswith("$ "):
                raise AssertionError(f"console block: output before any command: {lines[i]!r}")
            typed = [lines[i][2:]]
            while typed[-1].endswith("\\"):
                i += 1
                typed.append(lines[i])
            heredoc = re.search(r"<<'?(\w+)'?", typed[0])
            if heredoc:
                while lines[i] != heredoc.group(1):
                    i += 1
                    typed.append(lines[i])
            i += 1
            shown = []
            while i < len(lines) and not lines[i].startswith("$ "):
                shown.append(lines[i])
                i += 1
            commands.append(Command("\n".join(typed), "\n".join(shown)))
    return commands


class Shell:
    """One bash, its stderr merged into stdout, fed command by command as a user types them."""

    def __init__(self, cwd: pathlib.Path) -> None:
        self.process = subprocess.Popen(["bash", "--norc", "--noprofile"], cwd=cwd, env=user_env(), stdin=subprocess.PIPE,
                                        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)
        self._pending = b""
        self.type("exec 2>&1", 10)

    def type(self, text: str, limit: float) -> tuple[int, str]:
        """Run ``text``; its exit status and output, within ``limit`` s (else the test fails)."""
        assert self.process.stdin is not None and self.process.stdout is not None
        marker = f"__exit_status_{time.monotonic_ns()}__"
        self.process.stdin.write(f"{text}\necho \"{marker}$?\"\n".encode())
        self.process.stdin.flush()
        deadline = time.monotonic() + limit
        pattern = re.compile(rf"{marker}(\d+)\n".encode())
        while (found := pattern.search(self._pending)) is None:
            left = deadline - time.monotonic()
            if left <= 0 or self.process.poll() is not None:
                raise AssertionError(f"{text!r} did not finish within {limit} s: {self._pending.decode(errors='replace')}")
            ready, _, _ = select.select([self.process.stdout], [], [], min(left, 1.0))
            if ready:
                self._pending += os.read(self.process.stdout.fileno(), 65536)
        output, self._pending = self._pending[:found.start()], self._pending[found.end():]
        return int(found.group(1)), output.decode(errors="replace")

    def close(self) -> None:
        """End the shell and everything it started that is still there (its own session)."""
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGKILL)
        self.process.wait(10)
        for pipe in (self.process.stdin, self.process.stdout):
            if pipe is not None:
                pipe.close()  # wait() leaves them open: their collection would be an unraisable ResourceWarning
