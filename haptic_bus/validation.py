"""Checks that turn user input into validated floats, ints and output folders, or raise ParameterError.

A real in a range is checked by :func:`real_in_range` (and said by :func:`real_range`), re-exported from
:mod:`drives.ranges`: ``drives`` is the bottom layer, and its own checks (a scan's time budget) share it."""

from __future__ import annotations

import math
import numbers
import os
import pathlib
import tempfile
from collections.abc import Sequence
from typing import TypeVar

from drives.ranges import real_in_range as real_in_range
from drives.ranges import real_range as real_range
from haptic_bus.errors import NAMES_SHOWN, ParameterError

T = TypeVar("T")


def some_names(names: Sequence[str], joiner: str = "+", most: int = NAMES_SHOWN) -> str:
    """``names`` joined by ``joiner``, at most ``most`` of them and the count of the rest
    (``w0+w1+w2 and 2997 more``)."""
    shown = joiner.join(names[:most])
    return shown if len(names) <= most else f"{shown} and {len(names) - most} more"


def whole_in_range(name: str, value: object, low: int, high: int, *, context: str = "", allowed: str = "") -> int:
    """Return ``value`` as an int if it is a whole number in ``[low, high]``, else raise, saying ``allowed``
    (default ``an integer in [low, high]``; a node or unit id: its table's words, ``CANopen node ids 1..127``)."""
    allowed = allowed or f"an integer in [{low}, {high}]"
    if isinstance(value, bool):
        raise ParameterError(name, value, allowed, context)
    if isinstance(value, numbers.Integral):
        whole = int(value)
    elif isinstance(value, numbers.Real) and math.isfinite(float(value)) and float(value).is_integer():
        whole = int(float(value))
    else:
        raise ParameterError(name, value, allowed, context)
    if not low <= whole <= high:
        raise ParameterError(name, value, allowed, context)
    return whole


def ids_in_order(name: str, text: str, allowed: str, low: int, high: int, *, distinct: bool = False) -> list[int]:
    """The one reader of a list of node or unit ids, for every flag that takes several (``run``/``sim``
    ``--unit-ids``, ``sim --node-ids``, ``scan --node-ids``/``--unit-ids``): ``"5,6,7"`` or ``"5-7"``
    -> [5, 6, 7], in the order given (one per axis; a range ascending): whole numbers in ``low..high``
    (decimal or ``0x..``; ``distinct``: none twice), else ParameterError naming ``name`` and what is
    ``allowed`` (its table's words, ``"CANopen node ids 1..127"``), the same for every such flag; an id
    given twice where they must be distinct is named (``--node-ids = '5-7,6' is invalid; allowed: distinct
    CANopen node ids 1..127 (6 is given twice)``)."""
    ids: list[int] = []
    for part in text.split(","):
        first, dash, last = part.strip().partition("-")
        try:
            start, stop = int(first, 0), int(last if dash else first, 0)
        except ValueError:
            ids = []
            break
        if not low <= start <= stop <= high:  # the bounds before the range is listed: 1-10**12 is no list
            ids = []
            break
        ids.extend(range(start, stop + 1))
    if not ids:
        raise ParameterError(name, text, f"{'distinct ' if distinct else ''}{allowed} as N, N-M or a "
                                         f"comma-separated list of those, e.g. {low},{low + 1},{low + 2} or {low}-{low + 2}")
    repeated = next((each for i, each in enumerate(ids) if each in ids[:i]), None) if distinct else None
    if repeated is not None:
        raise ParameterError(name, text, f"distinct {allowed} ({repeated} is given twice)")
    return ids


def typed_repeat(values: Sequence[T]) -> tuple[T, str]:
    """What a refusal of a repeatable option's ``values`` (in the order typed, at least one) shows: one
    value as typed, not the list they read as (the first typed more than once, else the last), and how
    often (``given twice``; ``3 given, this one twice``; ``2 given, this one last``)."""
    again = next((value for value in values if values.count(value) > 1), None)
    if again is None:
        return values[-1], f"{len(values)} given, this one last"
    times = {2: "twice"}.get(values.count(again), f"{values.count(again)} times")
    return again, f"given {times}" if values.count(again) == len(values) else f"{len(values)} given, this one {times}"


def one_or_one_each(name: str, values: Sequence[object], size: int, each: str, *, context: str = "") -> None:
    """Nothing if a repeatable option's ``values`` (``--modbus``: as typed) are one for every ``each``
    (``"axis"``, ``"unit"``) or one per ``each`` (``size`` of them); else ParameterError naming ``name``,
    one value as typed (:func:`typed_repeat`) and the count: ``run`` and ``sim`` say it alike
    (``--modbus = 'tcp://127.0.0.1:5021' is invalid; allowed: one for every axis, or one per axis
    (3 axes; given twice)``)."""
    if len(values) not in (1, size):
        shown, given = typed_repeat(values)
        many = each if size == 1 else {"axis": "axes"}.get(each, f"{each}s")
        raise ParameterError(name, shown, f"one for every {each}, or one per {each} ({size} {many}; {given})", context)


def folder_path(name: str, path: str | os.PathLike[str], *, context: str = "") -> pathlib.Path:
    """``path`` as a folder's path, touching nothing; ParameterError naming ``name`` if it is empty
    (an empty string is no folder, not the current one)."""
    if not os.fspath(path):
        raise ParameterError(name, "", "a folder path (empty: none given)", context)
    return pathlib.Path(path)


def writable_folder(name: str, path: str | os.PathLike[str], *, context: str = "") -> pathlib.Path:
    """``path`` as a folder this user can write, created (with its parents) if missing and probed with a
    file now, before any work that would write there; ParameterError naming ``name`` otherwise (a file
    in the way named, else the system's reason)."""
    folder = folder_path(name, path, context=context)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        descriptor, probe = tempfile.mkstemp(prefix=".haptic-bus-write-test-", dir=folder)  # a name of its own: two
        os.close(descriptor)  # commands probing one folder at once unlinked each other's (No such file or directory)
        os.unlink(probe)
    except OSError as exc:
        raise ParameterError(name, str(folder), f"a folder this user can create and write ({_unwritable(folder, exc)})",
                             context) from None
    return folder


def writable_file(name: str, path: str | os.PathLike[str], *, context: str = "") -> pathlib.Path:
    """``path``'s folder created and the file shown writable (opened for appending; a file that did not
    exist is removed again), a regular file (:func:`_regular_or_none`); ParameterError naming ``name`` otherwise."""
    file = pathlib.Path(path)
    _regular_or_none(name, file, context)  # before it is opened: a pipe's open waited for a reader, for ever
    existed = file.exists()
    try:
        file.parent.mkdir(parents=True, exist_ok=True)
        with file.open("ab"):
            pass
        if not existed:
            file.unlink()
    except OSError as exc:
        raise ParameterError(name, str(file), f"a file this user can create and write ({_unwritable(file.parent, exc)})",
                             context) from None
    return file


def _regular_or_none(name: str, file: pathlib.Path, context: str) -> None:
    """ParameterError naming ``name`` if ``file`` is a device, a pipe or a socket: a command writes its file beside
    it and renames it over the name, which put a regular file where a device was (``haptic-bus region --png
    /dev/null`` or ``profiles new --out /dev/null --force`` run as root)."""
    if file.is_char_device() or file.is_block_device() or file.is_fifo() or file.is_socket():
        raise ParameterError(name, str(file), "a regular file or none (not a device, a pipe or a socket)", context)


NOT_YET = "a file that does not exist yet (--force overwrites it)"
"""What a new file's flag allows where the file exists and ``--force`` was not given."""


def new_file(name: str, path: str | os.PathLike[str], force: bool, *, context: str = "") -> pathlib.Path:
    """``path`` (not empty) as a file a command is about to write, touching nothing: in an existing folder this user
    can write, a regular file (:func:`_regular_or_none`), and one that does not exist yet unless ``force``;
    ParameterError naming ``name`` otherwise."""
    if not os.fspath(path):  # pathlib reads '' as '.', the current folder
        raise ParameterError(name, "", "a file's path (empty: none given)", context)
    target = pathlib.Path(path)
    if target.is_dir() or not target.parent.is_dir() or not os.access(target.parent, os.W_OK):
        raise ParameterError(name, str(target), "a file in an existing folder this user can write", context)
    _regular_or_none(name, target, context)
    if target.exists() and not force:
        raise ParameterError(name, str(target), NOT_YET, context)
    return target


def _unwritable(folder: pathlib.Path, exc: OSError) -> str:
    """Why ``folder`` cannot be made or written: a file in its way named, else the system's words."""
    for ancestor in (folder, *folder.parents):
        if ancestor.exists():
            return f"{ancestor} is a file, not a folder" if not ancestor.is_dir() else str(exc.strerror)
    return str(exc.strerror)
