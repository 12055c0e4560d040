"""The pytest plugin's example as the README shows it (not a test module): the test files run this text.

The block is the first ```python block after the README's marker line, so the README cannot
drift from what the tests run.
"""

from __future__ import annotations

import pathlib

REPO = pathlib.Path(__file__).resolve().parents[1]
MARKER = "<!-- plugin example:"
FENCE_OPEN, FENCE_CLOSE = "```python\n", "\n```"


def readme_plugin_example() -> str:
    """The README's plugin example, as a test file's text."""
    text = (REPO / "README.md").read_text()
    after = text[text.index(MARKER):]
    start = after.index(FENCE_OPEN) + len(FENCE_OPEN)
    return after[start:after.index(FENCE_CLOSE, start)] + "\n"
