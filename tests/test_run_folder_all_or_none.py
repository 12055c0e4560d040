"""A run refused a folder because one of the earlier run's files cannot go leaves the earlier run
whole: the breaker's immutable record.csv (chattr +i) refused the run after run.json was removed,
and `haptic-bus plot` then refused the folder as no run."""

import pathlib

import pytest

from haptic_bus.app.run_folder import own_run_folder
from haptic_bus.errors import ParameterError

EARLIER = ("run.json", "record.csv", "timeline.png", "bus.asc")


def test_a_file_that_cannot_go_leaves_every_file_of_the_earlier_run(tmp_path: pathlib.Path) -> None:
    folder = tmp_path / "run"
    folder.mkdir()
    for name in EARLIER:
        (folder / name).write_text(name)
    # record.csv cannot be moved aside: a non-empty folder holds the name it would take (EISDIR for
    # root and user alike, where an immutable file needs root and a file system that has the flag)
    (folder / ".record.csv.replaced").mkdir()
    (folder / ".record.csv.replaced" / "x").write_text("")
    with pytest.raises(ParameterError, match=r"nothing removed; .*record\.csv"):
        own_run_folder(folder, "cia402-handle")
    assert {name: (folder / name).read_text() for name in EARLIER} == {name: name for name in EARLIER}
    # and the folder is not left locked: a run may take it once the obstacle is gone
    (folder / ".record.csv.replaced" / "x").unlink()
    (folder / ".record.csv.replaced").rmdir()
    _, lock = own_run_folder(folder, "cia402-handle")
    lock.release()
    assert not any((folder / name).exists() for name in EARLIER)
