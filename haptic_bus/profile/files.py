"""Where profiles live: the shipped ones (the ``profiles`` package) by name, any other by path."""

from __future__ import annotations

import importlib.resources
import os
import pathlib

from haptic_bus.errors import ParameterError
from haptic_bus.profile.reader import profile_error, read_document

DEFAULT_PROFILE = "cia402-handle"
"""The shipped profile a command takes when none is named (``haptic-bus demo``, ``profiles show``)."""


def _profiles_folder() -> pathlib.Path:
    return pathlib.Path(str(importlib.resources.files("profiles")))


def shipped_profiles(axes: bool = False) -> dict[str, pathlib.Path]:
    """The one-axis profiles shipped in the ``profiles`` package (``axes``: the multi-axis ones,
    those with ``[[axes]]``): name (file stem) -> path, sorted."""
    return {p.stem: p for p in sorted(_profiles_folder().glob("*.toml")) if ("axes" in read_document(p)) == axes}


def resolve_profile(path_or_name: str | pathlib.Path) -> pathlib.Path:
    """The file of a shipped profile name, or ``path_or_name`` as a path if it is one; ParameterError if neither
    (also for what is neither text nor a path: ``hb.load_profile(5)`` was pathlib's TypeError)."""
    if path_or_name is None:  # nothing given: 'profile is missing', no 'profile None:' before it
        raise ParameterError("profile", None, "a shipped profile name or a TOML file's path (str or pathlib.Path)")
    if not isinstance(path_or_name, (str, os.PathLike)) or isinstance(os.fspath(path_or_name), bytes):
        raise profile_error(repr(path_or_name), "profile", path_or_name,
                            "a shipped profile name or a TOML file's path (str or pathlib.Path)")
    candidate = pathlib.Path(path_or_name)
    if _is_file(candidate):
        return candidate
    if isinstance(path_or_name, str) and pathlib.Path(path_or_name).name == path_or_name:  # a name, not a path
        shipped_file = _profiles_folder() / f"{path_or_name}.toml"  # found without reading every shipped profile
        if _is_file(shipped_file):
            return shipped_file
    shipped = {**shipped_profiles(), **shipped_profiles(axes=True)}
    allowed = f"an existing TOML file or a shipped profile name: {', '.join(shipped) or 'none'}"
    if not os.fspath(path_or_name):  # '': no 'profile :' before it
        raise ParameterError("profile", "", allowed)
    raise profile_error(path_or_name, "profile", str(path_or_name), allowed)


def _is_file(path: pathlib.Path) -> bool:
    """Whether ``path`` is a file; not when the system cannot say (a name too long for a file, a folder
    it may not search), which :meth:`pathlib.Path.is_file` raises as OSError."""
    try:
        return path.is_file()
    except OSError:
        return False
