"""The code blocks of the README and the manual's pages, and the command lines they show (not a test module).

A block is a fenced block of a Markdown page (```` ```python ````, ```` ```bash ````, ```` ```console ````);
a command line is one ``haptic-bus`` invocation of a bash or console block, its continuation lines
joined, cut at the first shell operator (``&``, ``|``, ``;``, a redirection).
"""

from __future__ import annotations

import pathlib
import re
import shlex

REPO = pathlib.Path(__file__).resolve().parents[1]
README = REPO / "README.md"
PAGES = sorted((REPO / "docs").glob("*.md"))
SHELL_OPERATORS = {"&", "&&", "|", "||", ";", ">", "2>", ">>", "<", "<<"}


def code_blocks(path: pathlib.Path, language: str) -> list[str]:
    """The ``language`` blocks of the page at ``path``, in order, each without its fences."""
    return re.findall(rf"^```{language}\n(.*?)^```$", path.read_text(), re.S | re.M)


def command_lines(path: pathlib.Path) -> list[list[str]]:
    """Every ``haptic-bus`` command of the page's bash and console blocks, as its arguments after
    ``haptic-bus``; a console block's commands are its ``$ `` lines, and ``$NAME`` is what the
    page's text sets it to (``NAME="..."``)."""
    text = path.read_text()
    variables = dict(re.findall(r'`([A-Z]+)="([^"]*)"`', text))
    commands = []
    for language in ("bash", "console"):
        for block in code_blocks(path, language):
            lines = block.replace("\\\n", " ").splitlines()
            if language == "console":
                lines = [line[2:] for line in lines if line.startswith("$ ")]
            for line in lines:
                for name, value in variables.items():
                    line = line.replace(f"${name}", value)
                words = shlex.split(line, comments=True)
                for start in (i for i, word in enumerate(words) if word == "haptic-bus"):
                    command = []
                    for word in words[start + 1:]:
                        if word in SHELL_OPERATORS or word.startswith(("2>", ">")):
                            break
                        command.append(word)
                    commands.append(command)
    return commands
