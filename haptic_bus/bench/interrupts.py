"""Ctrl-C during ``haptic-bus bench``: remembered where the code it lands in swallows it
(:class:`Interrupts`), held back while a child process is started and put where it is stopped
(:func:`sigint_after`), and a section's part that finished kept (:class:`SectionInterrupted`)."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
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


@contextmanager
def sigint_after() -> Iterator[None]:
    """A Ctrl-C (SIGINT, main thread) that comes inside the block acts as soon as the block ends, through
    the handler that was there.  Around ``children.append(subprocess.Popen(...))``: a KeyboardInterrupt
    raised inside ``Popen``, or between its return and the append, once the child runs, left a child that
    no ``finally`` knew of (a host gap probe outlived the bench's ``host_gaps`` call, spinning at
    SCHED_FIFO until its parent-death signal came)."""
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGINT) is None:
        yield  # only the main thread gets Python's SIGINT; a handler not set from Python cannot be put back
        return
    came: list[int] = []
    before = signal.signal(signal.SIGINT, lambda signum, frame: came.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, before)
        if came:
            signal.raise_signal(signal.SIGINT)  # to the handler put back: KeyboardInterrupt, the bench's, or none


@contextmanager
def sigterm_as_sigint() -> Iterator[list[int]]:
    """Inside the block SIGTERM (``kill``, ``timeout``, a service manager's stop) takes Ctrl-C's path: it is
    remembered in the list yielded and raised again as SIGINT, which the bench stops on where it stands,
    its children stopped by the ``finally`` that started them and the sections so far written.  Without
    it SIGTERM's default action ended the bench at once: no bench.json, and the simulated drive of the
    section running left behind with no parent (exit 143)."""
    if threading.current_thread() is not threading.main_thread():
        yield []
        return
    came: list[int] = []

    def on_sigterm(signum: int, frame: object) -> None:
        came.append(signum)
        signal.raise_signal(signal.SIGINT)

    before = signal.signal(signal.SIGTERM, on_sigterm)
    try:
        yield came
    finally:
        signal.signal(signal.SIGTERM, before)
