"""A text file written whole or not at all, and without ``replace`` never over a file already there.

``open(path, "x")`` creates the file exclusively but then writes into it: a full disk or a Ctrl-C during
the write left a truncated profile under the name (``profiles new``, ``identify --write-profile``), which
the next exclusive create then refused to replace.  :func:`write_text_whole` writes a temporary file in
the same folder and only then gives it the name: a hard link (``os.link``, which fails with
FileExistsError if the name is taken: the create stays exclusive), or with ``replace`` a rename over
it (``os.replace``), as ``run.json`` is rewritten (:func:`~haptic_bus.app.run_json.write_json`).
A folder that takes no hard links (FAT, some network mounts: ``os.link`` fails with EPERM or
EOPNOTSUPP) gets the file created exclusively under its name and written there, and removed again if
the write fails: exclusive and whole-or-nothing still, only not hidden from a reader while it is written.
"""

from __future__ import annotations

import errno
import os
import pathlib
import uuid

NO_HARD_LINKS = frozenset({errno.EPERM, errno.EOPNOTSUPP, errno.ENOSYS})  # os.link's errors where a folder takes none


def write_text_whole(path: pathlib.Path, text: str, *, replace: bool = False) -> pathlib.Path:
    """Write ``text`` (UTF-8) to ``path`` whole or not at all; the path written.  Without ``replace`` the
    file is created only if nothing is at ``path`` at that moment: FileExistsError otherwise, and what is
    there is left as it is.  Any failure (OSError, a Ctrl-C) leaves no file at ``path`` that was not there
    before, and no temporary file beside it."""
    temporary = path.with_name(f".{path.name}.{uuid.uuid4().hex}.part")  # a name of its own: two writers never meet
    try:
        with open(temporary, "x", encoding="utf-8") as file:  # mode 0o666 less the umask, as the file itself gets
            file.write(text)
        if replace:
            os.replace(temporary, path)
        else:
            try:
                os.link(temporary, path)
            except OSError as refused:
                if refused.errno not in NO_HARD_LINKS:
                    raise
                _create_whole(path, text)
    finally:
        temporary.unlink(missing_ok=True)
    return path


def _create_whole(path: pathlib.Path, text: str) -> None:
    """``text`` into a file created exclusively at ``path`` (FileExistsError if the name is taken), removed
    again if the write fails: this call made it, so nothing of another writer's is lost."""
    file = open(path, "x", encoding="utf-8")  # noqa: SIM115 -- FileExistsError here is another's file, left as it is
    try:
        with file:  # its close writes the rest, and may fail too
            file.write(text)
    except BaseException:
        path.unlink(missing_ok=True)
        raise
