"""The logging of every command line of the distribution (``haptic-bus``, ``haptic-bus sim``): its
handler, how a command sets it up, and a program's logging kept around a command it calls.

A :class:`logging.StreamHandler` keeps the stream it was given; a command run in-process (a test,
a notebook, the live view's console) may give it a ``sys.stderr`` that is closed by the time a
thread of an earlier command logs, and logging then prints "Logging error" into whatever comes
next.  :class:`StderrHandler` writes to ``sys.stderr`` as it is when each record comes.

A command takes the root logger (:func:`log_to_stderr`) without closing the handlers it finds, as
``logging.basicConfig(force=True)`` would: a program that calls a command in-process (a test, a
notebook, ``haptic_bus.app.cli.main(argv)``) keeps its log file open, and :func:`logging_kept` puts
the program's root handlers and level, and the bus libraries' levels, back as they were.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import threading
from collections.abc import Iterator
from typing import Any

LIBRARIES = ("can", "canopen", "pymodbus", "matplotlib")  # the libraries whose levels a command sets
_State = tuple[list[logging.Handler], int, dict[str, int]]  # root handlers and level, the libraries' levels


class StderrHandler(logging.StreamHandler):
    """Writes each record to the current ``sys.stderr`` (module docstring)."""

    @property
    def stream(self) -> Any:
        """The current ``sys.stderr``."""
        return sys.stderr

    @stream.setter
    def stream(self, value: Any) -> None:
        """Ignored: the stream is always the current ``sys.stderr``."""


def log_to_stderr(level: int, fmt: str) -> None:
    """The root logger at ``level``, its one handler a :class:`StderrHandler` formatting ``fmt``; the
    handlers it had are set aside, not closed (module docstring)."""
    handler = StderrHandler()
    handler.setFormatter(logging.Formatter(fmt))
    root = logging.getLogger()
    root.handlers = [handler]
    root.setLevel(level)


def _state() -> _State:
    root = logging.getLogger()
    return root.handlers[:], root.level, {name: logging.getLogger(name).level for name in LIBRARIES}


def _put_back(state: _State) -> None:
    handlers, level, levels = state
    root = logging.getLogger()
    root.handlers = handlers[:]
    root.setLevel(level)
    for name, library_level in levels.items():
        logging.getLogger(name).setLevel(library_level)


class _Calls:
    """The commands a program is calling (threads, or one nested in another), and the program's own
    logging, which the first of them found."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.running = 0
        self.program: _State = _state()


_calls = _Calls()


@contextlib.contextmanager
def logging_kept() -> Iterator[None]:
    """For a command a program calls: the root logger's handlers and level, and the :data:`LIBRARIES`'
    levels, put back when the block ends; the command's handlers are closed, the program's never.  A
    call that ends while others run puts back what it found (a nested call's caller has its logging
    again), the last to end what the first found."""
    with _calls.lock:
        found = _state()
        if not _calls.running:
            _calls.program = found
        _calls.running += 1
        logging.getLogger().handlers = []
    try:
        yield
    finally:
        with _calls.lock:
            _calls.running -= 1
            state = found if _calls.running else _calls.program
            kept = {id(handler) for handler in [*state[0], *_calls.program[0]]}
            for handler in {id(handler): handler for handler in [*logging.getLogger().handlers, *found[0]]}.values():
                if id(handler) not in kept:
                    handler.close()
            _put_back(state)
