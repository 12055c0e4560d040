"""A run owns its folder: an exclusive lock on ``.haptic-bus.lock`` in it, held for the run's life.

Two runs into one ``--out`` folder would write each other's ``record.csv``, ``bus.asc`` and
``run.json``.  :func:`own_folder` takes ``fcntl.flock(LOCK_EX | LOCK_NB)`` on the folder's lock
file and writes this process' id into it; a second run finds the lock taken and is refused with a
:class:`~haptic_bus.errors.ParameterError` (exit 2: its ``--out`` is the input at fault, found
before any bus is opened or any file of the run is written) naming the folder and the process
that holds it.  :meth:`FolderLock.release` removes the file and drops the lock at the run's end, so
a finished run's folder holds its records only; a process that dies (``kill -9`` too) loses the
lock with its files, and the stale file left is taken over by the next run.  A run that locked
a file another run removed meanwhile (opened just before) sees that the path no longer names
its file, and locks again.  The lock is advisory: it guards runs of haptic_bus, not other
writers; POSIX only (``fcntl``).
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
        """Remove the lock file and give the folder up (closing it drops the lock); again: nothing."""
        if self._fd is not None:
            if _names(self.path, self._fd):
                self.path.unlink()
            os.close(self._fd)
            self._fd = None

    def __del__(self) -> None:  # a caller of the Python API that lost the run's lock object: the folder is free again
        self.release()


_ATTEMPTS = 10  # a lock file removed under us by the run that just ended, again and again: not in practice


def own_folder(folder: pathlib.Path, name: str = "out_dir", context: str = "run") -> FolderLock:
    """Lock ``folder`` (which exists and is writable) for this process; ParameterError naming
    ``name``, the folder and the other run's process id if another run holds it."""
    path = folder / LOCK_NAME
    for _ in range(_ATTEMPTS):
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        except OSError as exc:
            raise ParameterError(name, str(folder), f"a folder this user can write ({path}: {exc.strerror})",
                                 context) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise ParameterError(name, str(folder), f"a folder no other run is writing (the run of process {holder} "
                                 f"holds {path}; wait for it to end, or give another --out)", context) from None
        if _names(path, fd):
            lock = FolderLock(path, fd)
            try:
                os.ftruncate(fd, 0)
                os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
            except OSError as exc:  # a full disk: refused before anything else is written
                lock.release()
                raise ParameterError(name, str(folder), f"a folder this run can write ({path}: {exc.strerror})",
                                     context) from None
            return lock
        os.close(fd)  # the run that held it removed it after we opened it: lock the file the path names now
    raise ParameterError(name, str(folder), f"a folder whose {LOCK_NAME} stays put (removed {_ATTEMPTS} times while "
                         "this run took it)", context)


def holder(folder: pathlib.Path) -> str | None:
    """The process id a run holding ``folder`` wrote into its lock file (:func:`own_folder`), or None: no
    lock file, or one a process that died left.  Writes nothing (a shared lock tried for an instant)."""
    try:
        fd = os.open(folder / LOCK_NAME, os.O_RDONLY | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return os.pread(fd, 32, 0).decode(errors="replace").strip() or "unknown"
    finally:
        os.close(fd)
    return None


def _names(path: pathlib.Path, fd: int) -> bool:
    """Whether ``path`` is the file open as ``fd`` (not removed, not replaced)."""
    try:
        return os.path.samestat(os.stat(path), os.fstat(fd))
    except FileNotFoundError:
        return False
