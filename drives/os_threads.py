"""Threads named for the operating system, so that ``top -H`` and ``/proc/PID/task/*/comm`` say
which is which.

CPython (before 3.14) names a thread for Python only (``threading.Thread(name=...)``); the
kernel keeps showing the process's name for every thread.  :func:`show_name` hands the Python
name to the kernel with ``pthread_setname_np`` (Linux: 15 bytes at most).  Where the C library
has no such function it does nothing.

Threads Python did not start have no Python name: a C library's pool, such as numpy's OpenBLAS
workers when a program imported numpy before ``haptic-bus`` could ask for one BLAS thread
(:mod:`haptic_bus.app.blas_threads`).  :func:`show_names` calls those that still show the
process's name :data:`NATIVE` (through ``/proc/self/task/TID/comm``), so that no thread of a run
passes for its main thread.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import pathlib
import threading
from collections.abc import Callable

COMM_LENGTH = 15  # bytes of a thread's name the kernel keeps (TASK_COMM_LEN 16, with the NUL)
NATIVE = "native-thread"
"""The OS name :func:`show_names` gives a thread that Python did not start (module docstring)."""
_TASKS = "/proc/self/task"


def _setter() -> Callable[[int, bytes], int] | None:
    """libc's ``pthread_setname_np(pthread_t, const char *)``, or None where there is none."""
    try:
        setname = ctypes.CDLL(None, use_errno=True).pthread_setname_np  # the C library this process has loaded
        # (ctypes.util.find_library("c") would run /sbin/ldconfig -p in a child process at every import)
    except (OSError, AttributeError):
        return None
    setname.argtypes = [ctypes.c_ulong, ctypes.c_char_p]
    setname.restype = ctypes.c_int
    return setname


_SETNAME = _setter()


def show_name(thread: threading.Thread) -> None:
    """The started ``thread``'s Python name (its first 15 bytes) as its OS name; nothing if it has
    ended or the platform cannot name threads."""
    ident = thread.ident
    if _SETNAME is None or ident is None or not thread.is_alive():
        return
    _SETNAME(ident, thread.name.encode("utf-8", "replace")[:COMM_LENGTH])


def show_own_name() -> None:
    """The calling thread's Python name as its OS name (:func:`show_name`, from inside: always safe)."""
    show_name(threading.current_thread())


def show_names() -> None:
    """Every running thread of this process but the main one shows its Python name to the OS
    (:func:`show_name`); the main thread keeps the process's name (``ps``, ``pgrep`` find it by it);
    a thread Python did not start that still shows the process's name is called :data:`NATIVE`
    (Linux; elsewhere nothing)."""
    try:
        tasks = os.listdir(_TASKS)  # before the Python threads are listed: a thread started in between is among them
    except OSError:
        tasks = []
    main = threading.main_thread()
    python = set()
    for thread in threading.enumerate():
        python.add(thread.native_id)
        if thread is not main:
            show_name(thread)
    own = _comm(main.native_id)
    for task in tasks:
        if int(task) not in python and own is not None and _comm(int(task)) == own:
            with contextlib.suppress(OSError):  # it ended meanwhile
                pathlib.Path(_TASKS, task, "comm").write_text(NATIVE)


def _comm(tid: int | None) -> str | None:
    """Thread ``tid``'s OS name, or None if it has none to read (ended, not Linux)."""
    try:
        return pathlib.Path(_TASKS, str(tid), "comm").read_text().strip()
    except OSError:
        return None
