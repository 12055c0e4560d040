"""One BLAS thread in a ``haptic-bus`` process.

numpy's and scipy's OpenBLAS each start a pool of worker threads at import
(one per further CPU), which ``top -H`` and ``/proc/PID/task/*/comm`` show under the process's name
beside the named threads of a run, and which burnt 0.1 s of CPU each while a three-axis run started
(measured here, 2 CPUs).  The project's matrices are 6 x 6 at most and its long arrays are
elementwise (no BLAS), so the pools buy nothing: before anything imports numpy, :func:`one_blas_thread`
asks each BLAS library the wheels ship for one thread, unless the environment already names a count
(the user's choice is kept, and passed to the run's writer and judge processes as this one's is).
"""

from __future__ import annotations

import os

BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")  # the thread counts numpy's and scipy's BLAS libraries read


def one_blas_thread() -> None:
    """One thread for each BLAS library this process will load, where the environment names no count
    (module docstring); only before numpy is imported does it change anything."""
    for name in BLAS_THREADS:
        os.environ.setdefault(name, "1")
