"""``run.json``: its name in a run folder, writing it whole or not at all, and reading it back.

Apart from :mod:`~haptic_bus.app.run_folder` (which builds the document) so that the run's writer
process (:mod:`~haptic_bus.app.writer_process`), which rewrites the file as events come, imports
the standard library only for it, not the profiles, the gates and the analysis the document is
made from.
"""

from __future__ import annotations

import json
import os
import pathlib
from typing import Any

RUN_JSON = "run.json"


def write_json(path: pathlib.Path, document: dict[str, Any]) -> pathlib.Path:
    """Write ``document`` to ``path`` whole or not at all (a temporary file renamed over it), so a
    process killed meanwhile leaves the previous version, never half of one."""
    temporary = path.with_name(f".{path.name}.tmp")
    try:
        temporary.write_text(json.dumps(document, indent=1) + "\n")
    except OSError:  # a full disk: no half-written temporary left beside the last whole version
        temporary.unlink(missing_ok=True)
        raise
    os.replace(temporary, path)
    return path


def read_document(folder: pathlib.Path) -> dict[str, Any]:
    """The ``run.json`` of the run folder ``folder``; empty when there is none or it cannot be read
    (a run that never began, or killed before its first whole version)."""
    try:
        document = json.loads((folder / RUN_JSON).read_text())
    except (OSError, ValueError):
        return {}
    return document if isinstance(document, dict) else {}
