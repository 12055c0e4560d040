"""Upload verdicts from a worker process: the gate never runs in the control thread.

The controller node hands a commit's staged walls to :func:`judge_walls` in this process's one
judge worker (:func:`judge_pool`: a :class:`concurrent.futures.ProcessPoolExecutor` of one
process, started by ``spawn``, so nothing of the control process -- its threads, its bus handles
-- is forked into it).  What crosses is plain data and picklable objects: the gate (the coupled one
with the verdicts the control process holds on its axes), the scene the upload changes,
``{name: (K, B)}`` one way; the new scene and the gate's decision, or the reason the values are
invalid (a ``str``), the other.  The worker is started, and has imported the
gate's modules, before a run's first cycle (:func:`judge_pool` waits for it).  It dies with the
control process (Linux: ``PR_SET_PDEATHSIG``), so a run killed with SIGKILL leaves no worker
behind holding its pipes.  The executor's two threads in this process are named:
``verdict-collect`` (collects the worker's answers and runs their callbacks) and
``verdict-feed`` (pickles the work into the worker's pipe).
"""

from __future__ import annotations

import ctypes
import importlib
import multiprocessing
import os
import signal
import threading
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from drives.os_threads import show_name
from haptic_bus.control.protocols import Decision, Gate, Scene
from haptic_bus.errors import HapticBusError

START_METHOD = "spawn"  # not fork: the control process has threads and open bus handles
PR_SET_PDEATHSIG = 1  # prctl(2): the signal this process gets when its parent dies
_pool: ProcessPoolExecutor | None = None
_pool_lock = threading.Lock()

Verdict = tuple[Scene, Decision] | str
_DIED_STARTING = ("the judge worker process died while it started; it is started by spawn, which runs the calling "
                  "script's top level again in it: a script that calls hb.run needs its run under "
                  "if __name__ == '__main__': (Python's rule for spawned processes)")


def judge_walls(gate: Gate[Any, Any], base: Scene, walls: dict[str, tuple[float, float]]) -> Verdict:
    """In the worker: ``base`` with ``walls`` (name -> (K N/m, B N s/m)) changed, and ``gate``'s
    decision on it; or, for an invalid value, the reason (a ``str``: plain data crosses back)."""
    try:
        scene = base.with_walls(walls)
        return scene, gate.judge(scene)
    except HapticBusError as error:
        return str(error)


def _die_with(parent: int) -> None:
    """In the worker, first: Ctrl-C is the control process's to handle (a terminal sends SIGINT to
    the whole process group: the worker printed a KeyboardInterrupt traceback beside the run's one
    line); SIGKILL when the thread of the control process ``parent`` that started it ends (Linux; a
    pool started by a thread that ended is found broken and started anew by :func:`judge_pool`),
    and exit now if ``parent`` is gone already."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)  # the loaded C library's
    except (OSError, AttributeError):  # no prctl here: a killed control process may leave the worker behind
        return
    if os.getppid() != parent:
        os._exit(0)


WARM_MODULES = ("haptic_bus.control.gate", "haptic_bus.control.space_gate")  # what unpickling either gate imports


def _ready() -> bool:
    """In the worker: its imports are done, the gates' too (unpickling a gate imports the analysis,
    numpy, scipy and mpmath: seconds on a loaded machine, which an upload's SDO answer must not wait for)."""
    for name in WARM_MODULES:
        importlib.import_module(name)
    return True


def judge_pool() -> ProcessPoolExecutor:
    """This process's judge worker, started (and its imports done) on the first call, started anew
    if it died."""
    global _pool
    with _pool_lock:
        if _pool is None or _broken(_pool):
            before = set(threading.enumerate())
            pool = ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context(START_METHOD),
                                       initializer=_die_with, initargs=(os.getpid(),))
            try:
                pool.submit(_ready).result()
            except BrokenProcessPool:
                pool.shutdown(wait=True)
                raise HapticBusError(_DIED_STARTING) from None
            for thread in set(threading.enumerate()) - before:
                thread.name = "verdict-feed" if thread.name == "QueueFeederThread" else "verdict-collect"
                show_name(thread)
            _pool = pool
        return _pool


def kill_workers(pool: ProcessPoolExecutor) -> None:
    """Kill ``pool``'s worker processes now: the work they were given and nobody waits for any more (a
    derate table at a run's end) is given up, its futures fail with BrokenProcessPool, the pool is
    shut down, and for the judge worker the next :func:`judge_pool` starts another.  Without this the interpreter's exit
    waits for every task handed to the pool."""
    kill = getattr(pool, "kill_workers", None)  # Python 3.14; before it, the executor's own table of processes
    if kill is not None:
        kill()
    else:
        for process in list((getattr(pool, "_processes", None) or {}).values()):
            process.kill()
    pool.shutdown(wait=True)  # its manager has seen the death and failed the futures: no later submit lands on it


def _broken(pool: ProcessPoolExecutor) -> bool:
    """Whether ``pool`` can no longer take work (its worker died)."""
    try:
        pool.submit(_ready)
    except (BrokenProcessPool, RuntimeError):
        return True
    return False
