"""The arguments both bus scans (:mod:`drives.canopen.scan`, :mod:`drives.modbus.scan`) check
before they touch a bus: a set of ids in a range, and a time budget."""

from __future__ import annotations

from collections.abc import Iterable

from drives.errors import ParameterError
from drives.ranges import real_in_range

MAX_SECONDS = 3600.0
DEFAULT_TIMEOUT = 1.0  # s: CANopen: the listening window after the probe; Modbus: no new unit started after it
DEFAULT_ANSWER_TIMEOUT = 0.1  # s: each SDO read (CANopen) or request (Modbus)


def checked_ids(name: str, ids: Iterable[int], allowed: str, low: int, high: int) -> list[int]:
    """``ids`` sorted without repeats; ParameterError naming ``name`` and ``allowed`` (its table's words,
    ``CANopen node ids 1..127``) if empty or any is outside ``low..high``."""
    found = sorted(set(ids))
    bad = [i for i in found if isinstance(i, bool) or not isinstance(i, int) or not low <= i <= high]
    if bad or not found:
        raise ParameterError(name, bad or found, f"one or more {allowed}", "scan")
    return found


def checked_seconds(name: str, value: float) -> float:
    """A time in (0, :data:`MAX_SECONDS`] s as float; ParameterError naming ``name`` otherwise, in the words of
    every range check (:func:`~drives.ranges.real_in_range`), as the command line's ``--timeout`` says it."""
    return real_in_range(name, value, 0.0, MAX_SECONDS, low_inclusive=False, unit="s", context="scan")
