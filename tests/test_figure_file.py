"""A figure's file is written whole or not at all (haptic_bus.app.figure_file): a Ctrl-C while the picture
is encoded leaves the file as it was (or none) and no temporary beside it, and the figure closed.  The Ctrl-C
is raised where it truncated figures before: in the PNG encoder, after its first bytes went into the file
(matplotlib draws the figure into memory first; Pillow opens the file, then encodes into it)."""

from __future__ import annotations

import pathlib
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import pytest
from PIL import Image

from haptic_bus.app.figure_file import save_figure

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
PNG_END = b"IEND\xaeB`\x82"  # the last chunk of every PNG, with its CRC


def interrupted_encoder(image: object, file: Any, filename: object) -> None:
    """Pillow's PNG encoder interrupted after the signature: what a Ctrl-C while encoding does."""
    file.write(PNG_SIGNATURE)
    raise KeyboardInterrupt


def test_a_figure_is_written_as_a_whole_png_and_closed(tmp_path: pathlib.Path) -> None:
    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    path = save_figure(fig, tmp_path / "line.png", dpi=50)
    data = path.read_bytes()
    assert data.startswith(PNG_SIGNATURE) and data.endswith(PNG_END)
    assert not plt.fignum_exists(fig.number) and [p.name for p in tmp_path.iterdir()] == ["line.png"]


@pytest.mark.parametrize("before", [None, b"the previous picture"])
def test_a_write_interrupted_leaves_the_file_as_it_was(tmp_path: pathlib.Path, before: bytes | None,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "fig4_region.png"
    if before is not None:
        path.write_bytes(before)
    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    monkeypatch.setitem(Image.SAVE, "PNG", interrupted_encoder)
    with pytest.raises(KeyboardInterrupt):
        save_figure(fig, path, dpi=50)
    assert (path.read_bytes() if path.exists() else None) == before  # never an empty or half picture
    assert [p.name for p in tmp_path.iterdir()] == ([path.name] if before is not None else [])  # no temporary left
    assert not plt.fignum_exists(fig.number)
