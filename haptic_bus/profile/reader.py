"""Reading one table of a profile's TOML document: typed fields whose errors name the file, the
dotted field, the value and the allowed range, and a check that no key was left unread (a typo
is an error, not a silent default).  A required key that is missing beside a key nobody read
whose name is close to it (``force_limt`` for ``force_limit``) is reported as that misspelling
("no such key; did you mean force_limit?"), not as a missing value the user did write.

A reader may be given ``silent``: defaults for required keys its caller lets be left out (the
simulated drive's view of a profile, which runs a bare ``[device]`` with its own defaults); a
default goes through the same check as a written value."""

from __future__ import annotations

import difflib
import pathlib
import re
import tomllib
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from haptic_bus.analysis.velocity import ALLOWED as VELOCITY_MODELS
from haptic_bus.analysis.velocity import VelocityModel
from haptic_bus.errors import ParameterError
from haptic_bus.validation import real_in_range, real_range, whole_in_range

NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
"""A name in a profile (the profile's, an object's, an axis'): letters, digits, '.', '_', '-', not starting with '.', '_', '-'."""

REQUIRED = object()
"""The default of a field that must be given."""

MISSPELLING_CUTOFF = 0.8
"""How alike (difflib's ratio, 0..1) an unread key and a missing required key must be for the
first to be named as a misspelling of the second: ``force_limt``/``force_limit`` 0.95, ``mas``/``mass``
0.86; two distinct keys of one table (``timing``/``delay``, ``stiffness``/``damping``) stay far below."""


def profile_error(path: pathlib.Path | str, field: str, value: object, allowed: str) -> ParameterError:
    """The error for an invalid field of the profile file at ``path``: ``field`` (dotted, e.g.
    ``scene.objects[2].stiffness``) is its ``name``, ``profile PATH`` its ``context``."""
    return ParameterError(field, value, allowed, context=f"profile {path}")


MAX_NESTING = 16
"""How deep a profile's tables and arrays may nest: the deepest a profile uses is 4 (``space.operator.toward``,
an array of points in a table in a table); tomllib parses recursively, and a document nested some hundreds
deep (``b = [[[[...]]]]``) exhausted Python's recursion limit in the parser or in the error's ``repr``: a
traceback, exit 1, where a malformed file is one line, exit 2."""


def read_document(path: pathlib.Path) -> dict[str, Any]:
    """The TOML document of a profile file; ParameterError when unreadable, not TOML, or nested deeper
    than :data:`MAX_NESTING`."""
    try:
        with open(path, "rb") as file:
            document = tomllib.load(file)
    except OSError as error:
        raise profile_error(path, "profile", str(path), f"a readable file ({error.strerror})") from None
    except tomllib.TOMLDecodeError as error:
        raise profile_error(path, "(TOML syntax)", str(error), "valid TOML 1.0") from None
    except UnicodeDecodeError as error:  # TOML is UTF-8 text
        raise profile_error(path, "(encoding)", f"byte 0x{error.object[error.start]:02X} at {error.start}",
                            "UTF-8 text (TOML 1.0)") from None
    except RecursionError:  # the parser recursed per nested array or inline table
        raise profile_error(path, "(nesting)", "deeper than the TOML parser can follow",
                            f"tables and arrays nested at most {MAX_NESTING} deep") from None
    _refuse_deep_nesting(path, document)
    return document


def _refuse_deep_nesting(path: pathlib.Path, document: dict[str, Any]) -> None:
    """ParameterError naming where (its first two levels, dotted) a value nests deeper than
    :data:`MAX_NESTING`; walked without recursion, so that the walk itself cannot exhaust the stack."""
    stack: list[tuple[str, object, int]] = [(str(key), value, 1) for key, value in document.items()]
    while stack:
        where, value, depth = stack.pop()
        if depth > MAX_NESTING:
            raise profile_error(path, "(nesting)", f"{where}...: more than {MAX_NESTING} levels",
                                f"tables and arrays nested at most {MAX_NESTING} deep")
        if isinstance(value, dict):
            stack.extend((f"{where}.{key}" if depth < 2 else where, item, depth + 1) for key, item in value.items())
        elif isinstance(value, list):
            stack.extend((f"{where}[{i}]" if depth < 2 else where, item, depth + 1) for i, item in enumerate(value))


def misspelling(key: str, keys: Iterable[object]) -> str | None:
    """The one of ``keys`` (a table's keys) that looks like a misspelling of the missing ``key``
    (:data:`MISSPELLING_CUTOFF`), or None."""
    close = difflib.get_close_matches(key, [k for k in keys if isinstance(k, str) and k != key], n=1,
                                      cutoff=MISSPELLING_CUTOFF)
    return close[0] if close else None


def refuse_duplicates(path: pathlib.Path, where: str, key: str, values: Iterable[object]) -> None:
    """ParameterError naming the field ``where[i].key`` of the first of ``values`` (one an entry of the
    array of tables ``where``; None: no value) that an earlier entry has, and that entry's field."""
    seen: dict[object, int] = {}
    for i, value in enumerate(values):
        if value is not None and value in seen:
            raise profile_error(path, f"{where}[{i}].{key}", value,
                                f"a {key} no other entry uses ({where}[{seen[value]}].{key} has it)")
        seen[value] = i


class Reader:
    """Reads one table of the document, tracking which keys were used (typo protection)."""

    def __init__(self, path: pathlib.Path, prefix: str, table: object, silent: Mapping[str, object] | None = None) -> None:
        self.path, self.prefix = path, prefix
        if not isinstance(table, dict):
            raise profile_error(path, prefix, table, "a TOML table")
        self.table = table
        self.silent: Mapping[str, object] = silent or {}
        self.used: set[str] = set()

    def field(self, key: str) -> str:
        return f"{self.prefix}.{key}" if self.prefix else key

    def raw(self, key: str, allowed: str, default: object = REQUIRED) -> object:
        self.used.add(key)
        if key not in self.table:
            default = self.silent.get(key, REQUIRED) if default is REQUIRED else default
            if default is REQUIRED:
                self.refuse_misspelling(key, allowed)
                raise profile_error(self.path, self.field(key), None, allowed)  # "KEY is missing; allowed: ..."
            return default
        return self.table[key]

    def refuse_misspelling(self, key: str, allowed: str) -> None:
        """Refuse an unread key of the table that looks like the missing required ``key`` (module docstring);
        ``allowed`` says what ``key`` takes."""
        close = misspelling(key, (k for k in self.table if k not in self.used))
        if close is not None:
            raise profile_error(self.path, self.field(close), self.table[close],
                                f"no such key; did you mean {key}? ({key} is required: {allowed})")

    def _wrap(self, key: str, check: Callable[[object], Any], value: object) -> Any:
        try:
            return check(value)
        except ParameterError as error:
            raise profile_error(self.path, self.field(key), value, error.allowed) from None

    def real(self, key: str, low: float, high: float, unit: str, *, low_inclusive: bool = True,
             default: object = REQUIRED) -> float:
        allowed = real_range(low, high, unit, low_inclusive=low_inclusive)
        value = self.raw(key, allowed, default)
        return self._wrap(key, lambda v: real_in_range(key, v, low, high, low_inclusive=low_inclusive, unit=unit), value)

    def whole(self, key: str, low: int, high: int, default: object = REQUIRED, *, allowed: str = "") -> int:
        allowed = allowed or f"an integer in [{low}, {high}]"  # a node or unit id: its table's words
        value = self.raw(key, allowed, default)
        if isinstance(value, float):  # TOML distinguishes 3000 from 3000.0; a count is an integer
            raise profile_error(self.path, self.field(key), value, allowed)
        return self._wrap(key, lambda v: whole_in_range(key, v, low, high, allowed=allowed), value)

    def flag(self, key: str, default: object = REQUIRED) -> bool:
        value = self.raw(key, "true or false", default)
        if not isinstance(value, bool):
            raise profile_error(self.path, self.field(key), value, "true or false")
        return value

    def text(self, key: str, *, pattern: re.Pattern | None = None, choices: tuple[str, ...] = (),
             default: object = REQUIRED) -> str:
        allowed = (" or ".join(repr(c) for c in choices) if choices
                   else "a name of letters, digits, '.', '_', '-'" if pattern else "a non-empty string")
        value = self.raw(key, allowed, default)
        ok = isinstance(value, str) and value.strip() != ""
        ok = ok and (not choices or value in choices) and (pattern is None or bool(pattern.match(value)))
        if not ok:
            raise profile_error(self.path, self.field(key), value, allowed)
        return value  # type: ignore[return-value]  # checked: a str

    def velocity_model(self, key: str, default: object = REQUIRED) -> VelocityModel:
        """A velocity model string (``"point"``, ``"average"``, ``"window:S"``, ``"lowpass:S"``)."""
        value = self.raw(key, f"the model of the drive's 0x606C: {VELOCITY_MODELS}; most drives report "
                              "'average' (an encoder difference over the cycle); 'point' only for a drive "
                              "documented to sample its velocity at SYNC", default)
        return self._wrap(key, VelocityModel.parse, value)

    def done(self) -> None:
        """Refuse the first key no field read (a typo), listing the keys that were read."""
        self.only(self.used)

    def only(self, keys: Iterable[str]) -> None:
        """Refuse the first key of the table not among ``keys`` (a typo), listing ``keys``; run before
        reading, it names a misspelt table ahead of the required one it hides."""
        allowed = set(keys)
        unknown = [k for k in self.table if k not in allowed]
        if unknown:
            raise profile_error(self.path, self.field(unknown[0]), self.table[unknown[0]],
                                f"no such key; keys of [{self.prefix or 'top level'}]: {', '.join(sorted(allowed))}")
