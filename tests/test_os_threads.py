"""Every thread of a run says what it is in ``/proc/PID/task/*/comm`` (drives/os_threads.py): Python's threads by
their Python names, threads Python did not start (numpy's OpenBLAS pool, when a program imported numpy before
haptic_bus could ask for one BLAS thread) as ``native-thread``, and a thread that named itself keeps its name."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from drives.os_threads import NATIVE

PROGRAM = r"""
import _thread, ctypes, json, os, threading
import numpy  # OpenBLAS starts its pool here: OPENBLAS_NUM_THREADS=2, a worker beside this thread on 2+ CPUs
from drives.os_threads import show_names

named, release = threading.Event(), threading.Event()

def named_itself():  # a thread Python's threading does not know, which gave itself an OS name
    ctypes.CDLL(None).prctl(15, b"own-name", 0, 0, 0)
    named.set()
    release.wait(10)

_thread.start_new_thread(named_itself, ())
named.wait(10)
helper = threading.Thread(target=release.wait, args=(10,), name="test-helper")
helper.start()
show_names()
comm = {int(t): open(f"/proc/self/task/{t}/comm").read().strip() for t in os.listdir("/proc/self/task")}
print(json.dumps({"main": comm.pop(threading.main_thread().native_id), "others": sorted(comm.values())}))
release.set()
helper.join(10)
"""


def test_show_names_names_every_thread_and_keeps_a_name_a_thread_gave_itself() -> None:
    environment = os.environ | {"OPENBLAS_NUM_THREADS": "2"}
    done = subprocess.run([sys.executable, "-c", PROGRAM], capture_output=True, text=True, timeout=60, env=environment,
                          check=True)
    names = json.loads(done.stdout)
    others = names["others"]
    assert "own-name" in others and "test-helper" in others
    natives = [name for name in others if name not in ("own-name", "test-helper")]
    assert natives == [NATIVE] * len(natives), others
    if (os.cpu_count() or 1) > 1:  # OpenBLAS (numpy's wheels bundle it) starts min(2, CPUs) - 1 workers
        assert natives, others
    assert names["main"] not in others  # no thread but the main one passes for the process
