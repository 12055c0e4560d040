"""A simulator made of parts that start and stop (a bus bridge, CANopen nodes, Modbus servers): all or none.

:func:`start_all` starts the parts in order and, if one fails, stops those that started, newest
first, before the error is raised; :func:`stop_all` stops them newest first, the reverse of the
start (a bus is started before the nodes on it and stopped after them).
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from typing import Protocol


class Part(Protocol):
    """A part of a simulator: ``start()`` serves (its result unused), ``stop()`` ends it."""

    def start(self) -> object: ...

    def stop(self) -> None: ...


def start_all(parts: Sequence[Part]) -> None:
    """Start ``parts`` in order; if one fails, stop those that started (newest first) and raise."""
    with contextlib.ExitStack() as started:
        for part in parts:
            part.start()
            started.callback(part.stop)
        started.pop_all()


def stop_all(parts: Sequence[Part]) -> None:
    """Stop ``parts`` newest first."""
    for part in reversed(parts):
        part.stop()
