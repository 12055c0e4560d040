"""A text file written whole or not at all, and without ``replace`` never over a file already there.

``open(path, "x")`` creates the file exclusively but then writes into it: a full disk or a Ctrl-C during
the write left a truncated profile under the name (``profiles new``, ``identify --write-profile``), which
the next exclusive create then refused to replace.  :func:`write_text_whole` writes a temporary file in
the same folder and only then gives it the name: a hard link (``os.link``, which fails with
FileExistsError if the name is taken: the create stays exclusive), or with ``replace`` a rename over
it (``os.replace``), as ``run.json`` is rewritten (:func:`~haptic_bus.app.run_json.write_json`).
"""

from __future__ import annotations

import os
import pathlib
import uuid


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
            os.link(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)
    return path
