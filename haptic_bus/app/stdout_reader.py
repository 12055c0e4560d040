"""stdout whose reader may go: ``haptic-bus run ... | head -3`` closes the pipe while the run goes on.

A ``print`` to a pipe nobody reads any more raises BrokenPipeError where it happens; during a run that
was in the middle of its set-up (the scaling lines, pre-flight's line), so the run ended "crashed" with
nothing enabled and nothing recorded, and the console script said nothing and exited 0.  The console
script's stdout is :class:`ReaderMayGo`: the first write or flush that meets the closed pipe points
the process' descriptor at /dev/null, and every command goes on to its end, its files and its exit
status its own.  A program calling :func:`haptic_bus.app.cli.main` keeps its own stdout.
"""

from __future__ import annotations

import io
import os
from typing import TextIO


class ReaderMayGo(io.TextIOBase):
    """``stream`` (a text stream with a descriptor) until its reader goes, then nothing (module docstring)."""

    def __init__(self, stream: TextIO) -> None:
        super().__init__()
        self.stream = stream

    def write(self, text: str) -> int:
        """``text`` written, or dropped once the reader has gone; its length either way."""
        try:
            return self.stream.write(text)
        except BrokenPipeError:
            self._gone()
            return len(text)

    def flush(self) -> None:
        """The stream flushed (into /dev/null once the reader has gone)."""
        try:
            self.stream.flush()
        except BrokenPipeError:
            self._gone()
            self.stream.flush()  # what it still held goes where the descriptor now points

    def _gone(self) -> None:
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(devnull, self.stream.fileno())
        finally:
            os.close(devnull)

    def fileno(self) -> int:
        """The stream's descriptor."""
        return self.stream.fileno()

    def isatty(self) -> bool:
        """Whether the stream is a terminal."""
        return self.stream.isatty()

    @property
    def encoding(self) -> str:  # type: ignore[override]
        """The stream's encoding."""
        return self.stream.encoding
