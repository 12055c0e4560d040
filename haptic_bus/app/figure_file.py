"""A figure's file written whole or not at all.

matplotlib's ``savefig`` opens the file before it encodes the picture: a Ctrl-C or a full disk
meanwhile left an empty or truncated PNG under the figure's name (``haptic-bus report`` interrupted
while writing ``fig4_region.png``).  :func:`save_figure` writes a temporary file beside it and renames
it over the name once it is whole, as ``run.json`` is written (:func:`~haptic_bus.app.run_json.write_json`).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def save_figure(fig: Figure, path: Path, **options: Any) -> Path:
    """Write ``fig`` to ``path`` (its format from the suffix, PNG without one; ``options``: ``savefig``'s, such
    as ``dpi``) whole or not at all: the previous file, or none, stays until the new one is whole.  The
    figure is closed whatever happens."""
    import matplotlib.pyplot as plt  # the caller's, already imported: this module does not choose the backend

    temporary = path.with_name(f".{path.name}.{os.getpid()}.part")
    try:
        with open(temporary, "wb") as file:  # ours to close, also on a Ctrl-C (Pillow leaves its own open then)
            fig.savefig(file, format=path.suffix[1:] or "png", **options)
        os.replace(temporary, path)
    finally:
        plt.close(fig)
        temporary.unlink(missing_ok=True)
    return path
