"""Threads named for the operating system, so that ``top -H`` and ``/proc/PID/task/*/comm`` say
which is which.

CPython (before 3.14) names a thread for Python only (``threading.Thread(name=...)``); the
kernel keeps showing the process's name for every thread.  :func:`show_name` hands the Python
name to the kernel with ``pthread_setname_np`` (Linux: 15 bytes at most).  Where the C library
has no such function it does nothing.
"""

from __future__ import annotations

import ctypes
import threading
from collections.abc import Callable

COMM_LENGTH = 15  # bytes of a thread's name the kernel keeps (TASK_COMM_LEN 16, with the NUL)


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
    (:func:`show_name`); the main thread keeps the process's name (``ps``, ``pgrep`` find it by it)."""
    main = threading.main_thread()
    for thread in threading.enumerate():
        if thread is not main:
            show_name(thread)
