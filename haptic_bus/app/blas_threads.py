"""One BLAS thread in a ``haptic-bus`` process.

numpy's and scipy's OpenBLAS each start a pool of worker threads at import
(one per further CPU), which ``top -H`` and ``/proc/PID/task/*/comm`` show under the process's name
beside the named threads of a run, and which burnt 0.1 s of CPU each while a three-axis run started
(measured here, 2 CPUs).  The project's matrices are 6 x 6 at most and its long arrays are
elementwise (no BLAS), so the pools buy nothing: before anything imports numpy, :func:`one_blas_thread`
asks each BLAS library the wheels ship for one thread, unless the environment already names a count
(the user's choice is kept, and passed to the run's writer and judge processes as this one's is).

A value that names no count is not a choice: OpenBLAS reads its variable with C's ``atoi`` and
starts its whole pool for anything that does not begin with a positive number (an empty
``OPENBLAS_NUM_THREADS=``, ``0``, ``auto``: measured, numpy 2.4's OpenBLAS 0.3.31), so such a value
is replaced by ``1`` as an absent one is.  A count the library reads after its own variable (OpenBLAS:
``GOTO_NUM_THREADS``, ``OMP_NUM_THREADS``; MKL: ``OMP_NUM_THREADS``) is the user's choice too.
"""

from __future__ import annotations

import os
import re

# the thread counts numpy's and scipy's BLAS libraries read, each with the variables it reads after it
BLAS_THREADS = {"OPENBLAS_NUM_THREADS": ("GOTO_NUM_THREADS", "OMP_NUM_THREADS"), "MKL_NUM_THREADS": ("OMP_NUM_THREADS",)}
_COUNT = re.compile(r"\s*\+?0*[1-9]")  # what atoi reads as a positive number: blanks, a sign, digits, not all 0


def names_a_count(value: str | None) -> bool:
    """Whether a BLAS library reads ``value`` (an environment variable's) as a positive thread count."""
    return value is not None and _COUNT.match(value) is not None


def one_blas_thread() -> None:
    """One thread for each BLAS library this process will load, where the environment names no count
    (module docstring); only before numpy is imported does it change anything."""
    for name, after in BLAS_THREADS.items():
        if not any(names_a_count(os.environ.get(each)) for each in (name, *after)):
            os.environ[name] = "1"
