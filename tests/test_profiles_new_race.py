"""``profiles new`` without ``--force`` never replaces a file, even one another command made after its
check that the file did not exist (two ``profiles new`` at once: 2 of 8 started together used to exit 0,
each having written the same file, the later replacing the earlier); it creates the file exclusively
(O_EXCL) and, finding it there, says so as its check does: one line, exit 2 (break16).  The file is written
whole or not at all (:func:`haptic_bus.app.whole_file.write_text_whole`, which ``identify --write-profile``
shares): a write that failed half way (a full disk) left a truncated profile the next run refused to replace."""

from __future__ import annotations

import errno
import os
import pathlib
from typing import Any

import pytest

import haptic_bus.app.profile_template as profile_template
from haptic_bus.app import whole_file
from haptic_bus.app.cli import main
from haptic_bus.app.whole_file import write_text_whole

OTHERS = "# written by another command meanwhile\n"


def test_a_file_made_between_the_check_and_the_write_is_kept(
        tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "new.toml"
    template = profile_template.template

    def another_command_meanwhile(*args: object, **kwargs: object) -> str:
        out.write_text(OTHERS)  # after profiles new's check, before its write
        return template(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(profile_template, "template", another_command_meanwhile)
    assert main(["profiles", "new", "new", "--out", str(out)]) == 2
    stdout, err = capsys.readouterr()
    assert stdout == "" and out.read_text() == OTHERS
    assert err == (f"haptic-bus profiles new: error: --out = '{out}' is invalid; allowed: a file that does not "
                   "exist yet (--force overwrites it)\n")
    assert main(["profiles", "new", "new", "--out", str(out), "--force"]) == 0  # --force replaces it, as it says
    assert out.read_text().startswith("# Profile new, written by `haptic-bus profiles new new`")


def _a_full_disk(monkeypatch: pytest.MonkeyPatch) -> None:
    """The writer's file takes its first 100 characters, then the disk is full (ENOSPC), as a write does."""
    def opened(path: Any, mode: str = "r", **options: Any) -> Any:
        file = open(path, mode, **options)  # noqa: SIM115 -- closed by the writer's with-block
        write = file.write

        def fills_the_disk(text: str) -> int:
            write(text[:100])
            file.flush()  # the partial content reaches the file, as it would on a disk that filled meanwhile
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        file.write = fills_the_disk
        return file

    monkeypatch.setattr(whole_file, "open", opened, raising=False)


@pytest.mark.parametrize("there", ["a file", "a dangling link"])
@pytest.mark.parametrize("replace", [False, True])
def test_a_file_there_is_never_touched_and_a_failed_write_leaves_nothing(
        there: str, replace: bool, tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Without ``replace`` whatever is at the name stays as it is (FileExistsError); a write that fails leaves
    the name as it was, with or without ``replace``, and no temporary file beside it."""
    target = tmp_path / "new.toml"
    if there == "a file":
        target.write_text(OTHERS)
    else:
        target.symlink_to(tmp_path / "nowhere.toml")
    before = (os.readlink(target) if target.is_symlink() else target.read_text(), target.lstat().st_mtime_ns)
    if not replace:
        with pytest.raises(FileExistsError):
            write_text_whole(target, "# new\n")
    _a_full_disk(monkeypatch)
    with pytest.raises(OSError, match="No space left on device"):
        write_text_whole(target, "# new\n" * 100, replace=replace)
    assert (os.readlink(target) if target.is_symlink() else target.read_text(), target.lstat().st_mtime_ns) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["new.toml"]


def test_a_write_that_fails_leaves_no_profile_and_says_why(
        tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """``profiles new`` on a disk that fills during the write: one line, exit 2, and no file at all (it left the
    first 100 characters under the name, which the next ``profiles new`` refused to replace)."""
    out = tmp_path / "new.toml"
    _a_full_disk(monkeypatch)
    assert main(["profiles", "new", "new", "--out", str(out)]) == 2
    assert capsys.readouterr().err == (f"haptic-bus profiles new: error: --out = '{out}' is invalid; allowed: a file "
                                       "this user can write (No space left on device)\n")
    assert list(tmp_path.iterdir()) == []
    monkeypatch.undo()
    assert main(["profiles", "new", "new", "--out", str(out)]) == 0  # the disk has room again: written whole
    assert out.read_text().startswith("# Profile new, written by `haptic-bus profiles new new`")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["new.toml"]


@pytest.mark.parametrize("code", sorted(whole_file.NO_HARD_LINKS))
def test_a_folder_without_hard_links_gets_the_file_exclusively_and_whole(
        code: int, tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Where ``os.link`` is refused (FAT, some network mounts) the file is created exclusively under its name:
    written whole; a file there kept (FileExistsError); a write that fails leaves nothing, no temporary file
    either.  Another error of ``os.link`` (here ENOSPC) is the caller's, nothing left."""
    def no_links(source: Any, destination: Any) -> None:
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(whole_file.os, "link", no_links)
    target = tmp_path / "new.toml"
    assert write_text_whole(target, "# new\n") == target and target.read_text() == "# new\n"
    with pytest.raises(FileExistsError):
        write_text_whole(target, "# other\n")
    assert target.read_text() == "# new\n" and sorted(p.name for p in tmp_path.iterdir()) == ["new.toml"]
    target.unlink()
    _a_full_disk(monkeypatch)
    with pytest.raises(OSError, match="No space left on device"):
        write_text_whole(target, "# new\n" * 100)
    assert list(tmp_path.iterdir()) == []


def test_another_link_error_is_the_callers(tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def full(source: Any, destination: Any) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(whole_file.os, "link", full)
    with pytest.raises(OSError, match="No space left on device"):
        write_text_whole(tmp_path / "new.toml", "# new\n")
    assert list(tmp_path.iterdir()) == []
