"""Where a command writes: shown writable before any work (or bus) is begun, else one line and exit 2."""

from __future__ import annotations

import pathlib

from drives.errors import ParameterError


def writable_folder(path: pathlib.Path, option: str, command: str) -> pathlib.Path:
    """``path`` created (with its parents) and probed by writing a file into it; ParameterError
    naming ``option`` and the operating system's reason otherwise."""
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / ".haptic-bus-write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise ParameterError(option, str(path), f"a folder this user can create and write ({_reason(path, exc)})",
                             command) from None
    return path


def writable_file(path: pathlib.Path, option: str, command: str) -> pathlib.Path:
    """``path``'s folder created and the file shown writable (opened for appending; a file that
    did not exist is removed again); ParameterError naming ``option`` otherwise."""
    existed = path.exists()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("ab"):
            pass
        if not existed:
            path.unlink()
    except OSError as exc:
        raise ParameterError(option, str(path), f"a file this user can create and write ({_reason(path.parent, exc)})",
                             command) from None
    return path


def _reason(folder: pathlib.Path, exc: OSError) -> str:
    """Why ``folder`` cannot be made or written: a file in its way named, else the system's words."""
    for ancestor in (folder, *folder.parents):
        if ancestor.exists():
            return f"{ancestor} is a file, not a folder" if not ancestor.is_dir() else str(exc.strerror)
    return str(exc.strerror)
