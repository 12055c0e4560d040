"""Ctrl-C during ``haptic-bus bench``: remembered where the code it lands in swallows it
(:class:`Interrupts`), and a section's part that finished kept (:class:`SectionInterrupted`)."""

from __future__ import annotations

import signal
import threading
from typing import Any


class SectionInterrupted(KeyboardInterrupt):
    """Ctrl-C in a section that keeps what it finished (``haptic-bus run`` after ``haptic-bus run``):
    ``section`` is its part of ``bench.json`` so far, written as the others are."""

    def __init__(self, section: dict) -> None:
        super().__init__()
        self.section = section


class Interrupts:
    """Remembers a Ctrl-C (SIGINT, main thread only) even where the code it lands in swallows the
    ``KeyboardInterrupt`` (a controller run ends "interrupted" and returns), so the run stops at the
    section's next progress step."""

    def __init__(self) -> None:
        self.seen = False
        self._previous: Any = None

    def __enter__(self) -> Interrupts:
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._on_sigint)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)

    def _on_sigint(self, signum: int, frame: object) -> None:
        self.seen = True
        raise KeyboardInterrupt

    def check(self) -> None:
        """Raise ``KeyboardInterrupt`` if a Ctrl-C came."""
        if self.seen:
            raise KeyboardInterrupt
