"""The log handler every command line of the distribution uses (``haptic-bus``, ``haptic-bus sim``).

A :class:`logging.StreamHandler` keeps the stream it was given; a command run in-process (a test,
a notebook, the live view's console) may give it a ``sys.stderr`` that is closed by the time a
thread of an earlier command logs, and logging then prints "Logging error" into whatever comes
next.  :class:`StderrHandler` writes to ``sys.stderr`` as it is when each record comes.
"""

from __future__ import annotations

import logging
import sys
from typing import Any


class StderrHandler(logging.StreamHandler):
    """Writes each record to the current ``sys.stderr`` (module docstring)."""

    @property
    def stream(self) -> Any:
        """The current ``sys.stderr``."""
        return sys.stderr

    @stream.setter
    def stream(self, value: Any) -> None:
        """Ignored: the stream is always the current ``sys.stderr``."""
