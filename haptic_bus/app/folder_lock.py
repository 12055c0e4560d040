"""A run owns its folder: an exclusive lock on ``.haptic-bus.lock`` in it, held for the run's life.

Two runs into one ``--out`` folder would write each other's ``record.csv``, ``bus.asc`` and
``run.json``.  :func:`own_folder` takes ``fcntl.flock(LOCK_EX | LOCK_NB)`` on the folder's lock
file and writes this process' id into it; a second run finds the lock taken and is refused with a
:class:`~haptic_bus.errors.ParameterError` (exit 2: its ``--out`` is the input at fault, found
before any bus is opened or any file of the run is written) naming the folder and the process
that holds it.  The kernel drops the lock when its file is closed: :meth:`FolderLock.release` at
the run's end, or the process' death (``kill -9`` too), so a stale lock file never blocks a
later run.  The file stays (removing it would let a third run lock a new file while a second still
holds the old one).  The lock is advisory and per open file: it guards runs of haptic_bus, not
other writers; POSIX only (``fcntl``).
"""

from __future__ import annotations

import fcntl
import os
import pathlib

from haptic_bus.errors import ParameterError

LOCK_NAME = ".haptic-bus.lock"


class FolderLock:
    """The lock a run holds on its folder (:func:`own_folder`); released by :meth:`release` or the process' end."""

    def __init__(self, path: pathlib.Path, fd: int) -> None:
        self.path = path
        self._fd: int | None = fd

    def release(self) -> None:
        """Give the folder up (closing the lock file drops the lock); again: nothing."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __del__(self) -> None:  # a caller of the Python API that lost the run's lock object: the folder is free again
        self.release()


def own_folder(folder: pathlib.Path, name: str = "--out", context: str = "run") -> FolderLock:
    """Lock ``folder`` (which exists and is writable) for this process; ParameterError naming
    ``name``, the folder and the other run's process id if another run holds it."""
    path = folder / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
    except OSError as exc:
        raise ParameterError(name, str(folder), f"a folder this user can write ({path}: {exc.strerror})", context) from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "unknown"
        os.close(fd)
        raise ParameterError(name, str(folder), f"a folder no other run is writing (the run of process {holder} holds "
                             f"{path}; wait for it to end, or give another --out)", context) from None
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    return FolderLock(path, fd)
