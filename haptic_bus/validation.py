"""Checks that turn user input into validated floats, ints and output folders, or raise ParameterError."""

from __future__ import annotations

import math
import numbers
import os
import pathlib
import tempfile
from collections.abc import Sequence

from haptic_bus.errors import NAMES_SHOWN, ParameterError


def some_names(names: Sequence[str], joiner: str = "+", most: int = NAMES_SHOWN) -> str:
    """``names`` joined by ``joiner``, at most ``most`` of them and the count of the rest
    (``w0+w1+w2 and 2997 more``)."""
    shown = joiner.join(names[:most])
    return shown if len(names) <= most else f"{shown} and {len(names) - most} more"


def real_range(low: float, high: float, unit: str = "", *, low_inclusive: bool = True) -> str:
    """What :func:`real_in_range` allows, as its refusal states it: ``a finite real in [low, high] unit``."""
    bracket = "[" if low_inclusive else "("
    return f"a finite real in {bracket}{low:g}, {high:g}]" + (f" {unit}" if unit else "")


def real_in_range(
    name: str,
    value: object,
    low: float,
    high: float,
    *,
    low_inclusive: bool = True,
    unit: str = "",
    context: str = "",
) -> float:
    """Return ``value`` as a Python float if it is a finite real in the range, else raise.

    ``low``/``high`` bound the range (``high`` always inclusive); ``unit`` only decorates
    the message.
    """
    allowed = real_range(low, high, unit, low_inclusive=low_inclusive)
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ParameterError(name, value, allowed, context)
    number = float(value)
    if not math.isfinite(number):
        raise ParameterError(name, value, allowed, context)
    below = number < low if low_inclusive else number <= low
    if below or number > high:
        raise ParameterError(name, value, allowed, context)
    return number


def whole_in_range(name: str, value: object, low: int, high: int, *, context: str = "") -> int:
    """Return ``value`` as an int if it is a whole number in ``[low, high]``, else raise."""
    allowed = f"an integer in [{low}, {high}]"
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


def ids_in_order(name: str, text: str, what: str, low: int, high: int, *, distinct: bool = False) -> list[int]:
    """The one reader of a list of node or unit ids, for every flag that takes several (``run``/``sim``
    ``--unit-ids``, ``sim --node-ids``, ``scan --node-ids``/``--unit-ids``): ``"5,6,7"`` or ``"5-7"``
    -> [5, 6, 7], in the order given (one per axis; a range ascending): whole numbers in ``low..high``
    (decimal or ``0x..``; ``distinct``: none twice), else ParameterError naming ``name`` and what is
    allowed (``what``: ``"CANopen node ids"``), the same words for every such flag."""
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
    if not ids or (distinct and len(set(ids)) != len(ids)):
        raise ParameterError(name, text, f"{'distinct ' if distinct else ''}{what} {low}..{high} as N, N-M or a "
                                         f"comma-separated list of those, e.g. {low},{low + 1},{low + 2} or {low}-{low + 2}")
    return ids


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
    exist is removed again); ParameterError naming ``name`` otherwise."""
    file = pathlib.Path(path)
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


NOT_YET = "a file that does not exist yet (--force overwrites it)"
"""What a new file's flag allows where the file exists and ``--force`` was not given."""


def new_file(name: str, path: str | os.PathLike[str], force: bool, *, context: str = "") -> pathlib.Path:
    """``path`` as a file a command is about to write, touching nothing: in an existing folder this user
    can write, and one that does not exist yet unless ``force``; ParameterError naming ``name`` otherwise."""
    target = pathlib.Path(path)
    if target.is_dir() or not target.parent.is_dir() or not os.access(target.parent, os.W_OK):
        raise ParameterError(name, str(target), "a file in an existing folder this user can write", context)
    if target.exists() and not force:
        raise ParameterError(name, str(target), NOT_YET, context)
    return target


def _unwritable(folder: pathlib.Path, exc: OSError) -> str:
    """Why ``folder`` cannot be made or written: a file in its way named, else the system's words."""
    for ancestor in (folder, *folder.parents):
        if ancestor.exists():
            return f"{ancestor} is a file, not a folder" if not ancestor.is_dir() else str(exc.strerror)
    return str(exc.strerror)
